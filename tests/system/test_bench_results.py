"""The bench's machine-readable results: a run of some sections keeps what earlier runs wrote
of the others, each key with when it was measured, and an unreadable earlier file is kept."""

from __future__ import annotations

import json

from tools.bench import earlier_results, merged_results


def run(started_utc: str, **sections) -> dict:
    return {"meta": {"started_utc": started_utc, "sections": sorted(sections)}, **sections}


def test_a_run_of_one_section_keeps_the_others_with_when_they_were_measured():
    full = merged_results(run("2026-01-01T00:00:00Z", speed={"x": 1}, attitude={"y": 2}), {})
    only_speed = merged_results(run("2026-02-01T00:00:00Z", speed={"x": 3}), full)
    assert only_speed["speed"] == {"x": 3}
    assert only_speed["attitude"] == {"y": 2}
    assert only_speed["meta"]["started_utc"] == "2026-02-01T00:00:00Z"
    assert only_speed["meta"]["measured_utc"] == {
        "speed": "2026-02-01T00:00:00Z",
        "attitude": "2026-01-01T00:00:00Z",
    }


def test_results_written_before_the_dates_were_kept_take_their_run_s_start():
    earlier = run("2025-12-01T00:00:00Z", wind={"z": 4})
    merged = merged_results(run("2026-02-01T00:00:00Z", speed={"x": 3}), earlier)
    assert merged["meta"]["measured_utc"]["wind"] == "2025-12-01T00:00:00Z"


def test_an_unreadable_earlier_file_is_kept_not_overwritten(tmp_path, capsys):
    path = tmp_path / "results.json"
    path.write_text('{"speed": ')
    assert earlier_results(path) == {}
    assert not path.exists()
    assert (tmp_path / "results.unreadable.json").read_text() == '{"speed": '
    assert "not JSON" in capsys.readouterr().err
    path.write_text(json.dumps({"speed": {"x": 1}}))
    assert earlier_results(path) == {"speed": {"x": 1}}
