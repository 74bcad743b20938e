"""What every offline command does alike: stop cleanly on SIGINT, SIGTERM and a closed pipe,
keep the garbage collector off what the imports built, and say in ``--help`` what it does and
every exit code it can return (:class:`ExitCode`, :func:`command_parser`).

An interrupted command prints one line and exits with :data:`INTERRUPTED_EXIT_CODE`; its outputs
are staged under temporary names (:mod:`buoy_common.safe_output`), so nothing half-written is
left under the names the user gave. Signals after the first are ignored, so that a wrapper
forwarding the signal twice cannot interrupt the clean-up of the first.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import signal
import sys
import textwrap
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from buoy_common.bag_io.common import RECOVERED_BAG_EXIT_CODE
from buoy_common.heap import freeze_existing_objects

INTERRUPTED_EXIT_CODE = 130
"""Exit code of a command stopped by SIGINT or SIGTERM (the shell's 128 + SIGINT)."""

BROKEN_PIPE_EXIT_CODE = 141
"""Exit code of a command whose output pipe was closed (the shell's 128 + SIGPIPE)."""

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@dataclass(frozen=True)
class ExitCode:
    """One exit code of a command and what it means, as ``--help`` lists it."""

    code: int
    meaning: str


DONE = ExitCode(0, "done")
BAD_INPUT = ExitCode(
    2, "bad arguments, parameters or input files: one line on stderr names the problem"
)
INTERRUPTED = ExitCode(
    INTERRUPTED_EXIT_CODE,
    "interrupted (SIGINT or SIGTERM): one line on stderr, nothing half-written left behind",
)
BROKEN_PIPE = ExitCode(
    BROKEN_PIPE_EXIT_CODE, "the reader of the output went away (a closed pipe, as with | head)"
)
RECOVERED_BAG = ExitCode(
    RECOVERED_BAG_EXIT_CODE,
    "done, but the input bag was cut short (a recorder killed or out of power) and was read up "
    "to its last complete chunk; a warning says how much",
)
INTERRUPTIBLE_EXIT_CODES = (DONE, BAD_INPUT, INTERRUPTED, BROKEN_PIPE)
"""What every command decorated with :func:`interruptible` can return besides its own codes."""
NODE_EXIT_CODES = (
    ExitCode(0, "stopped by SIGINT or SIGTERM"),
    ExitCode(2, "bad arguments or parameters, or rclpy could not start: one line on stderr"),
)
"""What a node run by :func:`buoy_common.base_node.run_node` returns."""

_HELP_WIDTH = 78


ROS_ARGUMENTS_NOTE = "ROS arguments (parameters, remappings) follow --ros-args."
"""What the help of a command that is also a ROS node adds to its description."""


def command_parser(
    program: str, docstring: str, exit_codes: Iterable[ExitCode], note: str = ""
) -> argparse.ArgumentParser:
    """The argument parser of a command: its description the first paragraph of the module's
    ``docstring`` (whole sentences, without reStructuredText markup) and ``note``, its epilog
    every one of ``exit_codes`` with its meaning."""
    description = " ".join(filter(None, (first_paragraph(docstring), note)))
    return _CommandParser(
        prog=program,
        description=_fill(description),
        epilog=exit_codes_text(exit_codes),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


class _CommandParser(argparse.ArgumentParser):
    """An argument parser whose help survives a reader that stops early (``--help | head``)."""

    def print_help(self, file=None) -> None:
        write_help(self.format_help(), file)


def write_help(text: str, stream=None) -> None:
    """Write a help text to ``stream`` (standard output when None). A reader that went away
    after the lines it wanted (``--help | head -1``) ends the writing quietly: help is not an
    error, and the interpreter's last flush of a dead pipe would print a traceback."""
    stream = stream or sys.stdout
    try:
        stream.write(text)
        stream.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())


def asks_for_help(argv: list[str]) -> bool:
    """Whether a node's command line (``sys.argv``) asks for its help, ``-h`` or ``--help``
    before any ROS arguments, rather than for the node to run."""
    ours = argv[1:]
    if "--ros-args" in ours:
        ours = ours[: ours.index("--ros-args")]
    return any(argument in ("-h", "--help") for argument in ours)


def node_help(program: str, docstring: str) -> str:
    """The help of a node that takes ROS arguments only: what it does (the first paragraph of
    its module's ``docstring``), how to give it parameters, and its exit codes."""
    description = f"{first_paragraph(docstring)} {ROS_ARGUMENTS_NOTE}"
    return (
        f"usage: {program} [-h] [--ros-args ...]\n\n{_fill(description)}\n\n"
        f"{exit_codes_text(NODE_EXIT_CODES)}"
    )


def first_paragraph(docstring: str) -> str:
    """The first paragraph of a docstring as plain text on one line."""
    paragraph = textwrap.dedent(docstring).strip().split("\n\n", 1)[0]
    return plain_text(" ".join(paragraph.split()))


def plain_text(text: str) -> str:
    """``text`` without reStructuredText roles and literals (:mod:`x` and ``x`` become x)."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", text)
    return text.replace("``", "")


def exit_codes_text(exit_codes: Iterable[ExitCode]) -> str:
    """The ``Exit codes:`` section of a command's help, one code a line, in order."""
    lines = ["exit codes:"]
    for exit_code in sorted(exit_codes, key=lambda e: e.code):
        lines += textwrap.wrap(
            exit_code.meaning + ".",
            _HELP_WIDTH,
            initial_indent=f"  {exit_code.code:<5d}",
            subsequent_indent=" " * 7,
        )
    return "\n".join(lines)


def _fill(text: str) -> str:
    return textwrap.fill(text, _HELP_WIDTH)


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
    (:mod:`buoy_common.heap`): each full collection during a run over a bag would otherwise walk
    all of it again, about a tenth of a second of CPU each time."""

    def decorate(main: Callable) -> Callable:
        @functools.wraps(main)
        def run(*args, **kwargs):
            if threading.current_thread() is not threading.main_thread():
                return main(*args, **kwargs)
            freeze_existing_objects()
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
