"""IMU faults injected into ``bags/sea_state``, judged against the bag's own truth.

Each fault (:data:`bag_faults.IMU_FAULTS`) is written into a copy of the first ``KEPT_S`` seconds
of the bag, processed by ``process_bag``, and the
output compared with ``truth/odometry`` and ``truth/wind``:

- five gyro samples of 30 rad/s on one axis (inside the 35 rad/s magnitude limit);
- one accelerometer sample of 100 m/s² (inside the 160 m/s² limit);
- the IMU's stamps jumping back 5 s, or forward 5 s, for the rest of the recording.

After each, no valid ``wind/true`` sample may be off the true wind by more than
``MAX_WIND_ERROR_MPS``, the attitude must be within the RTK targets from 30 s after the fault
on, and the run must still correct nearly every wind sample a clean run corrects (a fault
handled by invalidating everything would pass the first two checks).
"""

from __future__ import annotations

from pathlib import Path

import bag_faults
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from buoy_processing.report.data import interpolate_vectors, odometry_series, stamped_vectors
from processed_bags import processed_bag
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[2]
SOURCE_CASE = "sea_state"
SOURCE_BAG = REPO / "bags" / SOURCE_CASE
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
KEPT_S = 110.0  # of log time: aligned by 10 s, the fault at 65 s, 30 s to recover, 15 s judged
FAULT_AT_S = 65.0  # of log time
RECOVERY_S = 30.0
MAX_WIND_ERROR_MPS = 0.5
# RTK attitude targets (roll, pitch, heading), deg.
ATTITUDE_TARGETS_DEG = np.array([0.1, 0.1, 0.15])
# Samples a fault may cost (the wind of the spike's own 50 ms, interpolated across).
MAX_LOST_WIND_SAMPLES = 5
STAMP_MATCH_NS = 1000
ANEMOMETER_TOPIC = "/anemometer/wind"


def wind_errors(reader: BagReader) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (ns) of the ``wind/true`` samples and each one's error against ``truth/wind``
    (m/s, NaN where the sample is invalid)."""
    wind = stamped_vectors(reader, "wind/true")
    true_wind = stamped_vectors(reader, "truth/wind")
    return wind.stamps_ns, np.linalg.norm(
        wind.vectors - interpolate_vectors(wind.stamps_ns, true_wind), axis=1
    )


def judged(out: Path):
    """(wind errors of the valid samples m/s, number valid, attitude errors deg (roll, pitch,
    heading) with their stamps s)."""
    with BagReader(out) as reader:
        nav = odometry_series(reader, "nav/odometry")
        truth = odometry_series(reader, "truth/odometry")
        _, wind_error = wind_errors(reader)
    valid = np.isfinite(wind_error)
    position = np.clip(np.searchsorted(truth.stamps_ns, nav.stamps_ns), 0, truth.stamps_ns.size - 1)
    matched = np.abs(truth.stamps_ns[position] - nav.stamps_ns) <= STAMP_MATCH_NS
    estimated = Rotation.from_quat(nav.quat_xyzw[matched])
    true = Rotation.from_quat(truth.quat_xyzw[position[matched]])
    # as_euler("ZYX") is (yaw, pitch, roll) of R = Rz(yaw)·Ry(pitch)·Rx(roll)
    difference = np.degrees(estimated.as_euler("ZYX") - true.as_euler("ZYX"))[:, ::-1]
    attitude_error = np.abs((difference + 180.0) % 360.0 - 180.0)
    return wind_error[valid], int(valid.sum()), attitude_error, nav.stamps_ns[matched] * 1e-9


@pytest.fixture(scope="module")
def source_records() -> list[bag_faults.Record]:
    """The first ``KEPT_S`` of the bag, every topic: read once, each fault copies what it
    changes."""
    return bag_faults.read_records(SOURCE_BAG, None, KEPT_S)


@pytest.fixture(scope="module")
def valid_wind_samples_of_a_clean_run(tmp_path_factory, source_records) -> int:
    """The valid wind samples a clean run of the kept seconds gives.

    Counted in the session's run of the whole bag, which other modules make anyway, over the
    anemometer samples of the kept seconds: ``process_bag`` works forward in time, so what it
    writes for those samples does not depend on what follows them, and is what a run of the
    kept seconds alone writes."""
    kept_stamps_ns = [
        bag_faults.header_stamp_ns(r) for r in source_records if r.topic == ANEMOMETER_TOPIC
    ]
    with BagReader(processed_bag(tmp_path_factory, SOURCE_CASE)) as reader:
        stamps_ns, wind_error = wind_errors(reader)
    kept = np.isin(stamps_ns, kept_stamps_ns)
    assert np.count_nonzero(kept) == len(kept_stamps_ns), "the clean run misses kept samples"
    return int(np.count_nonzero(np.isfinite(wind_error[kept])))


@pytest.fixture(scope="module")
def processed(tmp_path_factory, source_records):
    runs = {}
    base = tmp_path_factory.mktemp("input_faults")

    def run(name: str):
        if name not in runs:
            bag, out = base / f"in_{name}", base / f"out_{name}"
            # the true stamp: a clock fault moves the stamps, not the fusion's time
            fault_s = bag_faults.stamp_at_s(source_records, bag_faults.IMU_TOPIC, FAULT_AT_S)
            records = bag_faults.IMU_FAULTS[name](FAULT_AT_S)(source_records)
            bag_faults.write_records(records, bag)
            summary = process_bag(
                bag,
                out,
                fusion_config_from_files([BUOY_PARAMETERS]),
                compensator_config_from_files([BUOY_PARAMETERS]),
            )
            runs[name] = (fault_s, summary, *judged(out))
        return runs[name]

    return run


@pytest.mark.parametrize(
    "fault", ["gyro_spike", "accelerometer_spike", "clock_back", "clock_forward"]
)
def test_no_wrong_wind_and_the_attitude_recovers(
    processed, valid_wind_samples_of_a_clean_run, fault
):
    fault_s, summary, wind_error, n_valid, attitude_error, attitude_t_s = processed(fault)
    n_valid_clean = valid_wind_samples_of_a_clean_run
    figures = (
        f"{fault}: {n_valid} valid wind samples (clean run {n_valid_clean}), largest error "
        f"{wind_error.max():.3f} m/s; fusion: {summary.fusion_lines}"
    )
    assert np.count_nonzero(wind_error > MAX_WIND_ERROR_MPS) == 0, figures
    assert n_valid >= n_valid_clean - MAX_LOST_WIND_SAMPLES, figures
    after = attitude_t_s >= fault_s + RECOVERY_S
    assert np.count_nonzero(after) > 0, figures
    worst = attitude_error[after].max(axis=0)
    assert np.all(worst <= ATTITUDE_TARGETS_DEG), f"roll, pitch, heading {worst} deg; {figures}"
