"""The current sections of ``make bench`` (tools/bench.py): paper 003's ship, the buoy scenarios
with a DVL, and what averaging removes, beside the paper's figures and this project's targets.

Two sections, the same tables:

- ``current`` (in the default set, about two minutes): ``ship_current`` for 20 minutes (the
  paper's 0.2 h and 8 minutes of averaging after it), ``sea_state`` for 11 minutes (one
  complete 10-minute window);
- ``current_long`` (opt-in, ``--only current_long``; tens of minutes): ``ship_current`` for the
  paper's hour, ``sea_state`` and ``open_ocean`` for an hour each (six 10-minute windows).

Table 7 (paper 003, its test case): ``ship_current`` processed by ``process_bag``; the mean of
the current estimates after 0.2 h, as the paper averages them, beside its 60.29°, its East and
North errors and its claim of 0.1 % of the current's speed. Twice: with the DVL of the scenario
(the paper's 0.2 % ± 0.2 cm/s, systematic) and with that DVL's systematic errors taken out (ping
noise only), which is the estimate's own accuracy.

Table 8 (the buoys): single samples against the water at the DVL and against the current, the
10-minute means against the current.

Table 8b: the error of the window means against the window length, on the same runs.
"""

from __future__ import annotations

import math

import numpy as np

from buoy_common.bag_io import BagReader
from buoy_processing.report.current import (
    CurrentData,
    current_data_from_bag,
    error_by_window_length,
    window_errors,
)

# ---------------------------------------------------------------------------------------------
# The paper's figures (paper 003, test case): the ship runs North at 5 m/s through a current of
# 2 m/s toward N60°E for 1 h; the estimates after 0.2 h averaged give 60.29°, errors of
# 0.0015 m/s East and 0.0095 m/s North (signs not given), "less than 0.1 % of the current".
PAPER_CURRENT = {
    "speed_mps": 2.0,
    "direction_deg": 60.0,
    "estimated_direction_deg": 60.29,
    "east_error_mps": 0.0015,
    "north_error_mps": 0.0095,
    "claimed_speed_error_fraction": 0.001,
    "averaged_after_s": 0.2 * 3600.0,
}

# Targets of this project.
PAPER_SPEED_ERROR_FRACTION = 0.001  # of the 2 m/s current
PAPER_DIRECTION_ERROR_DEG = 0.1
BUOY_MEAN_ERROR_MPS = 0.01  # 10-min mean current, vector error
BUOY_DIRECTION_ERROR_DEG = 2.0
BUOY_MIN_CURRENT_MPS = 0.2  # the direction target holds for currents this fast or faster
BUOY_MEAN_WINDOW_S = 600.0

# Runs: section -> (paper run length, buoy run length, buoy scenarios); with --quick the long
# section runs as long as the short one's paper runs.
CURRENT_RUNS = {
    "current": (1200.0, 660.0, ("sea_state",)),
    "current_long": (3600.0, 3600.0, ("sea_state", "open_ocean")),
}
QUICK_LONG_DURATION_S = 1200.0
# The paper's DVL without its systematic errors: ping noise only.
CALIBRATED_DVL = ("sensors.dvl.scale_factor_error_percent=0", "sensors.dvl.bias_mps=[0, 0, 0]")
PAPER_RUNS = {"paper_dvl": (), "calibrated_dvl": CALIBRATED_DVL}


def current_durations(section: str, quick: bool) -> tuple[float, float]:
    """(paper run, buoy run) lengths of ``section``, s."""
    paper_s, buoy_s, _ = CURRENT_RUNS[section]
    if quick and section == "current_long":
        return QUICK_LONG_DURATION_S, QUICK_LONG_DURATION_S
    return paper_s, buoy_s


def current_cases(section: str, quick: bool, case_type):
    """The runs of ``section`` (``current`` or ``current_long``) as ``case_type(key, scenario,
    overrides, pipeline, analysis, label)``; keys ``<section>/paper/<run>`` and
    ``<section>/buoy/<scenario>``."""
    paper_s, buoy_s = current_durations(section, quick)
    cases = [
        case_type(
            f"{section}/paper/{name}",
            "ship_current",
            (f"duration_s={paper_s:g}", *overrides),
            "process",
            "paper_current",
            f"ship_current, {name.replace('_', ' ')}",
        )
        for name, overrides in PAPER_RUNS.items()
    ]
    cases += [
        case_type(
            f"{section}/buoy/{scenario}",
            scenario,
            (f"duration_s={buoy_s:g}",),
            "process",
            "buoy_current",
            f"{scenario} with its DVL",
        )
        for scenario in CURRENT_RUNS[section][2]
    ]
    return cases


def current_results(section: str, case_results: dict) -> tuple[dict, dict]:
    """(paper runs, buoy runs) of ``section`` among the bench's results."""
    found = {"paper": {}, "buoy": {}}
    for key, value in case_results.items():
        parts = key.split("/")
        if parts[0] == section:
            found[parts[1]][parts[2]] = value
    return found["paper"], found["buoy"]


def _read(out_bag: str) -> CurrentData:
    with BagReader(out_bag) as reader:
        data = current_data_from_bag(reader)
    if data is None or data.truth_current_enu_mps is None:
        raise ValueError(f"{out_bag}: no current/velocity or no truth/current")
    return data


def _horizontal_rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(errors[:, :2] ** 2, axis=1)))) if len(errors) else math.nan


def _direction_rms_deg(estimate: np.ndarray, reference: np.ndarray) -> float:
    """RMS of the direction (toward) of each estimate minus its reference's, over the samples
    whose reference flows at least BUOY_MIN_CURRENT_MPS (a slack reference has no direction)."""
    fast = np.hypot(reference[:, 0], reference[:, 1]) >= BUOY_MIN_CURRENT_MPS
    if not fast.any():
        return math.nan
    difference = np.degrees(
        np.arctan2(estimate[fast, 0], estimate[fast, 1])
        - np.arctan2(reference[fast, 0], reference[fast, 1])
    )
    return float(np.sqrt(np.mean(((difference + 180.0) % 360.0 - 180.0) ** 2)))


def _toward_deg(vector) -> float:
    return math.degrees(math.atan2(vector[0], vector[1])) % 360.0


def analyse_paper_current(out_bag: str, scenario_duration_s: float) -> dict:
    """The paper's figures of merit: the mean of the estimates after 0.2 h."""
    data = _read(out_bag)
    valid = np.all(np.isfinite(data.current_enu_mps), axis=1)
    after = valid & (data.t_s - data.t_s[0] >= PAPER_CURRENT["averaged_after_s"])
    mean = data.current_enu_mps[after].mean(axis=0)
    truth = data.truth_current_enu_mps[after].mean(axis=0)
    speed, true_speed = math.hypot(mean[0], mean[1]), math.hypot(truth[0], truth[1])
    direction_error = (_toward_deg(mean) - _toward_deg(truth) + 180.0) % 360.0 - 180.0
    speed_error = speed - true_speed
    return {
        "scenario_duration_s": scenario_duration_s,
        "samples": int(np.count_nonzero(valid)),
        "averaged_samples": int(np.count_nonzero(after)),
        "mean_enu_mps": mean.tolist(),
        "east_error_mps": float(mean[0] - truth[0]),
        "north_error_mps": float(mean[1] - truth[1]),
        "vector_error_mps": float(np.hypot(*(mean - truth)[:2])),
        "speed_mps": speed,
        "speed_error_mps": speed_error,
        "speed_error_fraction": speed_error / true_speed,
        "direction_deg": _toward_deg(mean),
        "direction_error_deg": direction_error,
        "single_sample_rms_vs_water_mps": _horizontal_rms(
            data.current_enu_mps[valid] - data.truth_water_enu_mps[valid]
        ),
        "pass_speed": bool(abs(speed_error) <= PAPER_SPEED_ERROR_FRACTION * true_speed),
        "pass_direction": bool(abs(direction_error) <= PAPER_DIRECTION_ERROR_DEG),
    }


def analyse_buoy_current(out_bag: str, scenario_duration_s: float) -> dict:
    data = _read(out_bag)
    valid = np.all(np.isfinite(data.current_enu_mps), axis=1)
    errors = window_errors(
        data.t_s, data.current_enu_mps, data.truth_current_enu_mps, BUOY_MEAN_WINDOW_S
    )
    fast = errors.reference_speed_mps >= BUOY_MIN_CURRENT_MPS
    by_length = error_by_window_length(data)
    max_error = float(errors.vector_error_mps.max()) if errors.vector_error_mps.size else math.nan
    max_direction = (
        float(np.abs(errors.direction_error_deg[fast]).max()) if fast.any() else math.nan
    )
    return {
        "scenario_duration_s": scenario_duration_s,
        "samples": int(valid.size),
        "invalid_samples": int(np.count_nonzero(~valid)),
        "single_sample_rms_vs_water_mps": _horizontal_rms(
            data.current_enu_mps[valid] - data.truth_water_enu_mps[valid]
        ),
        "single_sample_rms_vs_current_mps": _horizontal_rms(
            data.current_enu_mps[valid] - data.truth_current_enu_mps[valid]
        ),
        "single_sample_direction_rms_vs_water_deg": _direction_rms_deg(
            data.current_enu_mps[valid], data.truth_water_enu_mps[valid]
        ),
        "single_sample_direction_rms_vs_current_deg": _direction_rms_deg(
            data.current_enu_mps[valid], data.truth_current_enu_mps[valid]
        ),
        "windows": int(errors.vector_error_mps.size),
        "windows_at_or_above_min_current": int(np.count_nonzero(fast)),
        "true_speed_range_mps": [
            float(errors.reference_speed_mps.min()),
            float(errors.reference_speed_mps.max()),
        ]
        if errors.reference_speed_mps.size
        else [math.nan, math.nan],
        "mean_vector_error_max_mps": max_error,
        "mean_vector_error_rms_mps": float(np.sqrt(np.mean(errors.vector_error_mps**2)))
        if errors.vector_error_mps.size
        else math.nan,
        "mean_speed_error_max_mps": float(np.abs(errors.speed_error_mps).max())
        if errors.speed_error_mps.size
        else math.nan,
        "mean_direction_error_max_deg": max_direction,
        "pass_mean_error": bool(max_error <= BUOY_MEAN_ERROR_MPS),
        "pass_direction": bool(max_direction <= BUOY_DIRECTION_ERROR_DEG),
        "by_window_length": [row._asdict() for row in by_length],
    }


CURRENT_ANALYSES = {"paper_current": analyse_paper_current, "buoy_current": analyse_buoy_current}


# ---------------------------------------------------------------------------------------------
# Tables.


def _window_name(window_s: float) -> str:
    return "1 sample" if window_s == 0 else f"{window_s:g} s"


def _mark(passed: bool) -> str:
    return "PASS" if passed else "MISS"


def print_current(section: str, paper: dict[str, dict], buoys: dict[str, dict], quick: bool):
    paper_s, buoy_s = current_durations(section, quick)
    print(
        f"\nTable 7 — current ({section}), paper 003's ship: process_bag on ship_current "
        f"({paper_s:g} s)"
    )
    print(
        "mean of current/velocity after 0.2 h against truth/current (2 m/s toward 60°); targets "
        f"|speed error| ≤ {PAPER_SPEED_ERROR_FRACTION:.1%} of the speed, |direction error| ≤ "
        f"{PAPER_DIRECTION_ERROR_DEG}°"
    )
    print(
        f"{'run':32s} {'toward':>9s} {'E err':>9s} {'N err':>9s} {'speed err':>10s} "
        f"{'dir err':>8s} {'1-sample RMS':>13s}"
    )
    p = PAPER_CURRENT
    print(
        f"{'paper 003':32s} {p['estimated_direction_deg']:8.2f}° {p['east_error_mps']:9.4f} "
        f"{p['north_error_mps']:9.4f} {'< 0.1 %':>10s} {p['estimated_direction_deg'] - 60:+7.2f}° "
        f"{'—':>13s}   (signs of its errors not given)"
    )
    for name, r in paper.items():
        label = {
            "paper_dvl": "ours, the paper's DVL",
            "calibrated_dvl": "ours, DVL without systematic error",
        }[name]
        print(
            f"{label:32s} {r['direction_deg']:8.2f}° {r['east_error_mps']:+9.4f} "
            f"{r['north_error_mps']:+9.4f} {r['speed_error_fraction']:+9.3%} "
            f"{r['direction_error_deg']:+7.3f}° {r['single_sample_rms_vs_water_mps']:13.4f}   "
            f"speed {_mark(r['pass_speed'])}, direction {_mark(r['pass_direction'])}"
        )

    print(f"\nTable 8 — current ({section}), the buoys with a DVL: process_bag ({buoy_s:g} s)")
    print(
        "single samples against the water at the DVL (the estimate's own error) and against "
        "the current (the waves' orbital velocity included); 10-min means against the current "
        f"(targets: vector error ≤ {BUOY_MEAN_ERROR_MPS} m/s, direction ≤ "
        f"{BUOY_DIRECTION_ERROR_DEG}° where the current is ≥ {BUOY_MIN_CURRENT_MPS} m/s)"
    )
    print(
        "single-sample directions where the reference flows at ≥ "
        f"{BUOY_MIN_CURRENT_MPS} m/s; speeds in m/s"
    )
    print(f"{'':12s} {'':13s} {'single samples, RMS':^37s} {'10-min means':^26s}")
    print(
        f"{'scenario':12s} {'current':>13s} {'vs water':>9s} {'dir':>7s} {'vs current':>11s} "
        f"{'dir':>7s} {'max':>9s} {'RMS':>7s} {'dir max':>8s} {'windows':>8s}"
    )
    for scenario, r in buoys.items():
        low, high = r["true_speed_range_mps"]
        print(
            f"{scenario:12s} {low:5.2f}–{high:4.2f} m/s {r['single_sample_rms_vs_water_mps']:9.4f} "
            f"{r['single_sample_direction_rms_vs_water_deg']:6.2f}° "
            f"{r['single_sample_rms_vs_current_mps']:11.4f} "
            f"{r['single_sample_direction_rms_vs_current_deg']:6.2f}° "
            f"{r['mean_vector_error_max_mps']:9.4f} "
            f"{r['mean_vector_error_rms_mps']:7.4f} {r['mean_direction_error_max_deg']:7.2f}° "
            f"{r['windows']:8d}   error {_mark(r['pass_mean_error'])}, direction "
            f"{_mark(r['pass_direction'])}"
        )

    print("\nTable 8b — what averaging removes: RMS horizontal error of window means (m/s)")
    print(
        "estimate − current = the waves' part (water at the DVL − current, falls as 1/T) plus "
        "the estimate's own (estimate − water, noise falls as 1/√T, the DVL's bias stays)"
    )
    for scenario, r in buoys.items():
        rows = r["by_window_length"]
        header = " ".join(f"{_window_name(row['window_s']):>9s}" for row in rows)
        print(f"{scenario:12s} {'window':18s} {header}")
        for field, label in (
            ("estimate_vs_current_mps", "estimate − current"),
            ("water_vs_current_mps", "water − current"),
            ("estimate_vs_water_mps", "estimate − water"),
        ):
            values = " ".join(f"{row[field]:9.4f}" for row in rows)
            print(f"{'':12s} {label:18s} {values}")
