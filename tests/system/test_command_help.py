"""Every console script's ``--help`` is whole: the description and every exit code the command
can return, each in complete sentences. The codes are the command's ``EXIT_CODES`` (declared
once, in its module, from :mod:`buoy_common.cli`; a node that takes only ROS arguments has those
of every node); the codes its source hands to ``sys.exit`` or ``parser.exit``, and those of
:func:`buoy_common.cli.interruptible`, must be among them. Asked for help, a node prints it and
exits instead of starting; whoever reads it may stop early (``--help | head -1``) without a
traceback."""

from __future__ import annotations

import ast
import contextlib
import importlib
import inspect
import io
import os
import re
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import pytest

from buoy_common.cli import BROKEN_PIPE_EXIT_CODE, INTERRUPTED_EXIT_CODE, NODE_EXIT_CODES

PACKAGES = ("buoy_common", "buoy_nav", "buoy_processing", "sensor_sim", "wind_comp")
SCRIPTS = sorted(
    (entry.name, entry.value.split(":")[0])
    for entry in entry_points(group="console_scripts")
    if entry.value.split(".")[0] in PACKAGES
)
UNFINISHED_ENDINGS = {"a", "an", "the", "of", "and", "or", "to", "with", "by", "from", "in", "for"}


def test_every_console_script_is_known():
    assert len(SCRIPTS) >= 20
    assert {"process_bag", "fuse_bag", "wind_report", "import_records"} <= {n for n, _ in SCRIPTS}


def declared_exit_codes(module) -> tuple:
    """The exit codes a command declares: its module's ``EXIT_CODES``, or those of every node
    run by :func:`buoy_common.base_node.main_for` (which takes only ROS arguments)."""
    if hasattr(module, "EXIT_CODES"):
        return module.EXIT_CODES
    assert "main_for" in inspect.getsource(module), module.__name__
    return NODE_EXIT_CODES


def _help_text(name: str, module_name: str) -> str:
    entry = next(e for e in entry_points(group="console_scripts") if e.name == name)
    main = entry.load()
    stdout = io.StringIO()
    saved_argv = sys.argv
    sys.argv = [name, "--help"]
    try:
        with contextlib.redirect_stdout(stdout), pytest.raises(SystemExit) as exited:
            main()
    finally:
        sys.argv = saved_argv
    assert exited.value.code in (0, None), name
    return stdout.getvalue()


def _codes_in_source(module) -> set[int]:
    """Exit codes the module's source hands to sys.exit, parser.exit or an exit_code, resolved
    through the module's names; those of the interruptible decorator and of argparse (2)."""
    tree = ast.parse(inspect.getsource(module))
    codes = {2}  # argparse's own for a bad argument
    for node in ast.walk(tree):
        value = None
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "exit" and node.args:
            value = node.args[0]
        elif isinstance(node, ast.Assign) and any(
            getattr(target, "id", "") == "exit_code" for target in node.targets
        ):
            value = node.value
        elif isinstance(node, ast.Call) and getattr(node.func, "id", "") == "interruptible":
            codes |= {INTERRUPTED_EXIT_CODE, BROKEN_PIPE_EXIT_CODE}
        if isinstance(value, ast.Constant) and isinstance(value.value, int):
            codes.add(value.value)
        elif isinstance(value, ast.Name) and isinstance(getattr(module, value.id, None), int):
            codes.add(getattr(module, value.id))
    return codes


@pytest.mark.parametrize(("name", "module_name"), SCRIPTS)
def test_help_names_every_exit_code_in_whole_sentences(name, module_name):
    module = importlib.import_module(module_name)
    declared = {exit_code.code for exit_code in declared_exit_codes(module)}
    assert _codes_in_source(module) <= declared, name
    text = _help_text(name, module_name)
    exit_section = text.split("\nexit codes:\n", 1)[1]
    listed = [int(code) for code in re.findall(r"^  (\d+) ", exit_section, flags=re.MULTILINE)]
    assert sorted(listed) == sorted(declared), name
    entries = re.split(r"\n(?=  \d+ )", exit_section.strip())
    assert all(" ".join(entry.split()).endswith(".") for entry in entries), entries
    description = text.split("\n\n")[1]
    assert " ".join(description.split()).endswith("."), (name, description)
    for paragraph in text.split("\n\n"):
        words = paragraph.split()
        assert words, name
        assert words[-1].rstrip(".").lower() not in UNFINISHED_ENDINGS, (name, paragraph)
        assert not words[-1].endswith((",", ";", ":")) or words[-1] == "codes:", (name, paragraph)


BIN = Path(sys.executable).parent


# One command and one node in the quick suite; every console script (about two minutes on a
# busy machine) in the long one.
QUICK_HELP_SCRIPTS = ("import_records", "fusion_node")


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(name, marks=[pytest.mark.long] * (name not in QUICK_HELP_SCRIPTS))
        for name, _ in SCRIPTS
    ],
)
def test_help_to_a_reader_that_went_away_ends_quietly(name):
    # The reader's end is closed before the command writes a byte: every write of the help
    # meets a closed pipe, the hardest case of ``--help | head -1``.
    # Buffered, as in a user's shell: the help then meets the closed pipe at the last flush.
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        process = subprocess.Popen(
            [str(BIN / name), "--help"],
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            env=environment,
        )
    finally:
        os.close(write_end)
    _, stderr = process.communicate(timeout=120)
    assert stderr == "", (name, stderr)
    assert process.returncode == 0, name


def test_the_first_line_of_help_through_head():
    completed = subprocess.run(
        f"'{BIN / 'process_bag'}' --help | head -1",
        shell=True,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.stdout.startswith("usage: process_bag")
    assert len(completed.stdout.splitlines()) == 1
    assert completed.stderr == ""
