"""The mutation check (`make mutants`, tools/mutation_check.py) only means something while each
of its edits still finds the code it mutates: every mutant applies to a copy of the sources,
and the copy then differs from the original in every edited file."""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def _mutation_check():
    spec = importlib.util.spec_from_file_location(
        "mutation_check", REPO / "tools" / "mutation_check.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


MUTATION_CHECK = _mutation_check()


@pytest.mark.parametrize("mutant", MUTATION_CHECK.MUTANTS, ids=lambda mutant: mutant.name)
def test_each_mutant_still_applies_to_the_code(mutant, tmp_path):
    edited = sorted({edit.path for edit in mutant.edits})
    for path in edited:
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / path, tmp_path / path)
    MUTATION_CHECK.apply(mutant, tmp_path)
    for path in edited:
        assert (tmp_path / path).read_text() != (REPO / path).read_text(), path
