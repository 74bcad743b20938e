"""Outputs never overwrite, contain or sit inside an input, and appear only when complete."""

from __future__ import annotations

import pytest

from buoy_common.safe_output import (
    OutputError,
    check_outputs_apart_from_inputs,
    move_into_place,
    staged_file,
    staging_path,
)


@pytest.fixture
def input_bag(tmp_path):
    bag = tmp_path / "data" / "bag"
    bag.mkdir(parents=True)
    (bag / "bag.mcap").write_bytes(b"precious")
    return bag


@pytest.mark.parametrize(
    ("output", "relation"),
    [
        ("data/bag", "is the input"),
        ("data/bag/", "is the input"),
        ("data/./bag", "is the input"),
        ("data/other/../bag", "is the input"),
        ("data", "contains the input"),
        (".", "contains the input"),
        ("data/bag/out", "lies inside the input"),
        ("data/bag/deeper/out", "lies inside the input"),
    ],
)
def test_output_overlapping_the_input_is_refused(
    tmp_path, monkeypatch, input_bag, output, relation
):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(OutputError, match=relation) as raised:
        check_outputs_apart_from_inputs([input_bag], [output])
    assert output in str(raised.value) and str(input_bag) in str(raised.value)


def test_a_link_to_the_input_is_the_input(tmp_path, input_bag):
    link = tmp_path / "link"
    link.symlink_to(input_bag)
    with pytest.raises(OutputError, match="is the input"):
        check_outputs_apart_from_inputs([input_bag], [link])
    with pytest.raises(OutputError, match="lies inside the input"):
        check_outputs_apart_from_inputs([link], [input_bag / "out"])


@pytest.mark.parametrize("output", ["data/bag2", "data/ba", "bag", "data/out/bag"])
def test_outputs_beside_the_input_are_accepted(tmp_path, input_bag, output):
    check_outputs_apart_from_inputs([input_bag], [tmp_path / output])


def test_every_output_is_checked_against_every_input(tmp_path, input_bag):
    other = tmp_path / "other"
    with pytest.raises(OutputError, match="is the input"):
        check_outputs_apart_from_inputs([other, input_bag], [tmp_path / "out", input_bag])


def test_staged_file_replaces_the_old_file_only_when_complete(tmp_path):
    final = tmp_path / "products.csv"
    final.write_text("old\n")
    with pytest.raises(RuntimeError), staged_file(final) as stream:
        stream.write("half")
        raise RuntimeError("interrupted")
    assert final.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["products.csv"]
    with staged_file(final) as stream:
        stream.write("new\n")
        assert final.read_text() == "old\n"
    assert final.read_text() == "new\n"
    assert [p.name for p in tmp_path.iterdir()] == ["products.csv"]


def test_move_into_place_keeps_or_replaces_an_existing_output(tmp_path):
    final = tmp_path / "out"
    final.mkdir()
    (final / "old").write_text("old")
    staged = staging_path(final)
    staged.mkdir()
    (staged / "new").write_text("new")
    assert staged.parent == final.parent
    with pytest.raises(OutputError, match="appeared"):
        move_into_place(staged, final, replace=False)
    assert (final / "old").read_text() == "old"
    move_into_place(staged, final, replace=True)
    assert sorted(p.name for p in final.iterdir()) == ["new"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
