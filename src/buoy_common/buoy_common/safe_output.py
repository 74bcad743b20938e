"""Outputs that never destroy an input and never appear half-written.

The offline tools call :func:`check_outputs_apart_from_inputs` with their paths before they touch
anything. Each output is then written under a temporary name beside its final one
(:func:`staging_path`) and moved into place once complete (:func:`move_into_place`,
:func:`staged_file`): an interrupted run (Ctrl-C, an error, SIGKILL) leaves at most a
``<name>.partial-<pid>`` beside the final name, never half an output under it, and an existing
output that is being replaced stays intact until its successor is complete.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TextIO


class OutputError(Exception):
    """An output cannot be written where asked; the message names the paths and the reason."""


def _resolved(path: str | Path) -> Path:
    return Path(path).expanduser().resolve()


def check_outputs_apart_from_inputs(
    inputs: Iterable[str | Path], outputs: Iterable[str | Path]
) -> None:
    """Raise OutputError if an output is, contains or lies inside an input.

    Paths are compared after following symbolic links, so a link to the input, or the input
    spelt another way (``./bag``, ``bag/``), is caught too.
    """
    resolved_inputs = [(path, _resolved(path)) for path in inputs]
    for output in outputs:
        resolved_output = _resolved(output)
        for given, resolved_input in resolved_inputs:
            if resolved_output == resolved_input:
                relation = "is the input"
            elif resolved_output in resolved_input.parents:
                relation = "contains the input"
            elif resolved_input in resolved_output.parents:
                relation = "lies inside the input"
            else:
                continue
            raise OutputError(f"output {output} {relation} {given}; refusing to write it")


def staging_path(final: Path) -> Path:
    """Where an output for ``final`` is written until it is complete: beside it, in the same
    file system (so that moving it into place is a rename), named for this process."""
    return final.with_name(f"{final.name}.partial-{os.getpid()}")


def move_into_place(staged: Path, final: Path, replace: bool) -> None:
    """Rename the complete directory ``staged`` to ``final``.

    An existing ``final`` is kept when ``replace`` is False (OutputError); otherwise it is moved
    aside first and deleted only once ``staged`` has taken its place, so that a failure leaves
    the old output where it was.
    """
    if not (final.exists() or final.is_symlink()):
        try:
            staged.rename(final)
            return
        except OSError as error:
            if not final.exists():
                raise
            raise OutputError(f"output {final} appeared while it was being written") from error
    if not replace:
        raise OutputError(f"output {final} appeared while it was being written")
    aside = final.with_name(f"{final.name}.replaced-{os.getpid()}")
    final.rename(aside)
    try:
        staged.rename(final)
    except BaseException:
        aside.rename(final)
        raise
    shutil.rmtree(aside)


@contextlib.contextmanager
def staged_file(final: str | Path) -> Iterator[TextIO]:
    """A text file open for writing that replaces ``final`` when the block completes; left by
    an exception, it is deleted and ``final`` is untouched."""
    final = Path(final)
    staged = staging_path(final)
    try:
        with staged.open("w", newline="") as stream:
            yield stream
        staged.replace(final)
    finally:
        staged.unlink(missing_ok=True)
