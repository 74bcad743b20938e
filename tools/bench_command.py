"""The command line of a timed bench tool run alone: how many timed runs, progress on stderr,
its table on stdout and its figures in ``out/bench/<name>.json``."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

OUT_DIR = Path(__file__).resolve().parent.parent / "out/bench"


def run_timed_tool(
    argv,
    name: str,
    docstring: str,
    runs: int,
    run: Callable[..., dict],
    print_result: Callable[[dict], None],
) -> None:
    """Parse ``argv`` (``--runs``, default ``runs``) for the tool ``name`` described by the
    first line of ``docstring``; ``run(runs, log)`` it, print its result with
    ``print_result`` and write it to out/bench/``name``.json."""
    parser = argparse.ArgumentParser(prog=f"bench_{name}", description=docstring.split("\n")[0])
    parser.add_argument("--runs", type=int, default=runs, help="timed runs of each")
    arguments = parser.parse_args(argv)
    result = run(arguments.runs, lambda text: print(text, file=sys.stderr, flush=True))
    print_result(result)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    (OUT_DIR / f"{name}.json").write_text(json.dumps(result, indent=2))
