"""``process_archive`` on a Dask ``LocalCluster`` of two worker processes, over an archive of
committed bags (linked in), a bag of two buoys under namespaces, a corrupt bag and a bag
without IMU: every good bag's outputs are ``process_bag``'s, the combined table holds every
product of every bag, the failures are listed, a second run skips what is done, and a changed
parameter re-does it. With ``--products-only`` the same products are written and no bag."""

from __future__ import annotations

import contextlib
import csv
import heapq
import io
import math
import shutil
from pathlib import Path

import distributed
import pandas
import pyarrow.parquet as pq
import pytest

from buoy_common.bag_io import BagReader, BagWriter
from buoy_nav.config import fusion_config_from_files
from buoy_processing.archive import BAG_COLUMN, COMBINED_TABLE, MARKER_SUFFIX, STATE_DIRECTORY
from buoy_processing.bag_processing import (
    ISO_TIME_COLUMNS,
    process_bag,
    product_field_of_csv_column,
    products_csv_path,
)
from buoy_processing.process_archive import EXIT_FAILED_BAGS, main
from processed_bags import BAGS_DIR, BUOY_PARAMETERS
from wind_comp.config import compensator_config_from_files

pytestmark = [pytest.mark.long, pytest.mark.xdist_group("process_archive")]

# The two shortest committed bags, at two depths of the tree.
GOOD_BAGS = {"buoy_a/2026-01/static": "static", "buoy_b/wind_tunnel_10": "wind_tunnel_10"}
# A bag of two buoys under namespaces: the first FLEET_KEPT_S of two committed bags.
FLEET_BAG = "fleet/2026-02"
FLEET = {"/buoy1": "static", "/buoy2": "wind_tunnel_10"}
FLEET_KEPT_S = 20.0
CORRUPT_BAG = "buoy_b/corrupt"
NO_IMU_BAG = "buoy_c/no_imu"
# CSV values carry 6 decimals.
CSV_TOLERANCE = 1e-6


def build_archive(root: Path) -> Path:
    archive = root / "archive"
    for relative, name in GOOD_BAGS.items():
        (archive / relative).parent.mkdir(parents=True)
        (archive / relative).symlink_to(BAGS_DIR / name)
    # An MCAP file cut before its first chunk ends: nothing of it is readable.
    corrupt = archive / CORRUPT_BAG
    corrupt.mkdir(parents=True)
    shutil.copy(BAGS_DIR / "static" / "metadata.yaml", corrupt)
    (corrupt / "static.mcap").write_bytes((BAGS_DIR / "static" / "static.mcap").read_bytes()[:4000])
    no_imu = archive / NO_IMU_BAG
    no_imu.parent.mkdir(parents=True)
    # The first 5 s of a committed bag without its IMU.
    with BagReader(BAGS_DIR / "wind_tunnel_10") as reader, BagWriter(no_imu) as writer:
        end_ns = reader.start_ns + 5_000_000_000
        for message in reader.messages(["/gnss/fix", "/gnss/heading", "/anemometer/wind"]):
            if message.log_time_ns <= end_ns:
                writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
    write_fleet(archive / FLEET_BAG)
    return archive


def write_fleet(out: Path) -> None:
    """Each bag of FLEET under its namespace, cut to FLEET_KEPT_S, merged in log-time order."""

    def tagged(namespace: str, name: str):
        with BagReader(BAGS_DIR / name) as reader:
            end_ns = reader.start_ns + int(FLEET_KEPT_S * 1e9)
            for message in reader.messages():
                if message.log_time_ns <= end_ns:
                    yield message.log_time_ns, namespace + message.topic, message

    out.parent.mkdir(parents=True)
    with BagWriter(out) as writer:
        for log_time_ns, topic, message in heapq.merge(
            *(tagged(namespace, name) for namespace, name in FLEET.items()),
            key=lambda item: item[0],
        ):
            writer.write_raw(topic, message.msgtype, log_time_ns, message.raw)


def parameter_file(directory: Path, anemometer_height_m: float, comment: str = "") -> Path:
    """buoy.yaml with the anemometer at ``anemometer_height_m`` above the IMU."""
    text = BUOY_PARAMETERS.read_text()
    old = "position: [0.0, 0.0, 3.0]"
    assert old in text
    path = directory / "buoy.yaml"
    path.write_text(comment + text.replace(old, f"position: [0.0, 0.0, {anemometer_height_m}]"))
    return path


def records(bag: Path) -> list[tuple[str, str, int, bytes]]:
    with BagReader(bag) as reader:
        return [(m.topic, m.msgtype, m.log_time_ns, bytes(m.raw)) for m in reader.messages()]


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        worker_dashboard_address=None,
    ) as local_cluster:
        yield local_cluster


class ArchiveRun:
    def __init__(self, code: int, stdout: str, stderr: str):
        self.code, self.stdout, self.stderr = code, stdout, stderr

    def done(self) -> set[str]:
        return {
            line.split()[1].rstrip(":") for line in self.stdout.splitlines() if line[:5] == "done "
        }


def run_tool(cluster, archive: Path, out: Path, params: Path, *options: str) -> ArchiveRun:
    """``process_archive ARCHIVE OUT --params-file PARAMS OPTIONS`` on ``cluster``."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        arguments = [str(archive), str(out), "--params-file", str(params), *options]
        try:
            main([*arguments, "--scheduler", cluster.scheduler_address])
            code = 0
        except SystemExit as exit_:
            code = exit_.code
    return ArchiveRun(code, stdout.getvalue(), stderr.getvalue())


@pytest.fixture(scope="module")
def archive_runs(cluster, tmp_path_factory):
    """The archive processed three times: first, again unchanged, then with a parameter file
    whose comments changed, then with a changed anemometer height."""
    root = tmp_path_factory.mktemp("archive")
    archive = build_archive(root)
    out = root / "out"

    def run(params: Path) -> ArchiveRun:
        return run_tool(cluster, archive, out, params)

    params_dir = root / "params"
    params_dir.mkdir()
    first = run(parameter_file(params_dir, 3.0))
    markers = {
        relative: (out / STATE_DIRECTORY / (relative + MARKER_SUFFIX)).stat().st_mtime_ns
        for relative in GOOD_BAGS
    }
    table_after_first = pq.read_table(out / COMBINED_TABLE).to_pylist()
    outputs_after_first = {
        relative: (records(out / relative), products_csv_path(out / relative).read_text())
        for relative in GOOD_BAGS
    }
    again = run(parameter_file(params_dir, 3.0))
    commented = run(parameter_file(params_dir, 3.0, comment="# the same values\n"))
    markers_unchanged = all(
        (out / STATE_DIRECTORY / (relative + MARKER_SUFFIX)).stat().st_mtime_ns == mtime
        for relative, mtime in markers.items()
    )
    higher = run(parameter_file(params_dir, 3.5))
    return {
        "archive": archive,
        "out": out,
        "first": first,
        "table_after_first": table_after_first,
        "outputs_after_first": outputs_after_first,
        "again": again,
        "commented": commented,
        "markers_unchanged": markers_unchanged,
        "higher": higher,
        "higher_table": pq.read_table(out / COMBINED_TABLE).to_pylist(),
    }


def test_failures_are_listed_with_their_reasons_and_the_exit_code_says_so(archive_runs):
    first = archive_runs["first"]
    assert first.code == EXIT_FAILED_BAGS
    failed = {
        line.split(": ")[2]: line
        for line in first.stderr.splitlines()
        if line.startswith("process_archive: failed: ")
    }
    assert set(failed) == {CORRUPT_BAG, NO_IMU_BAG}
    assert "imu/data_raw" in failed[NO_IMU_BAG]
    assert "static.mcap" in failed[CORRUPT_BAG]
    assert first.done() == {*GOOD_BAGS, FLEET_BAG}


def test_each_bag_gets_what_process_bag_writes_for_it(archive_runs, tmp_path):
    for relative, name in GOOD_BAGS.items():
        reference = tmp_path / name
        process_bag(
            BAGS_DIR / name,
            reference,
            fusion_config_from_files([BUOY_PARAMETERS]),
            compensator_config_from_files([BUOY_PARAMETERS]),
        )
        archived_records, archived_csv = archive_runs["outputs_after_first"][relative]
        # The same serialised messages, on the same topics, at the same log times.
        assert archived_records == records(reference)
        assert archived_csv == products_csv_path(reference).read_text()


def test_a_fleet_bag_gets_one_output_per_buoy_as_process_bag_writes_them(archive_runs):
    fleet_out = archive_runs["out"] / FLEET_BAG
    rows = [row for row in archive_runs["table_after_first"] if row[BAG_COLUMN] == FLEET_BAG]
    for namespace in FLEET:
        buoy = namespace.strip("/")
        with BagReader(fleet_out / buoy) as reader:
            assert f"{namespace}/wind/true" in reader.topics
        products = list(csv.DictReader(products_csv_path(fleet_out / buoy).open()))
        buoy_rows = [row for row in rows if row["namespace"] == namespace]
        assert len(buoy_rows) == len(products) > 0
    assert {row["namespace"] for row in rows} == set(FLEET)


def test_combined_table_holds_every_product_of_every_bag(archive_runs):
    rows = archive_runs["table_after_first"]
    assert {row[BAG_COLUMN] for row in rows} == {*GOOD_BAGS, FLEET_BAG}
    for relative in GOOD_BAGS:
        bag_rows = [row for row in rows if row[BAG_COLUMN] == relative]
        expected = list(
            csv.DictReader(io.StringIO(archive_runs["outputs_after_first"][relative][1]))
        )
        assert len(bag_rows) == len(expected) > 0
        for row, csv_row in zip(bag_rows, expected, strict=True):
            assert row["namespace"] == "/"
            for column, text in csv_row.items():
                if column in ISO_TIME_COLUMNS:
                    continue
                name = product_field_of_csv_column(column)
                value = float(text)
                if math.isnan(value):
                    assert math.isnan(row[name])
                else:
                    assert row[name] == pytest.approx(value, abs=CSV_TOLERANCE)


def test_a_second_run_skips_the_bags_done_and_retries_the_failed(archive_runs):
    for run in (archive_runs["again"], archive_runs["commented"]):
        assert run.code == EXIT_FAILED_BAGS
        assert run.done() == set()
        assert "3 done before" in run.stdout
        assert f"failed: {CORRUPT_BAG}" in run.stderr
    assert archive_runs["markers_unchanged"]


def test_a_changed_parameter_redoes_every_bag(archive_runs):
    higher = archive_runs["higher"]
    assert higher.done() == {*GOOD_BAGS, FLEET_BAG}
    before = archive_runs["table_after_first"]
    after = archive_runs["higher_table"]
    assert len(after) == len(before)
    # A higher anemometer on a moving buoy sees other motion: the corrected wind changes.
    assert any(
        a["mean_u_enu_mps"] != b["mean_u_enu_mps"] for a, b in zip(after, before, strict=True)
    )


def test_products_only_writes_the_same_products_and_no_bag(archive_runs, cluster, tmp_path):
    """No output bag, so no nav/* or tf: only the products CSVs and the combined table, which
    hold what the run that wrote the bags put in them."""
    out = tmp_path / "products_only"
    only = run_tool(
        cluster,
        archive_runs["archive"],
        out,
        parameter_file(tmp_path, 3.0),
        "--products-only",
    )
    assert only.code == EXIT_FAILED_BAGS
    assert only.done() == {*GOOD_BAGS, FLEET_BAG}
    assert not [path for path in out.rglob("*") if path.suffix == ".mcap"]
    assert not list(out.rglob("metadata.yaml"))
    for relative in GOOD_BAGS:
        assert not (out / relative).exists()
        _, csv_with_bags = archive_runs["outputs_after_first"][relative]
        assert products_csv_path(out / relative).read_text() == csv_with_bags
    for namespace in FLEET:
        assert products_csv_path(out / FLEET_BAG / namespace.strip("/")).is_file()
    pandas.testing.assert_frame_equal(
        pq.read_table(out / COMBINED_TABLE).to_pandas(),
        pandas.DataFrame(archive_runs["table_after_first"]),
    )
