"""`make bench` section ``smoother``: paper 002's Table 1 (forward filter against the
fixed-interval smoother on the ship sway model), and ``smoother_speed``: peak memory and time
of ``--smooth`` on long bags.

Paper 002 (Chen, Zeng, Liu, Wang, "Research on accuracy post-evaluation algorithm of the
integrated navigation system in the shaking environment") simulates 4000 s of ship sway (the
``sea_state`` scenario's motion) with a navigation-grade IMU and a 20 m GPS, and compares the
position, velocity and attitude errors of the Kalman filter and of the smoother, mean and σ,
in its Table 1. The text available to this project carries the table's caption and the
conclusion (the smoothed errors are smaller and flatter) but not its numbers: they are printed
as "n/a".

Errors are evaluated from 60 s after the alignment, at the truth's stamps (every other IMU
sample). The smoothed solution is ``nav/*``, the forward one ``nav/forward/odometry``; the
position error of the smoothed solution comes from ``nav/fix`` against the truth's geodetic
position, that of the forward one adds the difference of the two odometries (same ``map``
frame). The forward wind is the anemometer recorrected with ``nav/forward/odometry`` through the
same compensation pipeline.
"""

from __future__ import annotations

import dataclasses
import os
import resource
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    NAV_FIX_TOPIC,
    NAV_FORWARD_ODOMETRY_TOPIC,
    NAV_ODOMETRY_TOPIC,
    TRUTH_ODOMETRY_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
)
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from buoy_processing.report.data import stamped_vectors
from sensor_sim.geodesy import meridian_radius_m, prime_vertical_radius_m
from sensor_sim.scenario import load_scenario
from tools.bench_analysis import matching_indices, rms, wrap_deg
from tools.bench_plan import PROCESSING_PARAMS
from wind_comp.compensation_messages import anemometer_sample, fix_fields, odometry_fields
from wind_comp.config import compensator_config_from_files
from wind_comp.pipeline import wind_pipeline

# Section smoother_table1 runs the paper's 4000 s (a long section); the default section
# smoother the same cases on 300 s, a few minutes in all.
TABLE1_DURATION_S = {
    "smoother_table1": {"full": 4000.0, "quick": 600.0},
    "smoother": {"full": 300.0, "quick": 180.0},
}
EVALUATE_AFTER_ALIGNMENT_S = 60.0
# Paper 002, section 3, simulation conditions 3-4: accelerometer first-order Markov 1e-5 g;
# gyro random constant 0.01 °/h, white noise 0.01 °/h (taken as °/√h), first-order Markov
# 0.01 °/h; GPS position 20 m, 20 m, 50 m and velocity 0.2 m/s per axis. What the paper does not
# give is set to zero (scale factor, accelerometer white noise and switch-on bias); the
# correlation times, which it does not give either, keep this project's defaults. The paper
# fuses GPS position and velocity only: the filter runs on the dual-antenna heading alone (the
# heading aligns it), not on the baseline vector.
PAPER002_IMU = {
    "gyro_noise_deg_sqrt_h": 0.01,
    "gyro_turn_on_bias_deg_s": 0.01 / 3600.0,
    "gyro_bias_instability_deg_h": 0.01,
    "accel_noise_mps_sqrt_h": 0.0,
    "accel_turn_on_bias_mg": 0.0,
    "accel_bias_instability_mg": 0.01,
    "scale_factor_error_percent": 0.0,
}
PAPER002_GNSS = {
    "position_noise_horizontal_m": 20.0,
    "position_noise_vertical_m": 50.0,
    "velocity_noise_horizontal_mps": 0.2,
    "velocity_noise_vertical_mps": 0.2,
}
PAPER002_OVERRIDES = tuple(
    [f"sensors.imu.{k}={v!r}" for k, v in PAPER002_IMU.items()]
    + [f"sensors.gnss.{k}={v!r}" for k, v in PAPER002_GNSS.items()]
)
PAPER002_TABLE1 = None
"""Paper 002's Table 1 numbers: not in the available text."""
# Target: the smoother halves the forward filter's attitude RMS (default sensors).
ATTITUDE_RMS_RATIO_TARGET = 0.5
AXES = ("east", "north", "up")
ANGLES = ("roll", "pitch", "yaw")


@dataclasses.dataclass(frozen=True)
class SmoothingCase:
    key: str
    scenario: str
    overrides: tuple[str, ...]
    paper_settings: bool
    label: str


def plan(sections: set[str], quick: bool) -> list[SmoothingCase]:
    """The cases of the bench sections ``smoother`` and ``smoother_table1`` in ``sections``."""
    return [
        case
        for section in TABLE1_DURATION_S
        if section in sections
        for case in section_plan(section, quick)
    ]


def table1_results(sections: set[str], runs: dict) -> dict:
    """The results of the sections ``smoother`` and ``smoother_table1`` in ``sections`` from
    :func:`run_cases`'s ``runs``, each table printed."""
    results = {}
    for section in TABLE1_DURATION_S:
        if section in sections:
            section_runs = {k: v for k, v in runs.items() if k.startswith(f"{section}/")}
            results[section] = {
                "paper002_table1": PAPER002_TABLE1,
                "attitude_rms_ratio_target": ATTITUDE_RMS_RATIO_TARGET,
                "runs": section_runs,
            }
            print_table1(section_runs)
    return results


def section_plan(section: str, quick: bool) -> list[SmoothingCase]:
    """The cases of bench section ``section`` (``smoother`` or ``smoother_table1``)."""
    duration_s = TABLE1_DURATION_S[section]["quick" if quick else "full"]
    duration = f"duration_s={duration_s:g}"
    return [
        SmoothingCase(
            f"{section}/paper002",
            "sea_state",
            (duration, *PAPER002_OVERRIDES),
            True,
            f"sea_state, paper 002's sensors, {duration_s:g} s",
        ),
        SmoothingCase(
            f"{section}/sea_state",
            "sea_state",
            (duration,),
            False,
            f"sea_state, default sensors, {duration_s:g} s",
        ),
        SmoothingCase(
            f"{section}/open_ocean",
            "open_ocean",
            (duration,),
            False,
            f"open_ocean, default sensors, {duration_s:g} s",
        ),
    ]


def paper_fusion_config(config):
    return dataclasses.replace(config, use_gnss_baseline=False, **PAPER002_IMU)


def run_case(case: SmoothingCase, in_bag: str, out_bag: str) -> dict:
    """process_bag --smooth on one cached bag, then the analysis (in a worker process)."""
    config = fusion_config_from_files(PROCESSING_PARAMS)
    if case.paper_settings:
        config = paper_fusion_config(config)
    started = time.monotonic()
    summary = process_bag(
        in_bag,
        out_bag,
        config,
        compensator_config_from_files(PROCESSING_PARAMS),
        overwrite=True,
        smooth=True,
    )
    scenario = load_scenario(case.scenario, list(case.overrides), None)
    result = analyse_smoothing(out_bag, scenario)
    result["process_bag_smooth_wall_s"] = summary.wall_s
    result["analysis_wall_s"] = time.monotonic() - started - summary.wall_s
    result["overrides"] = list(case.overrides)
    result["label"] = case.label
    return result


def run_cases(
    cases: list[SmoothingCase], bag_of: dict[str, Path], runs_dir: Path, workers: int
) -> dict[str, dict]:
    """:func:`run_case` of each case on its bag, ``workers`` at a time."""
    runs_dir.mkdir(parents=True, exist_ok=True)
    results = {}
    with ProcessPoolExecutor(workers) as pool:
        futures = {
            pool.submit(
                run_case, case, str(bag_of[case.key]), str(runs_dir / case.key.replace("/", "_"))
            ): case
            for case in cases
        }
        for done, future in enumerate(as_completed(futures), 1):
            case = futures[future]
            results[case.key] = future.result()
            print(
                f"bench: [{done}/{len(cases)}] process_bag --smooth {case.label}: "
                f"{results[case.key]['process_bag_smooth_wall_s']:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    return results


def odometry_arrays(reader: BagReader, topic: str):
    stamps, quats, velocities, positions = [], [], [], []
    for message in reader.messages([topic]):
        m = reader.decode(message)
        stamps.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
        q, p, v = m.pose.pose.orientation, m.pose.pose.position, m.twist.twist.linear
        quats.append((q.x, q.y, q.z, q.w))
        positions.append((p.x, p.y, p.z))
        velocities.append((v.x, v.y, v.z))
    return np.array(stamps), np.array(quats), np.array(velocities), np.array(positions)


def fix_arrays(reader: BagReader):
    stamps, geodetic = [], []
    for message in reader.messages([NAV_FIX_TOPIC]):
        m = reader.decode(message)
        stamps.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
        geodetic.append((m.latitude, m.longitude, m.altitude))
    return np.array(stamps), np.array(geodetic)


def truth_geodetic(scenario, position_enu_m: np.ndarray) -> np.ndarray:
    """The simulator's geodetic trajectory from its curvilinear ENU displacement (see
    sensor_sim.truth): lat = lat0 + n/(R_M0 + h0), lon = lon0 + e/((R_N0 + h0) cos lat0)."""
    lat0 = np.radians(scenario.origin_latitude_deg)
    h0 = scenario.origin_altitude_m
    latitude = lat0 + position_enu_m[:, 1] / (meridian_radius_m(lat0) + h0)
    longitude = np.radians(scenario.origin_longitude_deg) + position_enu_m[:, 0] / (
        (prime_vertical_radius_m(lat0) + h0) * np.cos(lat0)
    )
    return np.column_stack((latitude, longitude, h0 + position_enu_m[:, 2]))


def describe(errors: np.ndarray, names) -> dict:
    return {
        name: {
            "mean": float(np.mean(errors[:, k])),
            "sigma": float(np.std(errors[:, k])),
            "rms": rms(errors[:, k]),
            "max_abs": float(np.max(np.abs(errors[:, k]))),
        }
        for k, name in enumerate(names)
    }


def analyse_smoothing(out_bag: str, scenario) -> dict:
    with BagReader(out_bag) as reader:
        smoothed = odometry_arrays(reader, NAV_ODOMETRY_TOPIC)
        forward = odometry_arrays(reader, NAV_FORWARD_ODOMETRY_TOPIC)
        truth = odometry_arrays(reader, TRUTH_ODOMETRY_TOPIC)
        fix_stamps, fix_geodetic = fix_arrays(reader)
    if not np.array_equal(smoothed[0], forward[0]) or not np.array_equal(smoothed[0], fix_stamps):
        raise RuntimeError(f"{out_bag}: nav/* and nav/forward/odometry stamps differ")
    from_ns = smoothed[0][0] + int(EVALUATE_AFTER_ALIGNMENT_S * 1e9)
    i_nav, i_truth = matching_indices(smoothed[0], truth[0])
    keep = smoothed[0][i_nav] >= from_ns
    i_nav, i_truth = i_nav[keep], i_truth[keep]
    true_rotation = Rotation.from_quat(truth[1][i_truth])
    true_velocity = true_rotation.apply(truth[2][i_truth])
    geodetic_true = truth_geodetic(scenario, truth[3][i_truth])
    lat = np.radians(fix_geodetic[i_nav, 0])
    height = fix_geodetic[i_nav, 2]
    smoothed_position_error = np.column_stack(
        (
            (np.radians(fix_geodetic[i_nav, 1]) - geodetic_true[:, 1])
            * (prime_vertical_radius_m(lat) + height)
            * np.cos(lat),
            (lat - geodetic_true[:, 0]) * (meridian_radius_m(lat) + height),
            height - geodetic_true[:, 2],
        )
    )
    result = {
        "evaluated_samples": int(i_nav.size),
        "evaluated_from_alignment_s": EVALUATE_AFTER_ALIGNMENT_S,
    }
    for name, (_, quats, velocities, positions) in (
        ("forward", forward),
        ("smoothed", smoothed),
    ):
        rotation = Rotation.from_quat(quats[i_nav])
        # as_euler("ZYX") gives (yaw, pitch, roll).
        euler = wrap_deg(np.degrees(rotation.as_euler("ZYX") - true_rotation.as_euler("ZYX")))
        position_error = smoothed_position_error + positions[i_nav] - smoothed[3][i_nav]
        result[name] = {
            "attitude_deg": describe(euler[:, ::-1], ANGLES),
            "velocity_mps": describe(rotation.apply(velocities[i_nav]) - true_velocity, AXES),
            "position_m": describe(position_error, AXES),
        }
    forward_rms = np.array([result["forward"]["attitude_deg"][a]["rms"] for a in ANGLES])
    smoothed_rms = np.array([result["smoothed"]["attitude_deg"][a]["rms"] for a in ANGLES])
    result["attitude_rms_ratio"] = dict(
        zip(ANGLES, (smoothed_rms / forward_rms).tolist(), strict=True)
    )
    result["attitude_rms_ratio_total"] = float(
        np.linalg.norm(smoothed_rms) / np.linalg.norm(forward_rms)
    )
    result["wind"] = wind_errors(out_bag)
    return result


def corrected_wind(out_bag: str, odometry_topic: str) -> tuple[np.ndarray, np.ndarray]:
    """The anemometer corrected with ``odometry_topic`` (and ``nav/fix``) through the
    compensation pipeline, as compensation_node receives them: (stamps ns, ENU wind)."""
    pipeline = wind_pipeline(compensator_config_from_files(PROCESSING_PARAMS))
    with BagReader(out_bag) as reader:
        stamps = []
        for message in reader.messages([odometry_topic, NAV_FIX_TOPIC, WIND_RAW_TOPIC]):
            topic = message.topic.lstrip("/")
            decoded = reader.decode(message)
            if topic == odometry_topic:
                pipeline.add_odometry(*odometry_fields(decoded))
            elif topic == NAV_FIX_TOPIC:
                pipeline.add_fix(*fix_fields(decoded))
            else:
                pipeline.add_sample(anemometer_sample(decoded))
                stamps.append(
                    decoded.header.stamp.sec * 1_000_000_000 + decoded.header.stamp.nanosec
                )
    return np.array(stamps), pipeline.flush().samples.flow_enu_mps


def wind_errors(out_bag: str) -> dict:
    """Per-sample RMS of corrected − true wind (norm, m/s) at the anemometer stamps that have
    a truth sample, for the smoothed ``wind/true`` and the forward recorrection."""
    with BagReader(out_bag) as reader:
        published = stamped_vectors(reader, WIND_TRUE_TOPIC)
        truth = stamped_vectors(reader, TRUTH_WIND_TOPIC)
    forward_stamps, forward_wind = corrected_wind(out_bag, NAV_FORWARD_ODOMETRY_TOPIC)
    if not np.array_equal(forward_stamps, published.stamps_ns):
        raise RuntimeError(f"{out_bag}: recorrected stamps differ from wind/true")
    _, at_wind, at_truth = np.intersect1d(published.stamps_ns, truth.stamps_ns, return_indices=True)
    both_valid = ~(
        np.isnan(published.vectors[at_wind]).any(axis=1)
        | np.isnan(forward_wind[at_wind]).any(axis=1)
    )
    truth_wind = truth.vectors[at_truth][both_valid]

    def error_rms(wind):
        error = wind[at_wind][both_valid] - truth_wind
        return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))

    return {
        "samples": int(np.count_nonzero(both_valid)),
        "forward_rms_mps": error_rms(forward_wind),
        "smoothed_rms_mps": error_rms(published.vectors),
    }


def print_table1(results: dict) -> None:
    print("\nTable S1 — paper 002 Table 1: errors of the forward filter and of the smoother")
    print("  (mean ± σ after 60 s; paper 002's own figures: not in the available text, n/a)")
    for key, result in results.items():
        print(f"\n  {result['label']} ({result['evaluated_samples']} samples)")
        print(f"  {'quantity':22s} {'forward mean ± σ':>22s} {'smoothed mean ± σ':>22s}  paper")
        for group, unit, names in (
            ("position_m", "m", AXES),
            ("velocity_mps", "m/s", AXES),
            ("attitude_deg", "deg", ANGLES),
        ):
            for name in names:
                f = result["forward"][group][name]
                s = result["smoothed"][group][name]
                print(
                    f"  {group.split('_')[0] + ' ' + name + ' (' + unit + ')':22s} "
                    f"{f['mean']:+10.4f} ± {f['sigma']:8.4f} {s['mean']:+10.4f} ± {s['sigma']:8.4f}"
                    "    n/a"
                )
        ratio = result["attitude_rms_ratio"]
        verdict = (
            ""
            if "paper002" in key
            else (
                "  target ≤ 0.5: "
                + ("met" if max(ratio.values()) <= ATTITUDE_RMS_RATIO_TARGET else "NOT met")
            )
        )
        print(
            "  attitude RMS smoothed/forward: "
            + ", ".join(f"{a} {ratio[a]:.2f}" for a in ANGLES)
            + f" (total {result['attitude_rms_ratio_total']:.2f}){verdict}"
        )
        wind = result["wind"]
        print(
            f"  wind per-sample RMS error: forward {wind['forward_rms_mps']:.4f} m/s, smoothed "
            f"{wind['smoothed_rms_mps']:.4f} m/s over {wind['samples']} samples "
            f"({'no worse' if wind['smoothed_rms_mps'] <= wind['forward_rms_mps'] else 'WORSE'})"
        )


# ---------------------------------------------------------------------------------------------
# Memory and time of --smooth.


def measured_child(arguments: list[str]) -> dict:
    """Run a command; its wall time and peak resident memory (from the kernel's accounting of
    that child alone)."""
    started = time.monotonic()
    process = subprocess.Popen(arguments, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(process.pid, 0)
    wall_s = time.monotonic() - started
    return {
        "command": " ".join(Path(a).name if a.startswith("/") else a for a in arguments),
        "exit_status": os.waitstatus_to_exitcode(status),
        "wall_s": wall_s,
        "peak_rss_mib": usage.ru_maxrss / 1024.0,
        "cpu_s": usage.ru_utime + usage.ru_stime,
    }


def run_smoother_speed(bags: dict[str, Path], out_dir: Path) -> dict:
    """fuse_bag --smooth and process_bag --smooth (and, for scale, without --smooth) on each
    bag, one at a time."""
    out_dir.mkdir(parents=True, exist_ok=True)
    bin_dir = Path(sys.executable).parent
    params = [a for p in PROCESSING_PARAMS for a in ("--params-file", p)]
    results = {}
    for label, bag in bags.items():
        with BagReader(bag) as reader:
            duration_s = reader.duration_s
        runs = {}
        for tool in ("fuse_bag", "process_bag"):
            for smooth in (False, True):
                os.sync()
                name = f"{tool}{' --smooth' if smooth else ''}"
                print(f"bench: smoother speed: {name} on {label}", file=sys.stderr, flush=True)
                runs[name] = measured_child(
                    [
                        str(bin_dir / tool),
                        str(bag),
                        str(out_dir / f"{label}_{tool}{'_smooth' if smooth else ''}"),
                        "--overwrite",
                        *params,
                        *(["--smooth"] if smooth else []),
                    ]
                )
                runs[name]["real_time_multiple"] = duration_s / runs[name]["wall_s"]
        results[label] = {"data_s": duration_s, "runs": runs}
    results["load_average_1min"] = os.getloadavg()[0]
    results["own_peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return results


def print_smoother_speed(results: dict) -> None:
    print("\nTable S2 — --smooth: wall time and peak memory (one process at a time)")
    print(f"  {'bag':6s} {'command':22s} {'wall s':>8s} {'x real time':>12s} {'peak MiB':>9s}")
    for label, result in results.items():
        if not isinstance(result, dict):
            continue
        for name, run in result["runs"].items():
            print(
                f"  {label:6s} {name:22s} {run['wall_s']:8.0f} {run['real_time_multiple']:12.1f} "
                f"{run['peak_rss_mib']:9.0f}{'' if run['exit_status'] == 0 else '  FAILED'}"
            )
    print(f"  load average during the runs: {results['load_average_1min']:.1f}")
