"""What every offline command does alike: stop cleanly on SIGINT, SIGTERM and a closed pipe.

An interrupted command prints one line and exits with :data:`INTERRUPTED_EXIT_CODE`; its outputs
are staged under temporary names (:mod:`buoy_common.safe_output`), so nothing half-written is
left under the names the user gave. Signals after the first are ignored, so that a wrapper
forwarding the signal twice cannot interrupt the clean-up of the first.
"""

from __future__ import annotations

import functools
import os
import signal
import sys
import threading
from collections.abc import Callable

INTERRUPTED_EXIT_CODE = 130
"""Exit code of a command stopped by SIGINT or SIGTERM (the shell's 128 + SIGINT)."""

BROKEN_PIPE_EXIT_CODE = 141
"""Exit code of a command whose output pipe was closed (the shell's 128 + SIGPIPE)."""

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _interrupt(signal_number, frame) -> None:
    for number in _STOP_SIGNALS:
        signal.signal(number, signal.SIG_IGN)
    raise KeyboardInterrupt


def interruptible(program: str) -> Callable:
    """Decorate a command's ``main``: SIGINT or SIGTERM end it with one line on stderr and
    exit code :data:`INTERRUPTED_EXIT_CODE`, without a traceback."""

    def decorate(main: Callable) -> Callable:
        @functools.wraps(main)
        def run(*args, **kwargs):
            if threading.current_thread() is not threading.main_thread():
                return main(*args, **kwargs)
            previous = {number: signal.getsignal(number) for number in _STOP_SIGNALS}
            for number in _STOP_SIGNALS:
                signal.signal(number, _interrupt)
            try:
                return main(*args, **kwargs)
            except KeyboardInterrupt:
                print(f"{program}: interrupted", file=sys.stderr)
                sys.exit(INTERRUPTED_EXIT_CODE)
            except BrokenPipeError:
                # The reader of the output went away (``| head``): stop quietly, as ``cat`` does.
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
                sys.exit(BROKEN_PIPE_EXIT_CODE)
            finally:
                for number, handler in previous.items():
                    signal.signal(number, handler)

        return run

    return decorate
