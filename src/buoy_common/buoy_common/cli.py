"""What every offline command does alike: stop cleanly on SIGINT, SIGTERM and a closed pipe, and
keep the garbage collector off what the imports built.

An interrupted command prints one line and exits with :data:`INTERRUPTED_EXIT_CODE`; its outputs
are staged under temporary names (:mod:`buoy_common.safe_output`), so nothing half-written is
left under the names the user gave. Signals after the first are ignored, so that a wrapper
forwarding the signal twice cannot interrupt the clean-up of the first.
"""

from __future__ import annotations

import functools
import gc
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


class _Interruption:
    """The handler of SIGINT and SIGTERM: the first one raises KeyboardInterrupt, later ones
    (a wrapper forwarding the signal again) are counted and otherwise ignored, so that they
    cannot interrupt the clean-up the first one started."""

    def __init__(self):
        self.signals = 0

    def __call__(self, signal_number, frame) -> None:
        self.signals += 1
        if self.signals == 1:
            raise KeyboardInterrupt


def interruptible(program: str) -> Callable:
    """Decorate a command's ``main``: SIGINT or SIGTERM end it with one line on stderr and
    exit code :data:`INTERRUPTED_EXIT_CODE`, a closed output pipe with
    :data:`BROKEN_PIPE_EXIT_CODE`, both without a traceback.

    What exists when the command starts (modules, classes, numpy, scipy: some 65 000 objects that
    live as long as the process) is moved out of the cyclic garbage collector's reach
    (``gc.freeze``): each full collection during a run over a bag would otherwise walk all of
    it again, about a tenth of a second of CPU each time."""

    def decorate(main: Callable) -> Callable:
        @functools.wraps(main)
        def run(*args, **kwargs):
            if threading.current_thread() is not threading.main_thread():
                return main(*args, **kwargs)
            gc.freeze()
            interruption = _Interruption()
            for number in _STOP_SIGNALS:
                signal.signal(number, interruption)
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
                if interruption.signals:
                    # Exiting: the interpreter would reset the handler to the default action
                    # while it exits, and a late signal then kill the process.
                    for number in _STOP_SIGNALS:
                        signal.signal(number, signal.SIG_IGN)

        return run

    return decorate
