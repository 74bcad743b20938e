"""The launch files, read as far as this machine allows.

``launch`` and ``launch_ros`` do not install from PyPI, so the files cannot run here. They are
parsed instead: every node they start must be an executable its package installs, every
package file they name must exist and be installed, every argument must be declared with a
description, documented in the file and in the README, and every argument an include passes
must be one the included file declares.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
LAUNCH_FILES = sorted(REPO.glob("src/*/launch/*.launch.py"))
README = (REPO / "README.md").read_text()


def call_name(node: ast.Call) -> str:
    return node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", "")


def calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call) and call_name(n) == name]


def keyword(call: ast.Call, name: str):
    return next((k.value for k in call.keywords if k.arg == name), None)


def string_constants(node) -> list[str]:
    return [
        n.value for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str)
    ]


def console_scripts(package: str) -> set[str]:
    setup = (REPO / "src" / package / "setup.py").read_text()
    return set(re.findall(r'"(\w+) = [\w.]+:main"', setup))


def package_files(call: ast.Call) -> Path | None:
    """The file a ``PathJoinSubstitution([FindPackageShare("pkg"), "dir", "file"])`` names."""
    parts = call.args[0].elts
    if not (isinstance(parts[0], ast.Call) and call_name(parts[0]) == "FindPackageShare"):
        return None
    package = parts[0].args[0].value
    return REPO / "src" / package / Path(*[p.value for p in parts[1:]])


def declared_arguments(tree) -> dict[str, ast.Call]:
    return {call.args[0].value: call for call in calls(tree, "DeclareLaunchArgument")}


@pytest.fixture(params=LAUNCH_FILES, ids=lambda path: path.name)
def launch_file(request) -> tuple[Path, ast.Module]:
    return request.param, ast.parse(request.param.read_text())


def test_there_are_launch_files_for_the_processing_and_the_demo():
    assert {path.name for path in LAUNCH_FILES} >= {"processing.launch.py", "demo.launch.py"}


def test_every_node_is_an_installed_executable(launch_file):
    path, tree = launch_file
    nodes = calls(tree, "Node")
    assert nodes
    for node in nodes:
        package = keyword(node, "package").value
        executable = keyword(node, "executable")
        names = (
            string_constants(tree)  # a loop over a tuple of names
            if isinstance(executable, ast.Name)
            else [executable.value]
        )
        scripts = console_scripts(package)
        named = [name for name in names if name in scripts or name.endswith("_node")]
        assert named, f"{path.name}: no executable of {package} found"
        for name in named:
            assert name in scripts, f"{path.name}: {package} installs no executable {name}"


def test_every_package_file_exists_and_is_installed(launch_file):
    path, tree = launch_file
    named = [package_files(call) for call in calls(tree, "PathJoinSubstitution")]
    named = [file for file in named if file is not None]
    assert named
    for file in named:
        assert file.is_file(), f"{path.name} names {file.relative_to(REPO)}, which does not exist"
        setup = (file.parents[1] / "setup.py").read_text()
        assert f'"{file.parent.name}"' in setup and file.suffix in setup, (
            f"{file.relative_to(REPO)} is not installed by its setup.py"
        )


def test_every_argument_is_declared_described_and_documented(launch_file):
    path, tree = launch_file
    declared = declared_arguments(tree)
    docstring = ast.get_docstring(tree)
    for name, call in declared.items():
        description = keyword(call, "description")
        assert description is not None and description.value.strip(), f"{name}: no description"
        assert f"``{name}``" in docstring, f"{path.name}: argument {name} not in its docstring"
        assert f"{name}:=" in README or f"`{name}`" in README, f"README misses {name}"
    for call in calls(tree, "LaunchConfiguration"):
        assert call.args[0].value in declared, f"{path.name}: {call.args[0].value} undeclared"


def test_an_include_passes_only_arguments_the_included_file_declares(launch_file):
    path, tree = launch_file
    for include in calls(tree, "IncludeLaunchDescription"):
        included = package_files(include.args[0])
        passed = keyword(include, "launch_arguments")
        names = [key.value for key in passed.func.value.keys]
        accepted = declared_arguments(ast.parse(included.read_text()))
        assert set(names) <= set(accepted), f"{path.name} passes {names} to {included.name}"
