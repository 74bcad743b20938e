"""The README, bags/README.md and docs/ say what the code does: links resolve, commands run.

The documents follow three conventions (docs/development.md, "The documentation and its
commands"):

- a ```console block holds commands a user types at the repository root inside the venv, one a
  line (``#`` starts a comment, a trailing backslash continues the line); the blocks of a
  document run in order, as a reader following it runs them;
- a ```text block holds usage synopses, with placeholders (``IN_BAG``, ``[--overwrite]``);
- inline code that starts with a command the suite ships (``process_bag ...``, ``make bench``,
  ``python tools/bench.py --only fluxes``) is a command too.

The quick console commands (the offline tools on the committed bags and records, ``python -c``)
run for real in a copy of the repository root whose ``out/`` is a temporary directory. Every
other command, and every synopsis and inline command, is checked instead: the executable, the
``make`` target, the script or the launch file exists, every repository file it names exists,
and every option it uses is in its ``--help`` (a launch argument: declared by the launch file).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from buoy_nav.aiding import AIDING_SOURCES

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
DOCS = tuple(sorted((REPO / "docs").glob("*.md")))
DOCUMENTS = (REPO / "README.md", REPO / "bags" / "README.md", *DOCS)
COMMITTED_DIRECTORIES = {"src", "bags", "tests", "tools", "docs", "ros2_ws"}
COMMAND_TIMEOUT_S = 300

# Commands that finish in seconds on the committed bags; the others run for minutes or until
# stopped (nodes, live runs, benchmarks) and are checked without running.
RUN_FOR_REAL = {"process_bag", "fuse_bag", "wind_report", "import_records"}
# Where a command line ends for option checking: ROS arguments, pipes, redirections, lists.
OPTION_TERMINATORS = {"--ros-args", "|", "||", "&&", ";", ">", "2>", ">>"}
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*$")


def console_scripts() -> dict[str, Path]:
    """The suite's console scripts: name -> the source file of their entry point."""
    scripts = {}
    for setup in REPO.glob("src/*/setup.py"):
        for name, module in re.findall(r'"(\w+) = ([\w.]+):main"', setup.read_text()):
            scripts[name] = setup.parent / (module.replace(".", "/") + ".py")
    return scripts


SCRIPTS = console_scripts()


# --- Reading the documents --------------------------------------------------------------------


@dataclass(frozen=True)
class Block:
    info: str
    lines: tuple[str, ...]


def split_fences(text: str) -> tuple[list[Block], str]:
    """The fenced blocks of a Markdown text, and the prose outside them."""
    blocks, prose, fence, info, lines = [], [], None, "", []
    for line in text.splitlines():
        stripped = line.strip()
        if fence is None:
            opening = re.match(r"^(`{3,})(.*)$", stripped)
            if opening:
                fence, info, lines = opening.group(1), opening.group(2).strip(), []
            else:
                prose.append(line)
        elif re.fullmatch(rf"{fence}`*", stripped):
            blocks.append(Block(info, tuple(lines)))
            fence = None
        else:
            lines.append(line.strip())
    return blocks, "\n".join(prose)


def inline_code(prose: str) -> list[str]:
    spans = re.findall(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)", prose, flags=re.S)
    return [" ".join(code.split()) for _, code in spans]


def logical_lines(lines: tuple[str, ...]) -> list[str]:
    """Lines of a console block with continuations joined and blank lines dropped."""
    joined, pending = [], ""
    for line in lines:
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        joined.append(pending + line)
        pending = ""
    return [line for line in joined if line.strip() and not line.lstrip().startswith("#")]


def tokens_of(line: str) -> list[str]:
    try:
        return shlex.split(line, comments=True)
    except ValueError:  # a synopsis with an unbalanced quote
        return line.split()


@dataclass(frozen=True)
class Command:
    document: Path
    line: str
    tokens: tuple[str, ...]
    kind: str  # script, make, tool, module, code, launch, pip
    target: str  # the script, tool path, module or launch file it runs
    in_console_block: bool


def recognised(document: Path, line: str, in_console_block: bool) -> Command | None:
    tokens = tokens_of(line)
    if not tokens:
        return None
    first = tokens[0].removeprefix(".venv/bin/")
    rest = tokens[1:]
    kind_target = None
    if first in SCRIPTS:
        kind_target = ("script", first)
    elif first == "make":
        kind_target = ("make", "make")
    elif first in ("python", "python3") and rest:
        if rest[0].startswith("tools/") and rest[0].endswith(".py"):
            kind_target = ("tool", rest[0])
        elif rest[0] == "-m" and len(rest) > 1:
            kind_target = ("module", rest[1])
        elif rest[0] == "-c":
            kind_target = ("code", "-c")
    elif first == "ros2" and rest[:1] == ["launch"] and len(rest) >= 3:
        kind_target = ("launch", f"src/{rest[1]}/launch/{rest[2]}")
    elif first == "pip" and rest[:1] == ["install"]:
        kind_target = ("pip", "install")
    if kind_target is None:
        return None
    return Command(document, line, tuple(tokens), *kind_target, in_console_block)


def console_lines(document: Path) -> list[str]:
    blocks, _ = split_fences(document.read_text())
    return [
        line for block in blocks if block.info == "console" for line in logical_lines(block.lines)
    ]


def commands_of(document: Path) -> list[Command]:
    blocks, prose = split_fences(document.read_text())
    found = [recognised(document, line, True) for line in console_lines(document)]
    for block in blocks:
        if block.info == "text":
            found += [recognised(document, line, False) for line in block.lines]
    found += [recognised(document, code, False) for code in inline_code(prose)]
    return [command for command in found if command is not None]


ALL_COMMANDS = [command for document in DOCUMENTS for command in commands_of(document)]
NAMED_SCRIPTS = {
    name for name in SCRIPTS for document in DOCUMENTS if f"`{name}" in document.read_text()
}


# --- What the code says ---------------------------------------------------------------------


def uses_argparse(source: Path) -> bool:
    return source.is_file() and "argparse" in source.read_text()


def help_target(command: Command) -> str | None:
    """What to ask for its --help: "script:NAME", "tool:PATH" or "module:NAME"; None if none."""
    if command.kind == "script" and uses_argparse(SCRIPTS[command.target]):
        return f"script:{command.target}"
    if command.kind == "tool" and uses_argparse(REPO / command.target):
        return f"tool:{command.target}"
    module_file = module_source(command.target) if command.kind == "module" else None
    if module_file is not None and uses_argparse(module_file):
        return f"module:{command.target}"
    return None


def module_source(module: str) -> Path | None:
    """The file of a module of the repository (``tools.X`` or a package's), None if elsewhere."""
    top = module.split(".")[0]
    roots = (
        [REPO] if top == "tools" else [REPO / "src" / top] if (REPO / "src" / top).is_dir() else []
    )
    for root in roots:
        path = root.joinpath(*module.split("."))
        for candidate in (path.with_suffix(".py"), path / "__main__.py"):
            if candidate.is_file():
                return candidate
    return None


HELP_DRIVER = r"""
import contextlib, io, json, runpy, sys
from importlib.metadata import entry_points

scripts = {ep.name: ep for ep in entry_points(group="console_scripts")}
texts = {}
for target in sys.argv[1:]:
    kind, name = target.split(":", 1)
    sys.argv = [name, "--help"]
    output, code = io.StringIO(), None
    with contextlib.redirect_stdout(output), contextlib.redirect_stderr(output):
        try:
            if kind == "script":
                scripts[name].load()()
            elif kind == "tool":
                sys.path.insert(0, name.rsplit("/", 1)[0])
                runpy.run_path(name, run_name="__main__")
            else:
                runpy.run_module(name, run_name="__main__", alter_sys=True)
        except SystemExit as stop:
            code = stop.code
    texts[target] = {"code": code, "text": output.getvalue()}
print(json.dumps(texts))
"""


@pytest.fixture(scope="module")
def help_texts() -> dict[str, dict]:
    """The --help of every script, tool and module the documents use, from one process (the
    imports they share are made once)."""
    targets = {target for command in ALL_COMMANDS if (target := help_target(command))}
    targets |= {f"script:{name}" for name in NAMED_SCRIPTS if uses_argparse(SCRIPTS[name])}
    completed = subprocess.run(
        [sys.executable, "-c", HELP_DRIVER, *sorted(targets)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT_S,
    )
    assert completed.returncode == 0, completed.stderr[-2000:]
    return json.loads(completed.stdout.splitlines()[-1])


def makefile_targets() -> set[str]:
    return set(re.findall(r"^([\w-]+):", (REPO / "Makefile").read_text(), flags=re.M))


def options_used(arguments: tuple[str, ...]) -> list[tuple[str, str | None]]:
    """(option, the token after it) for each option before the command's terminators."""
    cleaned = [token.strip("[](),") for token in arguments]
    used = []
    for index, token in enumerate(cleaned):
        if token in OPTION_TERMINATORS:
            break
        if re.fullmatch(r"--?[A-Za-z][\w-]*(=.*)?", token):
            following = cleaned[index + 1] if index + 1 < len(cleaned) else None
            used.append((token.split("=")[0], following))
    return used


def repository_paths(command: Command) -> list[str]:
    paths = []
    for token in command.tokens:
        if token in OPTION_TERMINATORS:
            break
        candidate = token.strip("[](),").split("=")[-1]
        if "/" in candidate and candidate.split("/")[0] in COMMITTED_DIRECTORIES:
            paths.append(candidate)
    return paths


def problems_of(command: Command, help_texts: dict[str, dict]) -> list[str]:
    problems = [
        f"{path} does not exist" for path in repository_paths(command) if not (REPO / path).exists()
    ]
    checks = {
        "script": script_problems,
        "make": make_problems,
        "tool": tool_problems,
        "module": module_problems,
        "launch": launch_problems,
        "pip": pip_problems,
        "code": lambda command, help_texts: [],
    }
    return problems + checks[command.kind](command, help_texts)


def option_problems(command: Command, help_texts: dict[str, dict], skip: int) -> list[str]:
    """Every option against the --help of what runs; ``skip`` tokens name what runs."""
    target = help_target(command)
    options = options_used(command.tokens[skip:])
    if target is None:
        return [
            f"{command.target} takes no options, yet is given {option}" for option, _ in options
        ]
    text = help_texts[target]["text"]
    problems = []
    for option, value in options:
        if not re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", text):
            problems.append(f"{option} is not an option of {command.target}")
        problems += choice_problems(option, value, text)
    return problems


def choice_problems(option: str, value: str | None, help_text: str) -> list[str]:
    """A value given to an option with choices must be one of them (placeholders aside)."""
    choices = re.search(rf"{re.escape(option)} \{{([^}}]*)\}}", help_text)
    if not choices or not value or value.startswith("-") or PLACEHOLDER.match(value):
        return []
    allowed = choices.group(1).split(",")
    return [] if value in allowed else [f"{option} {value}: not one of {choices.group(1)}"]


def script_problems(command, help_texts):
    if not (BIN / command.target).is_file():
        return [f"{command.target} is not installed in the venv"]
    return option_problems(command, help_texts, skip=1)


def make_problems(command, help_texts):
    targets = [token for token in command.tokens[1:] if not token.startswith("-")]
    return [
        f"make has no target {target}" for target in targets if target not in makefile_targets()
    ]


def tool_problems(command, help_texts):
    if not (REPO / command.target).is_file():
        return [f"{command.target} does not exist"]
    return option_problems(command, help_texts, skip=2)  # python tools/X.py


def module_problems(command, help_texts):
    top = command.target.split(".")[0]
    if top != "tools" and not (REPO / "src" / top).is_dir():
        return []  # a module of a dependency (pytest, ...)
    if module_source(command.target) is None:
        return [f"module {command.target} does not exist"]
    return option_problems(command, help_texts, skip=3)  # python -m MODULE


def launch_problems(command, help_texts):
    launch_file = REPO / command.target
    if not launch_file.is_file():
        return [f"{command.target} does not exist"]
    source = launch_file.read_text()
    arguments = [token.strip("[]").split(":=")[0] for token in command.tokens[4:] if ":=" in token]
    return [
        f"{command.target} declares no argument {argument}"
        for argument in arguments
        if not re.search(rf"DeclareLaunchArgument\(\s*[\"']{argument}[\"']", source)
    ]


def pip_problems(command, help_texts):
    pins = (REPO / "requirements.txt").read_text() + (REPO / "requirements-dev.txt").read_text()
    requirements = [token for token in command.tokens[2:] if not token.startswith("-")]
    return [
        f"{requirement} is not pinned so" for requirement in requirements if requirement not in pins
    ]


# --- Links ------------------------------------------------------------------------------------


def heading_anchors(document: Path) -> set[str]:
    """The anchors GitHub gives the headings of a Markdown file."""
    _, prose = split_fences(document.read_text())
    anchors, seen = set(), {}
    for heading in re.findall(r"^#{1,6} +(.+?) *#*$", prose, flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


def relative_links(document: Path) -> list[str]:
    _, prose = split_fences(document.read_text())
    prose = re.sub(r"(`+).+?\1", "", prose, flags=re.S)
    links = re.findall(r"\]\(([^)\s]+)\)", prose)
    return [link for link in links if not re.match(r"^[a-z]+:", link)]


def document_id(document: Path) -> str:
    return str(document.relative_to(REPO))


@pytest.mark.parametrize("document", DOCUMENTS, ids=document_id)
def test_every_relative_link_resolves_to_a_file_and_heading(document):
    broken = []
    for link in relative_links(document):
        path_part, _, anchor = link.partition("#")
        target = (document.parent / path_part).resolve() if path_part else document
        if not target.exists():
            broken.append(f"{link}: no file {target.relative_to(REPO)}")
        elif anchor and anchor not in heading_anchors(target):
            broken.append(f"{link}: no heading #{anchor} in {target.relative_to(REPO)}")
    assert broken == [], "\n".join(broken)


def test_the_readme_links_every_document_of_docs():
    linked = {
        (REPO / link.partition("#")[0]).resolve() for link in relative_links(REPO / "README.md")
    }
    assert [document_id(d) for d in DOCS if d.resolve() not in linked] == []


# --- Commands ---------------------------------------------------------------------------------


@pytest.mark.parametrize("document", DOCUMENTS, ids=document_id)
def test_a_console_block_holds_only_commands_the_suite_ships(document):
    unknown = [line for line in console_lines(document) if recognised(document, line, True) is None]
    assert unknown == []


@pytest.mark.parametrize("document", DOCUMENTS, ids=document_id)
def test_every_command_names_what_exists_and_options_its_help_lists(document, help_texts):
    problems = {
        command.line: found
        for command in ALL_COMMANDS
        if command.document == document and (found := problems_of(command, help_texts))
    }
    assert problems == {}, "\n".join(f"{line}: {found}" for line, found in problems.items())


def test_the_help_of_every_console_script_named_succeeds(help_texts):
    """Nodes without a command line of their own (they take only ROS arguments) are checked
    to be installed."""
    failed = {}
    for name in sorted(NAMED_SCRIPTS):
        if not (BIN / name).is_file():
            failed[name] = "not installed in the venv"
        elif uses_argparse(SCRIPTS[name]):
            answer = help_texts[f"script:{name}"]
            if answer["code"] not in (0, None) or not answer["text"].startswith("usage:"):
                failed[name] = answer["text"][-500:]
    assert failed == {}


@pytest.fixture(scope="module")
def repository_copy(tmp_path_factory) -> Path:
    """The repository root as a reader sees it, with an ``out/`` of its own."""
    root = tmp_path_factory.mktemp("repository")
    for entry in REPO.iterdir():
        if entry.name != "out":
            (root / entry.name).symlink_to(entry)
    (root / "out").mkdir()
    return root


def test_the_quick_console_commands_run_as_written(repository_copy):
    """In document order, the README first; a line that already ran is not run twice."""
    environment = {**os.environ, "PATH": f"{BIN}:{os.environ['PATH']}"}
    ran, failures = set(), {}
    for document in DOCUMENTS:
        for line in console_lines(document):
            command = recognised(document, line, True)
            quick = command.kind == "code" or (
                command.kind == "script" and command.target in RUN_FOR_REAL
            )
            if not quick or line in ran:
                continue
            ran.add(line)
            completed = subprocess.run(
                ["bash", "-c", line],
                cwd=repository_copy,
                env=environment,
                capture_output=True,
                text=True,
                timeout=COMMAND_TIMEOUT_S,
            )
            if completed.returncode != 0:
                failures[f"{document_id(document)}: {line}"] = completed.stderr[-1000:]
    assert ran, "no console command ran"
    assert failures == {}, "\n\n".join(f"{line}\n{error}" for line, error in failures.items())


# --- Tables the code fills ------------------------------------------------------------------


def table_rows_after(document: Path, heading: str) -> list[list[str]]:
    """The body rows of the first table under a heading, as lists of cells."""
    lines = document.read_text().split(f"\n{heading}\n", 1)[1].splitlines()
    start = next(index for index, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows[2:]  # after the header and its rule


def test_the_readme_names_every_registered_aiding_source():
    rows = table_rows_after(REPO / "README.md", "## Aiding sources")
    named = {row[1].strip("`"): row for row in rows}
    missing = []
    for source in AIDING_SOURCES:
        row = named.get(source.__name__)
        module_file = f"`{source.__module__.rsplit('.', 1)[-1]}.py`"
        if row is None or row[0] != module_file:
            missing.append(f"{source.__name__} ({module_file})")
        elif not source.pseudo and row[2] != f"`{source.topic}`":
            missing.append(f"{source.__name__}: topic {source.topic}, the table says {row[2]}")
    assert missing == []
    assert len(rows) == len(AIDING_SOURCES), "the table names a source that is not registered"


def pinned_distributions() -> set[str]:
    names = set()
    for requirements in ("requirements.txt", "requirements-dev.txt"):
        for line in (REPO / requirements).read_text().splitlines():
            if re.match(r"^[A-Za-z]", line):
                names.add(re.split(r"[\[=<>]", line)[0])
    return names


def test_the_readme_says_why_of_every_pinned_dependency():
    rows = table_rows_after(REPO / "README.md", "## Dependencies")
    explained = " ".join(row[0] for row in rows if len(row) > 1 and row[1]).lower()
    assert [name for name in sorted(pinned_distributions()) if name.lower() not in explained] == []
