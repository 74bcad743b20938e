"""The bookkeeping of ``process_archive`` without processing: which directories are bags, and
when a completion marker still vouches for a bag's outputs."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from buoy_nav.config import FusionConfig
from buoy_processing.archive import (
    BAG_COLUMN,
    NAMESPACE_COLUMN,
    ArchiveError,
    BagJob,
    BagOutcome,
    bag_identity,
    completed_outcome,
    find_bags,
    parameters_digest,
    suite_version,
    write_combined_table,
    write_marker,
    write_products_fragment,
)
from buoy_processing.process_archive import print_warnings
from wind_comp.config import CompensatorConfig


def make_bag(directory: Path, *, metadata: bool = True) -> Path:
    directory.mkdir(parents=True)
    if metadata:
        (directory / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (directory / f"{directory.name}.mcap").write_bytes(b"\x89MCAP0\r\n")
    return directory


def test_bags_are_found_at_any_depth_through_links_and_not_searched_inside(tmp_path):
    archive = tmp_path / "archive"
    make_bag(archive / "buoy1" / "2026-01-01")
    make_bag(archive / "buoy1" / "2026-01-02" / "nested_in_a_bag")
    (archive / "buoy1" / "2026-01-02" / "metadata.yaml").write_text("{}\n")
    make_bag(archive / "buoy2" / "unfinished", metadata=False)
    (archive / "buoy2" / "notes").mkdir()
    elsewhere = make_bag(tmp_path / "elsewhere" / "linked")
    (archive / "buoy3").mkdir()
    (archive / "buoy3" / "linked").symlink_to(elsewhere)
    (archive / "buoy3" / "linked_again").symlink_to(elsewhere)
    (archive / "buoy3" / "loop").symlink_to(archive)

    assert find_bags(archive) == [
        "buoy1/2026-01-01",
        "buoy1/2026-01-02",
        "buoy2/unfinished",
        "buoy3/linked",
        "buoy3/linked_again",
    ]


def test_a_single_bag_is_no_archive(tmp_path):
    with pytest.raises(ArchiveError, match="is a bag"):
        find_bags(make_bag(tmp_path / "one"))


@pytest.fixture
def done_job(tmp_path) -> BagJob:
    """A bag whose outputs, fragment and marker are in place, as a finished worker leaves them."""
    archive, out = tmp_path / "archive", tmp_path / "out"
    make_bag(archive / "buoy1" / "day1")
    fusion, compensator = FusionConfig(), CompensatorConfig()
    job = BagJob(
        "buoy1/day1",
        str(archive),
        str(out),
        fusion,
        compensator,
        None,
        (),
        parameters_digest(fusion, compensator, None, ()),
        "1.0",
    )
    job.out_bag.mkdir(parents=True)
    outputs = [job.out_bag, job.out_bag.with_name("day1_wind_products.csv")]
    outputs[1].write_text("window_s\n")
    job.fragment.parent.mkdir(parents=True)
    write_products_fragment(job.relative, [], job.fragment)
    outcome = BagOutcome(job.relative, "done", outputs=[str(path) for path in outputs])
    write_marker(job, bag_identity(job.in_bag), outcome)
    return job


def test_a_marker_vouches_for_an_unchanged_bag(done_job):
    assert completed_outcome(done_job).status == "skipped"


def test_a_bag_rewritten_since_is_redone(done_job):
    mcap = done_job.in_bag / "day1.mcap"
    mcap.write_bytes(mcap.read_bytes() + b"more")
    assert completed_outcome(done_job) is None


def test_a_bag_touched_since_is_redone(done_job):
    mcap = done_job.in_bag / "day1.mcap"
    status = mcap.stat()
    os.utime(mcap, ns=(status.st_atime_ns, status.st_mtime_ns + 1_000_000_000))
    assert completed_outcome(done_job) is None


def test_other_parameters_or_another_version_redo_the_bag(done_job):
    higher = dataclasses.replace(
        done_job.compensator_config, anemometer_position_body_m=(0.0, 0.0, 3.5)
    )
    other_digest = parameters_digest(done_job.fusion_config, higher, None, ())
    assert other_digest != done_job.digest
    assert completed_outcome(dataclasses.replace(done_job, digest=other_digest)) is None
    assert completed_outcome(dataclasses.replace(done_job, version="1.1")) is None
    namespaced = parameters_digest(
        done_job.fusion_config, done_job.compensator_config, "/buoy1", ()
    )
    assert namespaced != done_job.digest


def test_a_missing_output_redoes_the_bag(done_job):
    done_job.out_bag.with_name("day1_wind_products.csv").unlink()
    assert completed_outcome(done_job) is None


def test_the_combined_table_says_which_version_wrote_it_and_its_conventions(done_job):
    """Read with pyarrow, as any reader of the file would: the suite's version and the
    conventions of the columns travel in the file, for every bag's rows alike."""
    table = pq.read_table(write_combined_table(Path(done_job.out), [done_job.relative]))
    assert table.schema.metadata[b"wind_comp_version"].decode() == suite_version()
    conventions = table.schema.metadata[b"conventions"].decode()
    for stated in ("East, North, Up", "FROM, clockwise from true north", "QARTOD", "1970-01-01"):
        assert stated in conventions
    assert table.column_names[:2] == [BAG_COLUMN, NAMESPACE_COLUMN]


def test_a_warning_many_bags_share_is_said_once_with_their_count(capsys):
    shared = "no velocity reference: no GNSS and fusion.moored is false"
    outcomes = [
        BagOutcome(f"2026/01/01/{hour:02d}", "done", warnings=[shared]) for hour in range(3)
    ]
    outcomes[1].warnings.append("recovered 10 s of a cut bag")
    print_warnings(outcomes)
    said = capsys.readouterr().err.splitlines()
    assert said == [
        f"process_archive: warning: 3 bags (the first 2026/01/01/00): {shared}",
        "process_archive: warning: 2026/01/01/01: recovered 10 s of a cut bag",
    ]
