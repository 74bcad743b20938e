"""The offline tools never destroy their input, never leave half an output under its name, and
process what is left of a bag that was cut short, saying so with exit code 3."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import bag_faults
import numpy as np
import pytest
import xarray as xr
from nav_msgs.msg import Odometry

from buoy_common.bag_io import RECOVERED_BAG_EXIT_CODE, BagReader, BagWriter
from buoy_common.contract import QualityFlag
from buoy_common.safe_output import OutputError
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_fusion import fuse_bag
from buoy_processing.bag_processing import process_bag
from processed_bags import made_once
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
STATIC_BAG = REPO / "bags" / "static"
# The first minute of the static bag: the third of its file the cut-input test keeps still
# holds two complete chunks (about 10 s each), more than the 10 s the fusion takes to align and
# the chunk whose loss that test must see.
SHORT_BAG_S = 60.0
LONG_BAG = REPO / "bags" / "sea_state"
RUNS_TO_CATCH_MID_RUN = 3
TOOLS = ("fuse_bag", "process_bag")


def run_tool(tool: str, *arguments) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(BIN / tool), *map(str, arguments), "--params-file", str(BUOY_PARAMETERS)],
        capture_output=True,
        text=True,
        timeout=300,
    )


def contents(directory: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(directory)): p.read_bytes() for p in directory.rglob("*") if p.is_file()
    }


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory) -> Path:
    """The first ``SHORT_BAG_S`` of ``bags/static``, every topic, written once per session."""

    def make(directory: Path) -> None:
        bag_faults.write_records(
            bag_faults.read_records(STATIC_BAG, None, SHORT_BAG_S), directory / "bag"
        )

    return made_once(tmp_path_factory, f"static_first_{SHORT_BAG_S:g}s", make) / "bag"


@pytest.fixture
def input_bag(tmp_path, short_bag):
    """A copy of the short bag of the test's own, which the test may cut or overwrite."""
    bag = tmp_path / "in"
    shutil.copytree(short_bag, bag)
    return bag


@pytest.mark.parametrize("tool", TOOLS)
def test_the_input_given_as_output_is_refused_and_left_intact(tmp_path, input_bag, tool):
    before = contents(tmp_path)
    completed = run_tool(tool, input_bag, input_bag, "--overwrite")
    assert completed.returncode == 2, completed.stderr
    message = completed.stderr.strip()
    assert message.startswith(f"{tool}: ") and "\n" not in message, message
    assert "is the input" in message and "corrupt" not in message
    assert contents(tmp_path) == before


@pytest.mark.parametrize("tool", TOOLS)
@pytest.mark.parametrize(
    ("output", "relation"),
    [
        ("./in/", "is the input"),
        ("in/out", "lies inside the input"),
        (".", "contains the input"),
    ],
)
def test_an_output_overlapping_the_input_is_refused_before_anything_is_touched(
    tmp_path, monkeypatch, input_bag, tool, output, relation
):
    monkeypatch.chdir(tmp_path)
    before = contents(tmp_path)
    with pytest.raises(OutputError, match=relation):
        if tool == "fuse_bag":
            fuse_bag("in", output, fusion_config_from_files([]), overwrite=True)
        else:
            process_bag(
                "in",
                output,
                fusion_config_from_files([]),
                compensator_config_from_files([]),
                overwrite=True,
            )
    assert contents(tmp_path) == before


@pytest.mark.parametrize("tool", TOOLS)
def test_a_cut_input_is_processed_up_to_its_last_complete_chunk(tmp_path, input_bag, tool):
    (mcap_file,) = input_bag.glob("*.mcap")
    with mcap_file.open("r+b") as stream:
        stream.truncate(mcap_file.stat().st_size // 3)
    (input_bag / "metadata.yaml").unlink()  # as a recorder that lost power leaves it
    with BagReader(input_bag) as reader:
        recovered = reader.recovery.messages
        recovered_imu = reader.topics["/imu/data_raw"].count
    out = tmp_path / "out"
    completed = run_tool(tool, input_bag, out)
    assert completed.returncode == RECOVERED_BAG_EXIT_CODE, completed.stderr
    assert f"recovered {recovered} messages" in completed.stderr
    assert "Traceback" not in completed.stderr
    with BagReader(out) as reader:
        assert reader.recovery is None
        # one navigation solution per IMU sample once aligned (10 s of 100 Hz)
        assert recovered_imu - 1100 < reader.topics["/nav/odometry"].count < recovered_imu


def leftovers(directory: Path) -> list[str]:
    """Names of partial or set-aside outputs in ``directory``."""
    return sorted(
        p.name for p in directory.iterdir() if ".partial-" in p.name or ".replaced-" in p.name
    )


def _restore(directory: Path, files: dict[str, bytes]) -> None:
    for path in list(directory.iterdir()):
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    for name, data in files.items():
        (directory / name).parent.mkdir(parents=True, exist_ok=True)
        (directory / name).write_bytes(data)


def _wait_for_partial(out: Path, process: subprocess.Popen) -> None:
    deadline = time.monotonic() + 60
    while not list(out.parent.glob(f"{out.name}.partial-*")):
        if process.poll() is not None:
            assert process.returncode == 0, process.communicate()
            return
        assert time.monotonic() < deadline
        time.sleep(0.01)


@pytest.mark.parametrize("tool", TOOLS)
@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_an_interrupted_run_keeps_the_old_output_and_leaves_no_partial_one(tmp_path, tool, how):
    out = tmp_path / "out"
    with BagWriter(out) as writer:
        writer.write("/nav/odometry", "nav_msgs/msg/Odometry", 1, Odometry())
    old_csv = tmp_path / "out_wind_products.csv"
    old_csv.write_text("the products of an earlier run\n")
    before = contents(tmp_path)
    # On a busy machine the tool may finish the bag before its writing process has started:
    # such a run was not interrupted, and is run again on the old outputs it replaced.
    for _ in range(RUNS_TO_CATCH_MID_RUN):
        process = subprocess.Popen(
            [str(BIN / tool), str(LONG_BAG), str(out), "--overwrite"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        _wait_for_partial(out, process)
        if process.poll() is None:
            break
        process.communicate()
        _restore(tmp_path, before)
    process.send_signal(how)
    process.communicate(timeout=60)
    assert process.returncode != 0
    # The writing process of a killed tool sees its pipe close and deletes the partial bag.
    deadline = time.monotonic() + 30
    while leftovers(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert leftovers(tmp_path) == []
    assert contents(tmp_path) == before


def test_an_existing_netcdf_file_is_replaced_only_with_overwrite(tmp_path, input_bag):
    netcdf = tmp_path / "out.nc"
    netcdf.write_text("someone's file")
    completed = run_tool("process_bag", input_bag, tmp_path / "out", "--netcdf", netcdf)
    assert completed.returncode == 2, completed.stderr
    message = completed.stderr.strip()
    assert message.startswith("process_bag: ") and "--overwrite" in message, message
    assert netcdf.read_text() == "someone's file"
    assert not (tmp_path / "out").exists()
    completed = run_tool(
        "process_bag", input_bag, tmp_path / "out", "--netcdf", netcdf, "--overwrite"
    )
    assert completed.returncode == 0, completed.stderr
    with xr.open_dataset(netcdf) as dataset:
        assert dataset["eastward_wind"].size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "in",
        "out",
        "out.nc",
        "out_wind_fluxes.csv",
        "out_wind_products.csv",
    ]


def test_all_invalid_wind_still_gives_the_navigation_and_says_why(tmp_path, input_bag):
    wrong_frame = tmp_path / "wrong_frame.yaml"
    wrong_frame.write_text(
        "/**:\n  ros__parameters:\n    compensation:\n      anemometer_frame_id: sonic_link\n"
    )
    netcdf = tmp_path / "out.nc"
    completed = run_tool(
        "process_bag",
        input_bag,
        tmp_path / "out",
        "--netcdf",
        netcdf,
        "--params-file",
        wrong_frame,
    )
    assert completed.returncode == 4, completed.stderr
    assert "most wind samples are invalid" in completed.stderr
    assert "expected 'sonic_link'" in completed.stderr
    with xr.open_dataset(netcdf) as dataset:
        assert np.isnan(dataset["eastward_wind"].values).all()
        meanings = dataset["wind_status"].attrs["flag_meanings"].split()
        assert {meanings[code] for code in dataset["wind_status"].values} == {"invalid_wind"}
        assert np.isfinite(dataset["latitude"].values).all() and dataset["latitude"].size > 0
        flags = dataset["wind_1min_quality_flag"].values
        assert (flags == QualityFlag.MISSING).all() and flags.size > 0


RECORD = REPO / "tests" / "data" / "ooi_fdchp" / "fdchp_test_dp.dat"
COLUMN_MAP = REPO / "src" / "buoy_common" / "config" / "records" / "ooi_fdchp.yaml"
RECORD_COPIES = 8
"""Copies of the 20-minute record in one file: long enough to be interrupted while its bag is
written (the samples are numbered, so the copies follow one another in time)."""


def test_an_interrupted_import_exits_130_with_one_line_and_writes_nothing(tmp_path):
    record = tmp_path / "long.dat"
    record.write_text(RECORD.read_text() * RECORD_COPIES)
    out = tmp_path / "out"
    process = subprocess.Popen(
        [str(BIN / "import_records"), str(record), str(COLUMN_MAP), str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    # The screening table is printed once the record is read, just before its bag is written.
    assert process.stdout.readline().startswith("field")
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert "wrote" not in stdout, "the import finished before the signal: make the record longer"
    assert (process.returncode, stderr) == (130, "import_records: interrupted\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.dat"]
