"""The README, bags/README.md and docs/ say what the code does: links resolve, commands run.

The documents follow three conventions (docs/development.md, "The documentation and its
commands"):

- a ```console block holds commands a user types at the repository root inside the venv, one a
  line (``#`` starts a comment, a trailing backslash continues the line); the blocks of a
  document run in order, as a reader following it runs them;
- a ```text block holds usage synopses, with placeholders (``IN_BAG``, ``[--overwrite]``);
- inline code that starts with a command the suite ships (``process_bag ...``, ``make bench``,
  ``python -m tools.bench --only fluxes``) is a command too;
- a tool runs as a module of the package ``tools`` (``python -m tools.bench``), never as a
  script path; ``ros2 run PACKAGE EXECUTABLE`` names a console script of that package.

The quick console commands (the offline tools on the committed bags and records, ``python -c``)
run for real in a copy of the repository root whose ``out/`` is a temporary directory. Every
other command, and every synopsis and inline command, is checked instead: the executable, the
``make`` target, the script or the launch file exists, every repository file it names exists,
and every option it uses is in its ``--help`` (a launch argument: declared by the launch file).

What the prose names is checked too: every repository path in backticks exists
(``src/...``, ``tests/...``, a package's ``wind_comp/pipeline.py``, a file name such as
``fusion.yaml``), every dotted name of a package (``buoy_nav.aiding.AIDING_SOURCES``) imports,
the executables tables name each executable with the package that installs it, and the module
table of docs/development.md names each module where it is.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from buoy_nav.aiding import AIDING_SOURCES

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
DOCS = tuple(sorted((REPO / "docs").glob("*.md")))
DOCUMENTS = (
    REPO / "README.md",
    REPO / "bags" / "README.md",
    REPO / "tests" / "data" / "ooi_fdchp" / "README.md",
    *DOCS,
)
COMMITTED_DIRECTORIES = {"src", "bags", "tests", "tools", "docs", "ros2_ws"}
COMMAND_TIMEOUT_S = 300

# Commands that finish in seconds on the committed bags; the others run for minutes or until
# stopped (nodes, live runs, benchmarks) and are checked without running.
RUN_FOR_REAL = {"process_bag", "fuse_bag", "wind_report", "import_records"}
# Where a command line ends for option checking: ROS arguments, pipes, redirections, lists.
OPTION_TERMINATORS = {"--ros-args", "|", "||", "&&", ";", ">", "2>", ">>"}
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*$")


PACKAGES = tuple(sorted(setup.parent.name for setup in REPO.glob("src/*/setup.py")))


def console_scripts_of(package: str) -> dict[str, Path]:
    """A package's console scripts: name -> the source file of their entry point."""
    setup = REPO / "src" / package / "setup.py"
    return {
        name: setup.parent / (module.replace(".", "/") + ".py")
        for name, module in re.findall(r'"(\w+) = ([\w.]+):main"', setup.read_text())
    }


PACKAGE_SCRIPTS = {package: console_scripts_of(package) for package in PACKAGES}
SCRIPTS = {name: path for scripts in PACKAGE_SCRIPTS.values() for name, path in scripts.items()}


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
    kind: str  # script, make, module, code, launch, pip
    target: str  # the script, module or launch file it runs
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
        if rest[0] == "-m" and len(rest) > 1:
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
    """Whether the script parses a command line (argparse, buoy_common.cli's parser, or the
    timed bench tools' in tools/bench_command.py)."""
    if not source.is_file():
        return False
    text = source.read_text()
    return any(parser in text for parser in ("argparse", "command_parser(", "run_timed_tool("))


def help_target(command: Command) -> str | None:
    """What to ask for its --help: "script:NAME" or "module:NAME"; None if none."""
    if command.kind == "script" and uses_argparse(SCRIPTS[command.target]):
        return f"script:{command.target}"
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
            else:
                runpy.run_module(name, run_name="__main__", alter_sys=True)
        except SystemExit as stop:
            code = stop.code
    texts[target] = {"code": code, "text": output.getvalue()}
print(json.dumps(texts))
"""


@pytest.fixture(scope="module")
def help_texts() -> dict[str, dict]:
    """The --help of every script and module the documents use, from one process (the
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


def module_problems(command, help_texts):
    top = command.target.split(".")[0]
    if top != "tools" and not (REPO / "src" / top).is_dir():
        return []  # a module of a dependency (pytest, ...)
    if any(PLACEHOLDER.match(part) for part in command.target.split(".")):
        return []  # a synopsis: python -m tools.NAME
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


# --- What the prose names ---------------------------------------------------------------------

# A name in backticks with one of these endings and no directory is a file of the repository
# (``.md`` and ``.csv`` are also the names of outputs).
FILE_SUFFIXES = (".py", ".yaml", ".json", ".dat", ".npy", ".toml", ".cfg", ".xml")
# The files of the example sensor of docs/adding-a-sensor.md, which its reader writes.
EXAMPLE_FILES = {
    "src/buoy_nav/buoy_nav/aiding/gyrocompass.py",
    "src/buoy_nav/test/test_gyrocompass.py",
    "test_gyrocompass.py",
}
# A segment of a path that stands for a name of the reader's (``OUT_BAG_wind_products.csv``,
# ``DIR/buoy1/``, ``NAME.py``); README is a name of its own.
PATH_PLACEHOLDER = re.compile(r"(^|/)(?!README\b)[A-Z][A-Z0-9_]*(?=[/._]|$)")
# Directories a walk of the repository does not enter: made by builds, runs and the venv.
NOT_COMMITTED = {"out", "build", "install", "log", "__pycache__", "ros2_ws"}


def repository_file_names() -> set[str]:
    names = set()
    for _, directories, files in os.walk(REPO):
        directories[:] = [
            d
            for d in directories
            if not d.startswith(".") and d not in NOT_COMMITTED and not d.endswith(".egg-info")
        ]
        names.update(files)
    return names


FILE_NAMES = repository_file_names()


def path_problem(name: str) -> str | None:
    """Why a name in backticks that reads as a repository path names nothing, None when it
    names something or is no such path (a topic, a placeholder, a file outside the repository).

    ``src/...``, ``bags/...`` (a committed directory) are paths from the repository root; a path
    that starts with a package (``wind_comp/pipeline.py``, ``buoy_nav/config/fusion.yaml``) lies
    in ``src/``, in the package's directory or in its Python package; a bare file name
    (``fusion.yaml``) is the name of some file of the repository."""
    if re.search(r"[\s<>*{}\[\]$=:]|\.\.\.", name) or PATH_PLACEHOLDER.search(name):
        return None
    if name in EXAMPLE_FILES:
        return None
    top = name.split("/")[0]
    if "/" in name and top in COMMITTED_DIRECTORIES:
        candidates = [REPO / name]
    elif "/" in name and top in PACKAGES:
        candidates = [REPO / "src" / name, REPO / "src" / top / name]
    elif "/" not in name and name.endswith(FILE_SUFFIXES):
        return None if name in FILE_NAMES else f"{name}: no file of that name"
    else:
        return None
    return None if any(path.exists() for path in candidates) else f"{name} does not exist"


def dotted_name_problem(name: str) -> str | None:
    """Why ``package.module.attribute`` (a call's arguments aside) does not import, None when
    it does or names no package of the suite."""
    name = re.sub(r"\(.*\)$", "", name)
    parts = name.split(".")
    if not re.fullmatch(r"\w+(\.\w+)+", name) or parts[0] not in (*PACKAGES, "tools"):
        return None
    for length in range(len(parts), 0, -1):
        module_name = ".".join(parts[:length])
        try:
            found = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name is not None and not module_name.startswith(error.name):
                return f"{name}: importing {module_name} fails: {error}"
            continue
        for attribute in parts[length:]:
            if not hasattr(found, attribute):
                return f"{name}: {module_name} has no {'.'.join(parts[length:])}"
            found = getattr(found, attribute)
        return None
    return f"{name}: no such module"


@pytest.mark.parametrize("document", DOCUMENTS, ids=document_id)
def test_every_repository_path_and_module_named_exists(document):
    _, prose = split_fences(document.read_text())
    problems = set()
    for code in inline_code(prose):
        problem = path_problem(code) or dotted_name_problem(code)
        if problem:
            problems.add(problem)
    assert sorted(problems) == [], "\n".join(sorted(problems))


@pytest.mark.parametrize("document", DOCUMENTS, ids=document_id)
def test_tools_are_run_as_modules_of_the_package_tools(document):
    """``python -m tools.X`` runs from the repository root whatever the venv's path holds."""
    script_forms = re.findall(r"\bpython3?\s+(tools/[\w/]+)\.py", document.read_text())
    wrong = [f"{form}.py: write python -m {form.replace('/', '.')}" for form in script_forms]
    assert wrong == [], "\n".join(wrong)


@pytest.mark.parametrize("document", DOCUMENTS, ids=document_id)
def test_ros2_run_names_an_executable_of_the_package(document):
    wrong = []
    for package, executable in re.findall(r"ros2 run +([\w.]+) +(\w+)", document.read_text()):
        if PLACEHOLDER.match(package) or package == "...":
            continue
        if executable not in PACKAGE_SCRIPTS.get(package, {}):
            wrong.append(f"ros2 run {package} {executable}")
    assert wrong == [], "\n".join(wrong)


EXECUTABLES_TABLES = (
    ("README.md", "## Running the nodes"),
    ("docs/running-the-nodes.md", "## Executables"),
)


@pytest.mark.parametrize("document, heading", EXECUTABLES_TABLES)
def test_the_executables_tables_name_the_package_of_each_executable(document, heading):
    rows = table_rows_after(REPO / document, heading)
    misplaced, named = [], set()
    for row in rows:
        package, executables = row[0], re.findall(r"`(\w+)`", row[1])
        named.update(executables)
        misplaced += [
            f"{executable} is not an executable of {package}"
            for executable in executables
            if executable not in PACKAGE_SCRIPTS.get(package, {})
        ]
    assert misplaced == [], "\n".join(misplaced)
    if document == "README.md":
        assert sorted(set(SCRIPTS) - named) == [], "executables the README's table misses"


def test_the_module_table_names_each_module_where_it_is():
    """A bare file name after a path (``wind_comp/compensator.py``, ``miller.py``) lies in
    that path's directory."""
    rows = table_rows_after(REPO / "docs" / "development.md", "## Modules")
    missing = []
    for row in rows:
        directory = None
        for name in re.findall(r"`([^`]+)`", row[0]):
            if "/" in name.rstrip("/"):
                directory = name.rstrip("/").rsplit("/", 1)[0]
            relative = name if "/" in name.rstrip("/") else f"{directory}/{name}"
            package = relative.split("/")[0]
            if not (REPO / "src" / package / relative).exists():
                missing.append(f"{name} ({relative})")
    assert missing == [], "\n".join(missing)


def test_the_layout_names_every_package():
    rows = table_rows_after(REPO / "docs" / "development.md", "## Layout")
    listed = {name for row in rows for name in re.findall(r"`src/(\w+)`", row[0])}
    assert sorted(set(PACKAGES) - listed) == []


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


@pytest.fixture
def repository_copy(tmp_path_factory) -> Path:
    """The repository root as a reader sees it, with an ``out/`` of its own for each test (a
    document's commands begin where its reader does, without another's outputs)."""
    root = tmp_path_factory.mktemp("repository")
    for entry in REPO.iterdir():
        if entry.name != "out":
            (root / entry.name).symlink_to(entry)
    (root / "out").mkdir()
    return root


def expected_exit_code(line: str) -> int:
    """0, or the code a console line documents in a trailing ``# exit code N`` comment (a
    command that finishes with a documented warning, such as process_bag's 4)."""
    documented = re.search(r"#\s*exit code (\d+)", line)
    return int(documented.group(1)) if documented else 0


def quick_lines(document: Path) -> list[str]:
    """The console lines of ``document`` that finish in seconds, each once, in document order."""
    lines = []
    for line in console_lines(document):
        command = recognised(document, line, True)
        quick = command.kind == "code" or (
            command.kind == "script" and command.target in RUN_FOR_REAL
        )
        if quick and line not in lines:
            lines.append(line)
    return lines


# The README's commands run in `make test`; the other documents' reprocess more records, for a
# minute in all, and run with the long runs.
@pytest.mark.parametrize(
    "document",
    [
        pytest.param(
            document,
            id=document_id(document),
            marks=() if document == REPO / "README.md" else pytest.mark.long,
        )
        for document in DOCUMENTS
        if quick_lines(document)
    ],
)
def test_the_quick_console_commands_run_as_written(repository_copy, document):
    """In document order, each line after those it builds on."""
    environment = {**os.environ, "PATH": f"{BIN}:{os.environ['PATH']}"}
    failures = {}
    for line in quick_lines(document):
        problem = run_finite(line, repository_copy, environment, expected_exit_code(line))
        if problem is not None:
            failures[line] = problem
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


FINITE_LIVE_COMMANDS = {"bag_player", "run_scenario"}
"""Live commands of the README that end by themselves: a bag played out, a scenario run."""
LIVE_START_TIMEOUT_S = 120.0
"""How long the README's endless nodes, started together on a busy machine, may take to say
their first line (a node logs its configuration once built; wind_echo prints the wind)."""


def readme_live_lines() -> list[tuple[str, str]]:
    """(executable, line) of the README's console commands that talk DDS, in order."""
    lines = []
    for line in console_lines(REPO / "README.md"):
        command = recognised(REPO / "README.md", line, True)
        if command.kind == "script" and command.target not in RUN_FOR_REAL:
            lines.append((command.target, line))
    return lines


def run_finite(line: str, cwd: Path, environment: dict[str, str], exit_code: int = 0) -> str | None:
    """Run a console line to its end; what went wrong, None when it exits with ``exit_code``."""
    completed = subprocess.run(
        ["bash", "-c", line],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT_S,
    )
    return None if completed.returncode == exit_code else completed.stderr[-1000:]


def run_until_interrupted(lines: list[str], cwd: Path, environment: dict[str, str]) -> dict:
    """Start the console lines together; once each has said something, Ctrl-C them all;
    what went wrong with each that did not run and stop with exit code 0."""
    logs = [cwd / "out" / f"live_{index}.log" for index in range(len(lines))]
    processes = []
    for line, log in zip(lines, logs, strict=True):
        with open(log, "w") as stream:
            processes.append(
                subprocess.Popen(
                    ["bash", "-c", f"exec {line}"],
                    cwd=cwd,
                    env=environment,
                    stdout=stream,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            )
    failures = {}
    try:
        deadline = time.monotonic() + LIVE_START_TIMEOUT_S
        while time.monotonic() < deadline and not all(
            log.stat().st_size or process.poll() is not None
            for log, process in zip(logs, processes, strict=True)
        ):
            time.sleep(0.5)
        running = [
            process.poll() is None and log.stat().st_size
            for log, process in zip(logs, processes, strict=True)
        ]
        for process in processes:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        for line, log, process, was_running in zip(lines, logs, processes, running, strict=True):
            code = process.wait(timeout=30)
            if not was_running or code != 0:
                failures[line] = f"exit {code}: {log.read_text()[-800:]}"
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
    return failures


@pytest.mark.long
def test_the_readme_live_examples_run_as_written(repository_copy, ros_env):
    """The README's live commands, pasted at the repository root in an isolated DDS domain:
    those that end by themselves end with exit code 0; the endless nodes, started together as
    the README's terminals would, run until Ctrl-C and then stop with exit code 0."""
    environment = {**ros_env, "PATH": f"{BIN}:{os.environ['PATH']}"}
    live = readme_live_lines()
    assert {"run_scenario", "bag_player", "fusion_node", "wind_echo"} <= {e for e, _ in live}
    failures = {
        line: problem
        for executable, line in live
        if executable in FINITE_LIVE_COMMANDS
        and (problem := run_finite(line, repository_copy, environment))
    }
    endless = [line for executable, line in live if executable not in FINITE_LIVE_COMMANDS]
    failures.update(run_until_interrupted(endless, repository_copy, environment))
    assert failures == {}, "\n\n".join(f"{line}\n{error}" for line, error in failures.items())
