"""Bags recorded under namespaces: a single buoy in ``/buoy1``, a fleet of two, remapped topics.

What the offline tools write for a namespaced buoy must be what they write for the same
recording at the root, moved into the namespace: the same core on the same messages.
"""

from __future__ import annotations

import heapq
from pathlib import Path

import pytest

from buoy_common.bag_io import BagReader, BagWriter
from buoy_processing import fuse_bag as fuse_bag_command
from buoy_processing import process_bag as process_bag_command
from buoy_processing import wind_report as wind_report_command

REPO = Path(__file__).resolve().parents[2]
BUOY_PARAMETERS = str(REPO / "src" / "buoy_common" / "config" / "buoy.yaml")
# Two committed recordings of different buoys, the first minute of each (enough to align and
# correct; the tests compare outputs, not accuracy).
RECORDINGS = {
    "/buoy1": REPO / "bags" / "vertical_wind_5",
    "/buoy2": REPO / "bags" / "wind_tunnel_10",
}
KEPT_S = 60.0


def write_renamed(out: Path, sources: dict[str, Path], rename=lambda topic: topic) -> Path:
    """A bag holding the first ``KEPT_S`` of each source bag's topics under its namespace (key
    of ``sources``), merged in log-time order, each stored name passed through ``rename``."""

    def tagged(namespace: str, bag: Path):
        with BagReader(bag) as reader:
            end_ns = reader.start_ns + int(KEPT_S * 1e9)
            for message in reader.messages():
                if message.log_time_ns > end_ns:
                    continue
                yield message.log_time_ns, namespace + message.topic, message

    with BagWriter(out) as writer:
        for log_time_ns, topic, message in heapq.merge(
            *(tagged(ns, bag) for ns, bag in sources.items()), key=lambda item: item[0]
        ):
            writer.write_raw(rename(topic), message.msgtype, log_time_ns, message.raw)
    return out


def messages_by_topic(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    with BagReader(bag) as reader:
        found: dict[str, list[tuple[int, bytes]]] = {}
        for message in reader.messages():
            found.setdefault(message.topic, []).append((message.log_time_ns, message.raw))
        return found


def run_command(module, argv: list[str]) -> int:
    try:
        module.main(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    return 0


@pytest.fixture(scope="module")
def buoys(tmp_path_factory) -> dict[str, Path]:
    """Each fleet member's (shortened) recording at the root namespace."""
    folder = tmp_path_factory.mktemp("buoys")
    return {
        namespace: write_renamed(folder / namespace.strip("/"), {"": bag})
        for namespace, bag in RECORDINGS.items()
    }


@pytest.fixture(scope="module")
def fleet_bag(tmp_path_factory) -> Path:
    return write_renamed(tmp_path_factory.mktemp("fleet") / "fleet", RECORDINGS)


@pytest.fixture(scope="module")
def root_processed(buoys, tmp_path_factory) -> dict[str, dict[str, list[tuple[int, bytes]]]]:
    """``process_bag`` of each fleet member's recording at the root namespace."""
    out_dir = tmp_path_factory.mktemp("root")
    found = {}
    for namespace, bag in buoys.items():
        out = out_dir / namespace.strip("/")
        code = run_command(
            process_bag_command, [str(bag), str(out), "--params-file", BUOY_PARAMETERS]
        )
        assert code == 0
        found[namespace] = messages_by_topic(out)
    return found


def test_a_fleet_bag_is_processed_per_namespace_as_each_buoy_alone(
    fleet_bag, root_processed, tmp_path, capsys
):
    out = tmp_path / "fleet_processed"
    code = run_command(
        process_bag_command, [str(fleet_bag), str(out), "--params-file", BUOY_PARAMETERS]
    )
    assert code == 0
    printed = capsys.readouterr().out
    for namespace in RECORDINGS:
        assert f"namespace {namespace} -> {out / namespace.strip('/')}" in printed
        processed = messages_by_topic(out / namespace.strip("/"))
        alone = root_processed[namespace]
        assert sorted(processed) == sorted(namespace + topic for topic in alone)
        for topic, messages in alone.items():
            # The same bytes: the same core ran on the same messages.
            assert [raw for _, raw in processed[namespace + topic]] == [raw for _, raw in messages]
        assert (out / f"{namespace.strip('/')}_wind_products.csv").is_file()

    report = tmp_path / "fleet_report"
    assert run_command(wind_report_command, [str(out / "buoy1"), "--out", str(report)]) == 0
    assert (report / "wind_products.md").is_file()


def test_a_single_namespace_is_found_and_kept(tmp_path, root_processed):
    bag = write_renamed(tmp_path / "buoy2_only", {"/buoy2": RECORDINGS["/buoy2"]})
    out = tmp_path / "fused"
    code = run_command(fuse_bag_command, [str(bag), str(out), "--params-file", BUOY_PARAMETERS])
    assert code == 0
    fused = messages_by_topic(out)
    assert "/buoy2/nav/odometry" in fused and "/nav/odometry" not in fused
    alone = root_processed["/buoy2"]["/nav/odometry"]
    assert [raw for _, raw in fused["/buoy2/nav/odometry"]] == [raw for _, raw in alone]


def test_a_remapped_topic_is_read_under_its_contract_name(tmp_path, root_processed):
    bag = write_renamed(
        tmp_path / "renamed",
        {"/buoy1": RECORDINGS["/buoy1"]},
        rename=lambda topic: topic.replace("/anemometer/wind", "/sonic/wind_raw"),
    )
    out = tmp_path / "processed"
    refused = run_command(process_bag_command, [str(bag), str(out)])
    assert refused == 2
    code = run_command(
        process_bag_command,
        [
            str(bag),
            str(out),
            "--params-file",
            BUOY_PARAMETERS,
            "--namespace",
            "buoy1",
            "--remap",
            "anemometer/wind:=sonic/wind_raw",
        ],
    )
    assert code == 0
    processed = messages_by_topic(out)
    alone = root_processed["/buoy1"]["/wind/true"]
    assert [raw for _, raw in processed["/buoy1/wind/true"]] == [raw for _, raw in alone]


def test_an_absent_namespace_is_named_in_the_error(fleet_bag, tmp_path, capsys):
    code = run_command(
        fuse_bag_command, [str(fleet_bag), str(tmp_path / "out"), "--namespace", "/buoy3"]
    )
    assert code == 2
    error = capsys.readouterr().err
    assert "/buoy3/imu/data_raw" in error and "/buoy1/imu/data_raw" in error
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("bad", ["imu/data_raw", ":=x", "a:=", "imu/data_raw:=/x//y"])
def test_a_malformed_remapping_is_refused(fleet_bag, tmp_path, capsys, bad):
    code = run_command(fuse_bag_command, [str(fleet_bag), str(tmp_path / "out"), "--remap", bad])
    assert code == 2
    error = capsys.readouterr().err
    assert "remapping" in error or "topic name" in error
