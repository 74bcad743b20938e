"""The fault matrix: each fault a row, injected into a stretch of a recorded bag.

A row is a fault (a bag transform of :mod:`bag_faults`), the stamps it touches, and what the suite
must do about it: the rejection reasons it must count and the wind outputs it must mark invalid.
Rows are played in groups: the faults of a group go into one bag, far enough apart not to
interact, so that one offline run and one live replay check every row of the group. What holds
for every row and every group: exactly one ``wind/true`` per ``anemometer/wind`` sample, with
its stamp; no valid ``wind/true`` further from the simulator's true wind than
:data:`WIND_TOLERANCE_MPS`; the live nodes publish what ``process_bag`` writes.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import bag_faults as faults
import numpy as np
from bag_faults import Fault, Record
from live_replay import (
    SENSOR_TOPICS,
    assert_offline_run_is_near_the_truth,
    odometry_arrays,
    vector_arrays,
)

REPO = Path(__file__).resolve().parents[2]
SOURCE_BAG = REPO / "bags" / "sea_state"
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
TRUTH_WIND_TOPIC = "/truth/wind"
WIND_TOLERANCE_MPS = 0.5
"""Largest error of a valid wind sample against the simulator's truth, m/s: the bound the suite
promises after any fault it accepts (the sea_state bag's error without faults is ~0.03 m/s RMS)."""
NAN = math.nan
INF = math.inf


@dataclass(frozen=True)
class FaultRow:
    """One fault and what the suite must do about it."""

    name: str
    fault: Fault
    counted: dict[str, int] = field(default_factory=dict)
    """Rejections the run must count: ``"kind: reason"`` (``imu: non_finite``) or
    ``"/topic: reason"`` for messages the fusion refuses, and ``"wind: <reason>"`` (the
    contract's word, ``invalid_wind``) for wind outputs, each at least this many times."""
    invalid_between_s: tuple[float, float] | None = None
    """Stamps (s from the first record) whose wind outputs must all be invalid."""


@dataclass(frozen=True)
class FaultGroup:
    name: str
    seconds: float
    rows: tuple[FaultRow, ...]
    within_limits_before_s: float | None = None
    """If given, the run must also keep the wind budget of the clean bag, and its navigation
    the clean bag's limits up to this stamp (s from the first record; after it a fault the
    filter cannot tell from motion leaves it flagged untrusted, by design)
    (:func:`live_replay.assert_offline_run_is_near_the_truth`)."""

    def fault(self) -> Fault:
        return faults.combine(*(row.fault for row in self.rows))


# -- outcomes --------------------------------------------------------------------------------------


@dataclass
class Outcome:
    """What one run (offline or live) produced."""

    wind_ns: np.ndarray
    wind: np.ndarray
    nav_ns: np.ndarray
    nav: np.ndarray
    counted: Counter = field(default_factory=Counter)


def counted_in_summary(fusion_lines: list[str], wind_status_counts: dict[str, int]) -> Counter:
    """The rejections of a ``process_bag`` summary as ``"kind: reason"`` counts."""
    counts: Counter = Counter()
    for line in fusion_lines:
        message = re.match(r"rejected message (\S+): (\w+): (\d+)$", line)
        if message:
            counts[f"{message[1]}: {message[2]}"] += int(message[3])
            continue
        kind = re.match(r"(\w+)\s+accepted.*rejected: (.*)$", line)
        if kind and kind[2] != "none":
            for item in kind[2].split(", "):
                reason, n = item.rsplit(" ", 1)
                counts[f"{kind[1]}: {reason}"] += int(n)
    for outcome, n in wind_status_counts.items():
        counts[f"wind: {outcome}"] += n
    return counts


def truth_wind_at(records: list[Record], stamps_ns: np.ndarray) -> np.ndarray:
    """The true wind (ENU, m/s) at these stamps, interpolated in the truth topic."""
    truth = [r.message() for r in records if r.topic == TRUTH_WIND_TOPIC]
    truth_ns = np.array([faults.stamp_to_ns(m.header.stamp) for m in truth])
    values = np.array([[m.vector.x, m.vector.y, m.vector.z] for m in truth])
    return np.column_stack(
        [np.interp(stamps_ns, truth_ns, values[:, axis], left=NAN, right=NAN) for axis in range(3)]
    )


def wind_input_stamps_ns(records: list[Record]) -> np.ndarray:
    return np.array([faults.header_stamp_ns(r) for r in records if r.topic == "/anemometer/wind"])


def check_row(row: FaultRow, outcome: Outcome, start_ns: int, failures: list[str]) -> None:
    """Append to ``failures`` what the run failed to do for ``row``."""
    for key, minimum in row.counted.items():
        if outcome.counted[key] < minimum:
            failures.append(
                f"{row.name}: counted {outcome.counted[key]} '{key}', expected >= {minimum}"
            )
    if row.invalid_between_s is not None:
        begin_s, end_s = row.invalid_between_s
        relative_s = (outcome.wind_ns - start_ns) * 1e-9
        inside = (relative_s >= begin_s) & (relative_s < end_s)
        valid_inside = int(np.count_nonzero(~np.isnan(outcome.wind[inside]).any(axis=1)))
        if not inside.any() or valid_inside:
            failures.append(
                f"{row.name}: {valid_inside} of {int(inside.sum())} wind outputs between "
                f"{begin_s:g} s and {end_s:g} s are valid; all must be invalid"
            )


def check_outputs(records: list[Record], outcome: Outcome, label: str, failures: list[str]) -> None:
    """One output per input, same stamps; valid outputs within tolerance of the truth."""
    inputs_ns = wind_input_stamps_ns(records)
    if outcome.wind_ns.size != inputs_ns.size or not np.array_equal(outcome.wind_ns, inputs_ns):
        failures.append(
            f"{label}: {outcome.wind_ns.size} wind/true for {inputs_ns.size} anemometer/wind "
            "samples, or stamps differ"
        )
        return
    valid = ~np.isnan(outcome.wind).any(axis=1)
    truth = truth_wind_at(records, outcome.wind_ns)
    error = np.linalg.norm(outcome.wind - truth, axis=1)
    judged = valid & ~np.isnan(truth).any(axis=1)
    if judged.any() and float(np.max(error[judged])) > WIND_TOLERANCE_MPS:
        worst = int(np.argmax(np.where(judged, error, -1.0)))
        start_ns = records[0].log_time_ns
        failures.append(
            f"{label}: valid wind {error[worst]:.2f} m/s from truth at "
            f"{(outcome.wind_ns[worst] - start_ns) * 1e-9:.2f} s "
            f"({int(np.count_nonzero(judged & (error > WIND_TOLERANCE_MPS)))} samples beyond "
            f"{WIND_TOLERANCE_MPS} m/s)"
        )


# -- the rows --------------------------------------------------------------------------------------

IMU = "/imu/data_raw"
FIX = "/gnss/fix"
VEL = "/gnss/vel"
HEADING = "/gnss/heading"
BASELINE = "/gnss/baseline"
WIND = "/anemometer/wind"


def _heading_nan(message) -> None:
    message.orientation.z = NAN


def _heading_turned_90_deg(message) -> None:
    # yaw-only quaternion (0, 0, z, w): a quarter turn more is a product with (0, 0, s, s)
    z, w = message.orientation.z, message.orientation.w
    half = math.sqrt(0.5)
    message.orientation.z, message.orientation.w = half * (z + w), half * (w - z)


def _latitude_moved_50_m(message) -> None:
    message.latitude += 50.0 / 111_000.0


def _latitude_nan(message) -> None:
    message.latitude = NAN


SENSOR_VALUES = FaultGroup(
    "sensor values",
    45.0,
    (
        FaultRow(
            "IMU rate NaN",
            faults.mutate(IMU, 15.0, 2, faults.set_vector("angular_velocity", (NAN, 0.0, 0.0))),
            {"imu: non_finite": 2},
        ),
        FaultRow(
            "IMU specific force inf",
            faults.mutate(IMU, 17.0, 2, faults.set_vector("linear_acceleration", (0, INF, 9.8))),
            {"imu: non_finite": 4},
        ),
        FaultRow(
            "GNSS fix NaN latitude",
            faults.mutate(FIX, 19.0, 1, _latitude_nan),
            {"gnss_fix: non_finite": 1},
        ),
        FaultRow(
            "GNSS velocity inf",
            faults.mutate(VEL, 21.0, 1, faults.set_vector("twist.twist.linear", (INF, 0, 0))),
            {"gnss_velocity: non_finite": 1},
        ),
        FaultRow(
            "GNSS baseline NaN",
            faults.mutate(BASELINE, 23.0, 1, faults.set_vector("vector", (NAN, NAN, NAN))),
            {"gnss_baseline: non_finite": 1},
        ),
        FaultRow(
            "GNSS heading NaN",
            faults.mutate(HEADING, 25.0, 1, _heading_nan),
            {"gnss_heading: non_finite": 1},
        ),
        FaultRow(
            "GNSS position spike 50 m",
            faults.mutate(FIX, 27.0, 1, _latitude_moved_50_m),
            {"gnss_fix: gate": 1},
        ),
        FaultRow(
            "GNSS baseline spike (a quarter turn)",
            faults.mutate(BASELINE, 29.0, 1, faults.set_vector("vector", (0.0, 1.5, 0.0))),
            {"gnss_baseline: gate": 1},
        ),
        FaultRow(
            "anemometer NaN",
            faults.mutate(WIND, 31.0, 3, faults.set_vector("vector", (NAN, 1.0, 0.0))),
            {"wind: invalid_wind": 3},
        ),
        FaultRow(
            "anemometer inf",
            faults.mutate(WIND, 34.0, 2, faults.set_vector("vector", (INF, 1.0, 0.0))),
            {"wind: invalid_wind": 5},
        ),
        FaultRow(
            "sonic error code (NaN components, per the contract)",
            faults.mutate(WIND, 37.0, 4, faults.set_vector("vector", (NAN, NAN, NAN))),
            {"wind: invalid_wind": 9},
        ),
        FaultRow(
            "anemometer spike 150 m/s",
            faults.mutate(WIND, 40.0, 1, faults.add_to_vector("vector", (150.0, 0.0, 0.0))),
            {"wind: wind_speed_out_of_range": 1},
        ),
    ),
)

MESSAGES = FaultGroup(
    "messages",
    70.0,
    (
        FaultRow("IMU duplicate", faults.duplicate(IMU, 42.0), {"imu: duplicate_stamp": 1}),
        FaultRow("IMU out of order", faults.swap(IMU, 45.0), {"imu: stamp_not_increasing": 1}),
        FaultRow(
            "GNSS fix duplicate", faults.duplicate(FIX, 48.0), {"gnss_fix: duplicate_stamp": 1}
        ),
        FaultRow("GNSS fix late by 1 s", faults.delay(FIX, 51.0, 1.0), {"gnss_fix: too_late": 1}),
        # Measurements wait max_measurement_delay_s for the IMU: two swapped within it are
        # put back in order, not rejected.
        FaultRow("GNSS baseline out of order", faults.swap(BASELINE, 54.0)),
        FaultRow("anemometer duplicate", faults.duplicate(WIND, 57.0), {"wind: invalid_stamp": 1}),
        FaultRow("anemometer out of order", faults.swap(WIND, 60.0), {"wind: invalid_stamp": 2}),
        FaultRow(
            "anemometer late by 2 s",
            faults.delay(WIND, 63.0, 2.0),
            {"wind: invalid_stamp": 3},
        ),
    ),
)

OUTAGES = FaultGroup(
    "outages",
    120.0,
    (
        FaultRow(
            "GNSS fix and velocity outage 10 s",
            faults.combine(faults.drop(FIX, 68.0, 78.0), faults.drop(VEL, 68.0, 78.0)),
        ),
        FaultRow(
            "GNSS heading and baseline outage 10 s",
            faults.combine(faults.drop(HEADING, 80.0, 90.0), faults.drop(BASELINE, 80.0, 90.0)),
        ),
        FaultRow("anemometer outage 10 s", faults.drop(WIND, 92.0, 102.0)),
        FaultRow(
            "IMU outage 2 s (realignment)",
            faults.drop(IMU, 105.0, 107.0),
            invalid_between_s=(105.0, 107.0),
        ),
    ),
)

GNSS_CLOCK_JUMP_S = 52.0

IMU_SPIKES_AND_CLOCK = FaultGroup(
    "IMU spikes and clock jumps",
    60.0,
    (
        FaultRow(
            "gyro spike 30 rad/s x5 (under the 35 rad/s limit)",
            faults.gyro_spike(25.0),
            {"imu: implausible_change": 5},
        ),
        FaultRow(
            "accelerometer spike 100 m/s² (under the 160 m/s² limit)",
            faults.accelerometer_spike(30.0),
            {"imu: implausible_change": 6},
        ),
        # The samples after the step are held until they prove to be the IMU's: none lost.
        FaultRow("IMU stamps jump back 5 s", faults.imu_clock_back(35.0)),
        # The IMU's clock back onto the GNSS's: a forward step, re-stamped like the first.
        FaultRow("IMU stamps jump forward 5 s", faults.imu_clock_forward(45.0)),
        # The GNSS's clock ahead of the IMU's for good: positions and velocities of other
        # moments fail the gates, the navigation is not trusted and corrects no wind.
        FaultRow(
            "GNSS fix and velocity stamps jump forward 2 s",
            faults.combine(
                faults.shift_stamps(FIX, GNSS_CLOCK_JUMP_S, 2.0),
                faults.shift_stamps(VEL, GNSS_CLOCK_JUMP_S, 2.0),
            ),
            {"gnss_fix: gate": 1, "wind: navigation_not_trusted": 1},
        ),
    ),
    within_limits_before_s=GNSS_CLOCK_JUMP_S,
)
"""The IMU faults of :data:`bag_faults.IMU_FAULTS`, the IMU's clock stepping back and forward
again 10 s later, and the GNSS's clock jumping ahead."""

SENSOR_MESSAGE_AND_OUTAGE_FAULTS = FaultGroup(
    "sensor values, messages and outages",
    OUTAGES.seconds,
    SENSOR_VALUES.rows + MESSAGES.rows + OUTAGES.rows,
)
"""Sensor values (15–40 s), message faults (42–65 s) and outages (68–107 s) share one bag: none
of them leaves the filter in a state that changes what the others do, and the realignment after
the IMU outage comes last."""

GROUPS = (SENSOR_MESSAGE_AND_OUTAGE_FAULTS, IMU_SPIKES_AND_CLOCK)
"""Each group one bag, one offline run and one live replay."""


# -- running ---------------------------------------------------------------------------------------


def faulted_records(group: FaultGroup) -> list[Record]:
    """The group's stretch of the source bag, with every fault of the group in it."""
    records = faults.read_records(SOURCE_BAG, (*SENSOR_TOPICS, TRUTH_WIND_TOPIC), group.seconds)
    return sorted(group.fault()(records), key=lambda record: record.log_time_ns)


def bag_outcome(bag: Path, counted: Counter | None = None) -> Outcome:
    """The ``wind/true`` and ``nav/odometry`` of a bag (written offline or recorded live)."""
    wind_ns, wind = vector_arrays(bag, "wind/true")
    nav_ns, nav = odometry_arrays(bag)
    return Outcome(wind_ns, wind, nav_ns, nav, counted or Counter())


def run_offline(bag: Path, out: Path) -> Outcome:
    """``process_bag`` of ``bag`` with the shipped extrinsics."""
    from buoy_nav.config import fusion_config_from_files
    from buoy_processing.bag_processing import process_bag
    from wind_comp.config import compensator_config_from_files

    summary = process_bag(
        bag,
        out,
        fusion_config_from_files([BUOY_PARAMETERS]),
        compensator_config_from_files([BUOY_PARAMETERS]),
    )
    return bag_outcome(out, counted_in_summary(summary.fusion_lines, summary.wind.status_counts))


def offline_failures(
    group: FaultGroup, bag: Path, records: list[Record], offline: Path, outcome: Outcome
) -> list[str]:
    if group.within_limits_before_s is not None:
        until_ns = records[0].log_time_ns + round(group.within_limits_before_s * 1e9)
        assert_offline_run_is_near_the_truth("sea_state", bag, offline, group.name, until_ns)
    failures: list[str] = []
    check_outputs(records, outcome, f"{group.name} offline", failures)
    for row in group.rows:
        check_row(row, outcome, records[0].log_time_ns, failures)
    return failures
