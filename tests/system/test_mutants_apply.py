"""The mutation check (`make mutants`, tools/mutation_check.py) only means something while each
of its edits still finds the code it mutates: every mutant applies to a copy of the sources,
and the copy then differs from the original in every edited file."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tools import mutation_check

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("mutant", mutation_check.MUTANTS, ids=lambda mutant: mutant.name)
def test_each_mutant_still_applies_to_the_code(mutant, tmp_path):
    edited = sorted({edit.path for edit in mutant.edits})
    for path in edited:
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / path, tmp_path / path)
    mutation_check.apply(mutant, tmp_path)
    for path in edited:
        assert (tmp_path / path).read_text() != (REPO / path).read_text(), path
