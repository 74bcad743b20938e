"""`make bench`: accuracy and speed of the suite on simulated data, beside the source paper.

Source paper (000): Zhang, Zhou, Shao, "Design of wind speed measurement motion compensation
scheme based on dual-antenna GNSS/SINS integrated system". Its Tables 1-3 are reproduced here
as constants and printed beside our figures:

1. attitude (paper Table 1): fuse_bag on static, tilt_table, sea_state, open_ocean; and
   (Table 1b) sea_state and open_ocean again with other seeds;
2. wind tunnel (paper Table 2): process_bag on wind_tunnel at 5, 10, 15 m/s, still reference
   and sway-and-rotation run;
3. vertical wind (paper Table 3): process_bag on vertical_wind at 5 and 15 m/s;
4. sea: process_bag on sea_state and open_ocean, with the share of each Miller term;
5. speed: fuse_bag and process_bag on one hour of open_ocean;
6. live latency and CPU of fusion_node (tools/bench_live.py), and (6b) the same run with
   pass-through stand-ins for both nodes (tools/passthrough_node.py): the floor it is read
   against;
7. consistency: Monte-Carlo normalised errors of the accelerometer bias over many seeds
   (tools/bias_consistency.py).

Simulated bags are cached in out/bench/cache/ under a key of scenario, overrides, seed and a
hash of the simulator's sources and parameter files, so a second run only processes. Figures
go to stdout and out/bench/results.json, progress to stderr.

    python tools/bench.py [--quick] [--only attitude|wind|speed|live|consistency ...]
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import math
import os
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_nav.fuse_bag import fuse_bag, fusion_config_from_files
from sensor_sim.scenario import load_scenario
from sensor_sim.simulate_bag import simulate
from wind_comp.compensator import WindStatus, correct_batch
from wind_comp.miller import mounting_rotation_from_rpy_deg
from wind_comp.nav_interpolation import NavTrack
from wind_comp.nav_messages import anemometer_sample, odometry_arrays, remove_earth_rate
from wind_comp.process_bag import compensator_config_from_files, process_bag
from wind_comp.products import meteorological_direction_deg

REPO = Path(__file__).resolve().parents[1]
OUT_DIR = REPO / "out" / "bench"
CACHE_DIR = OUT_DIR / "cache"
RUNS_DIR = OUT_DIR / "runs"
BUOY_PARAMS = REPO / "src/buoy_common/config/buoy.yaml"
# The shipped defaults, given explicitly so that the bench runs what a user of the files runs.
PROCESSING_PARAMS = [
    str(BUOY_PARAMS),
    str(REPO / "src/buoy_nav/config/fusion.yaml"),
    str(REPO / "src/wind_comp/config/compensation.yaml"),
]
SIMULATION_PARAMS = [str(BUOY_PARAMS)]
SIMULATOR_PACKAGE = REPO / "src/sensor_sim/sensor_sim"
# Modules outside sensor_sim whose code decides what simulate_bag writes.
SIMULATION_SHARED_MODULES = ("buoy_common.parameters", "buoy_common.bag_io")
SECTIONS = ("attitude", "wind", "speed", "live", "consistency")
WORKERS = max(1, min(2, os.cpu_count() or 1))

# ---------------------------------------------------------------------------------------------
# The paper's figures.

# Paper 000, Table 1 (姿态对比实验结果): (max negative, max positive) attitude error, deg, of the
# MTi-3 AHRS and of the paper's dual-antenna GNSS/SINS system. Static: 2000 s at rest; dynamic:
# tilt table swaying +-15 deg at 5 deg/s, 10 swings. The paper lists pitch first.
PAPER_TABLE1_DEG = {
    "static": {
        "pitch": {"mti3_min_max_deg": (-0.83, 0.76), "combined_min_max_deg": (-0.23, 0.20)},
        "roll": {"mti3_min_max_deg": (-0.72, 0.91), "combined_min_max_deg": (-0.28, 0.27)},
        "heading": {"mti3_min_max_deg": (-0.80, 1.72), "combined_min_max_deg": (-0.07, 0.21)},
    },
    "dynamic": {
        "pitch": {"mti3_min_max_deg": (-0.22, 0.21), "combined_min_max_deg": (-0.20, 0.21)},
        "roll": {"mti3_min_max_deg": (-0.42, 0.50), "combined_min_max_deg": (-0.21, 0.30)},
        "heading": {"mti3_min_max_deg": (-0.07, 8.30), "combined_min_max_deg": (-0.10, 0.09)},
    },
}
# Which paper row each of our attitude scenarios reproduces (None: beyond the paper).
PAPER_TABLE1_ROW = {"static": "static", "tilt_table": "dynamic"}

# Paper 000, Table 2 (运动补偿与静止0°结果比较): mean speed (m/s) and direction (deg) in the wind
# tunnel, still at 0 deg vs motion-compensated during sway and rotation; text: speed errors
# < 0.2 m/s, direction deviations 0.04, 0.56, 0.75 deg, all < 1 deg.
PAPER_TABLE2 = {
    5: {
        "still": {"speed_mps": 5.0652, "direction_deg": 0.3307},
        "corrected": {"speed_mps": 5.1262, "direction_deg": 0.3771},
    },
    10: {
        "still": {"speed_mps": 10.2432, "direction_deg": 1.0705},
        "corrected": {"speed_mps": 10.2607, "direction_deg": 0.5114},
    },
    15: {
        "still": {"speed_mps": 15.3172, "direction_deg": 1.2810},
        "corrected": {"speed_mps": 15.3856, "direction_deg": 0.5152},
    },
}
PAPER_TABLE2_BOUNDS = {"speed_error_mps": 0.2, "direction_error_deg": 1.0}

# Paper 000, Table 3 (补偿前后垂向风速比较): vertical wind (m/s) before and after compensation,
# (min, max). The 15 m/s "after" range is printed as "0.490~0.406"; a minimum above the maximum
# is impossible, so the minus sign was lost: read as -0.490. Text: 10-min means after
# compensation -0.051 and -0.092 m/s; the error falls to 11 % of the uncorrected one.
PAPER_TABLE3 = {
    5: {
        "before_min_max_mps": (-1.207, 1.315),
        "after_min_max_mps": (-0.197, 0.090),
        "mean_after_mps": -0.051,
    },
    15: {
        "before_min_max_mps": (-3.507, 4.033),
        "after_min_max_mps": (-0.490, 0.406),
        "mean_after_mps": -0.092,
    },
}
PAPER_RESIDUAL_SHARE = 0.11

# ---------------------------------------------------------------------------------------------
# Targets of this project.

ATTITUDE_MAX_ERROR_DEG = {"roll": 0.10, "pitch": 0.10, "heading": 0.15}
ATTITUDE_RMS_DEG = {"roll": 0.05, "pitch": 0.05, "heading": 0.08}
# Convergence: 1-sigma of the filter's own ENU attitude-error covariance (pose covariance
# indices 21, 28, 35: rotation-vector error about East, North, Up) below these for good.
CONVERGED_SIGMA_DEG = {"east": 0.05, "north": 0.05, "up": 0.08}
POSE_COVARIANCE_ATTITUDE_INDICES = {"east": 21, "north": 28, "up": 35}
NOT_CONVERGED_FALLBACK_S = 60.0
VERTICAL_RESIDUAL_SHARE_TARGET = 0.05
VERTICAL_SPEED_ERROR_TARGET = 0.01
SEA_MEAN_SPEED_ERROR_MPS = 0.05
SEA_MEAN_DIRECTION_ERROR_DEG = 0.3
SEA_MEAN_WINDOW_S = 600.0
# A window with less data than this (e.g. the single sample stamped at the end of a run) is
# not reported as a mean.
MIN_MEAN_WINDOW_COVERAGE_S = 60.0
SPEED_TARGET_REAL_TIME = 100.0
# Runs of each tool in the speed table.
SPEED_RUNS = 2
STAMP_MATCH_NS = 1000

# ---------------------------------------------------------------------------------------------
# Runs: scenarios, overrides and durations.

TUNNEL_SPEEDS_MPS = (5, 10, 15)
VERTICAL_SPEEDS_MPS = (5, 15)
STILL_LEVEL = ("motion.rotation_range_deg=0", "motion.sway_amplitude_deg=0")
ATTITUDE_SCENARIOS = ("static", "tilt_table", "sea_state", "open_ocean")
# The sea runs again with other seeds: other sensor errors (turn-on biases above all), noise and
# wave phases. A target met on one seed only is not met.
SEED_SPREAD_SCENARIOS = ("sea_state", "open_ocean")
SEED_SPREAD = (1, 2, 3)
SEA_SCENARIOS = ("sea_state", "open_ocean")
# --quick: scenario durations, s (None: as shipped). Long enough for alignment and motion.
QUICK_DURATION_S = {
    "static": 300.0,
    "tilt_table": None,
    "sea_state": 240.0,
    "open_ocean": 240.0,
    "wind_tunnel": 150.0,
    "vertical_wind": 150.0,
}
SPEED_DURATION_S = {"full": 3600.0, "quick": 600.0}
LIVE_DURATION_S = {"full": 40.0, "quick": 20.0}
CONSISTENCY_SEEDS = {"full": range(2, 202), "quick": range(2, 12)}
CONSISTENCY_DURATION_S = 75.0
CONSISTENCY_CHECKPOINTS_S = (30.0, 50.0, 70.0)


@dataclass(frozen=True)
class Case:
    """One simulated run and how it is processed and analysed."""

    key: str
    scenario: str
    overrides: tuple[str, ...]
    pipeline: str  # "fuse" (fuse_bag) or "process" (process_bag)
    analysis: str  # "attitude", "tunnel", "vertical", "sea"
    label: str


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def duration_overrides(scenario: str, quick: bool) -> tuple[str, ...]:
    duration_s = QUICK_DURATION_S[scenario] if quick else None
    return () if duration_s is None else (f"duration_s={duration_s:g}",)


def plan_cases(sections: set[str], quick: bool) -> list[Case]:
    cases = []
    if "attitude" in sections:
        for scenario in ATTITUDE_SCENARIOS:
            cases.append(
                Case(
                    f"attitude/{scenario}",
                    scenario,
                    duration_overrides(scenario, quick),
                    "fuse",
                    "attitude",
                    scenario,
                )
            )
        for scenario in SEED_SPREAD_SCENARIOS:
            for seed in SEED_SPREAD:
                cases.append(
                    Case(
                        f"attitude_seed/{scenario}/{seed}",
                        scenario,
                        (*duration_overrides(scenario, quick), f"seed={seed}"),
                        "fuse",
                        "attitude",
                        f"{scenario} seed {seed}",
                    )
                )
    if "wind" in sections:
        for speed in TUNNEL_SPEEDS_MPS:
            base = (*duration_overrides("wind_tunnel", quick), f"wind.speed_mps={speed}")
            cases.append(
                Case(
                    f"tunnel/{speed}/reference",
                    "wind_tunnel",
                    (*base, *STILL_LEVEL),
                    "process",
                    "tunnel",
                    f"wind tunnel {speed} m/s, still level",
                )
            )
            cases.append(
                Case(
                    f"tunnel/{speed}/motion",
                    "wind_tunnel",
                    base,
                    "process",
                    "tunnel",
                    f"wind tunnel {speed} m/s, sway and rotation",
                )
            )
        for speed in VERTICAL_SPEEDS_MPS:
            cases.append(
                Case(
                    f"vertical/{speed}",
                    "vertical_wind",
                    (*duration_overrides("vertical_wind", quick), f"wind.speed_mps={speed}"),
                    "process",
                    "vertical",
                    f"vertical wind {speed} m/s",
                )
            )
        for scenario in SEA_SCENARIOS:
            cases.append(
                Case(
                    f"sea/{scenario}",
                    scenario,
                    duration_overrides(scenario, quick),
                    "process",
                    "sea",
                    scenario,
                )
            )
    return cases


def speed_overrides(quick: bool) -> tuple[str, ...]:
    return (f"duration_s={SPEED_DURATION_S['quick' if quick else 'full']:g}",)


# ---------------------------------------------------------------------------------------------
# Simulated bags, cached.


def simulator_fingerprint() -> str:
    """Hash of everything that shapes a simulated bag besides scenario, overrides and seed:
    the simulator modules simulate_bag runs on (not the live nodes, whose edits do not change
    a simulated bag), the shipped scenario files and the parameter files."""
    sources = {
        Path(module.__file__)
        for name, module in list(sys.modules.items())
        if (
            name.split(".")[0] == "sensor_sim"
            or any(name == m or name.startswith(m + ".") for m in SIMULATION_SHARED_MODULES)
        )
        and getattr(module, "__file__", None)
    }
    sources |= set((SIMULATOR_PACKAGE / "scenarios").glob("*.yaml"))
    sources |= {Path(p) for p in SIMULATION_PARAMS}
    digest = hashlib.sha256()
    for path in sorted(sources):
        digest.update(str(path.relative_to(REPO)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cached_bag_path(scenario: str, overrides: tuple[str, ...], fingerprint: str) -> Path:
    seed = load_scenario(scenario, list(overrides), None).seed
    key = json.dumps([scenario, sorted(overrides), seed, fingerprint])
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    readable = "_".join(o.split(".")[-1].replace("=", "") for o in sorted(overrides))
    return CACHE_DIR / f"{scenario}{'_' + readable if readable else ''}_seed{seed}_{digest}"


def simulate_to_cache(scenario: str, overrides: tuple[str, ...], bag: str) -> float:
    """Simulate into a temporary name and rename, so an aborted run leaves no usable bag."""
    partial = Path(f"{bag}.partial")
    shutil.rmtree(partial, ignore_errors=True)
    started = time.monotonic()
    with contextlib.redirect_stderr(io.StringIO()):
        simulate(
            argparse.Namespace(
                scenario=scenario,
                output=str(partial),
                overrides=list(overrides),
                seed=None,
                params_file=SIMULATION_PARAMS,
                no_truth=False,
                overwrite=False,
            )
        )
    partial.rename(bag)
    return time.monotonic() - started


def ensure_bags(wanted: dict[Path, tuple[str, tuple[str, ...]]]) -> dict[str, float]:
    """Simulate the bags not in the cache, in parallel; returns wall s per simulated bag."""
    missing = {path: spec for path, spec in wanted.items() if not (path / "metadata.yaml").exists()}
    log(f"bench: {len(wanted) - len(missing)} cached bag(s), {len(missing)} to simulate")
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    walls = {}
    if not missing:
        return walls
    with ProcessPoolExecutor(WORKERS) as pool:
        futures = {
            pool.submit(simulate_to_cache, scenario, overrides, str(path)): path
            for path, (scenario, overrides) in missing.items()
        }
        for done, future in enumerate(as_completed(futures), 1):
            path = futures[future]
            walls[path.name] = future.result()
            log(f"bench: [{done}/{len(missing)}] simulated {path.name} in {walls[path.name]:.1f} s")
    return walls


# ---------------------------------------------------------------------------------------------
# Reading bags into arrays.


def decoded(reader: BagReader, topic: str):
    for record in reader.messages([topic]):
        yield reader.decode(record)


def stamp_ns(message) -> int:
    return message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec


def odometry_columns(reader: BagReader, topic: str) -> dict[str, np.ndarray]:
    """Stamps (ns), body→ENU quaternions, body-frame velocity (m/s), attitude variances (rad²)."""
    stamps, quats, velocities, variances = [], [], [], []
    for message in decoded(reader, topic):
        stamps.append(stamp_ns(message))
        q = message.pose.pose.orientation
        quats.append((q.x, q.y, q.z, q.w))
        v = message.twist.twist.linear
        velocities.append((v.x, v.y, v.z))
        covariance = message.pose.covariance
        variances.append([covariance[i] for i in POSE_COVARIANCE_ATTITUDE_INDICES.values()])
    return {
        "stamp_ns": np.array(stamps, dtype=np.int64),
        "quat_xyzw": np.array(quats, dtype=float),
        "velocity_body_mps": np.array(velocities, dtype=float),
        "attitude_variance_enu_rad2": np.array(variances, dtype=float),
    }


def vector_columns(reader: BagReader, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (ns) and (N, 3) vectors of a Vector3Stamped topic."""
    stamps, vectors = [], []
    for message in decoded(reader, topic):
        stamps.append(stamp_ns(message))
        vectors.append((message.vector.x, message.vector.y, message.vector.z))
    return np.array(stamps, dtype=np.int64), np.array(vectors, dtype=float).reshape(-1, 3)


def matching_indices(stamps_a_ns: np.ndarray, stamps_b_ns: np.ndarray):
    """Indices (ia, ib) of stamps present in both sorted arrays, within STAMP_MATCH_NS."""
    position = np.clip(np.searchsorted(stamps_b_ns, stamps_a_ns), 1, len(stamps_b_ns) - 1)
    left, right = stamps_b_ns[position - 1], stamps_b_ns[position]
    nearest = np.where(stamps_a_ns - left <= right - stamps_a_ns, position - 1, position)
    close = np.abs(stamps_b_ns[nearest] - stamps_a_ns) <= STAMP_MATCH_NS
    return np.flatnonzero(close), nearest[close]


def interpolate_vectors(query_ns, stamps_ns, vectors, origin_ns) -> np.ndarray:
    """Linear interpolation of (N, 3) vectors to ``query_ns``; NaN outside their span."""
    query_s = (query_ns - origin_ns) * 1e-9
    stamps_s = (stamps_ns - origin_ns) * 1e-9
    return np.stack(
        [np.interp(query_s, stamps_s, vectors[:, k], left=np.nan, right=np.nan) for k in range(3)],
        axis=1,
    )


def wrap_deg(angles_deg):
    return (np.asarray(angles_deg) + 180.0) % 360.0 - 180.0


def rms(values) -> float:
    values = np.asarray(values, dtype=float)
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def vector_rms(errors: np.ndarray) -> float:
    """RMS of the length of (N, 3) error vectors."""
    return float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))) if len(errors) else math.nan


# ---------------------------------------------------------------------------------------------
# Table 1: attitude.


def convergence(nav_stamps_ns: np.ndarray, variances_rad2: np.ndarray) -> dict:
    """First stamp after which every 1-sigma stays below its CONVERGED_SIGMA_DEG for good."""
    sigma_deg = np.degrees(np.sqrt(np.maximum(variances_rad2, 0.0)))
    per_axis_ns = {}
    for k, (axis, threshold) in enumerate(CONVERGED_SIGMA_DEG.items()):
        above = np.flatnonzero(~(sigma_deg[:, k] < threshold))
        if len(above) == 0:
            per_axis_ns[axis] = int(nav_stamps_ns[0])
        elif above[-1] == len(nav_stamps_ns) - 1:
            per_axis_ns[axis] = None
        else:
            per_axis_ns[axis] = int(nav_stamps_ns[above[-1] + 1])
    converged = all(v is not None for v in per_axis_ns.values())
    return {
        "converged": converged,
        "per_axis_ns": per_axis_ns,
        "at_ns": max(per_axis_ns.values()) if converged else None,
        "final_sigma_enu_deg": sigma_deg[-1].tolist(),
    }


def analyse_attitude(out_bag: str, scenario_duration_s: float) -> dict:
    with BagReader(out_bag) as reader:
        nav = odometry_columns(reader, "nav/odometry")
        truth = odometry_columns(reader, "truth/odometry")
    start_ns = int(truth["stamp_ns"][0])
    aligned_ns = int(nav["stamp_ns"][0])
    conv = convergence(nav["stamp_ns"], nav["attitude_variance_enu_rad2"])
    evaluate_from_ns = conv["at_ns"] if conv["converged"] else aligned_ns + int(60e9)
    # Truth (50 Hz) is stamped on every other IMU stamp: compare there, exactly, no interpolation.
    i_nav, i_truth = matching_indices(nav["stamp_ns"], truth["stamp_ns"])
    keep = nav["stamp_ns"][i_nav] >= evaluate_from_ns
    i_nav, i_truth = i_nav[keep], i_truth[keep]
    estimated = Rotation.from_quat(nav["quat_xyzw"][i_nav])
    true = Rotation.from_quat(truth["quat_xyzw"][i_truth])
    # as_euler("ZYX") gives (yaw, pitch, roll) of R = Rz(yaw)·Ry(pitch)·Rx(roll).
    error_deg = wrap_deg(np.degrees(estimated.as_euler("ZYX") - true.as_euler("ZYX")))
    angles = {"heading": error_deg[:, 0], "pitch": error_deg[:, 1], "roll": error_deg[:, 2]}
    velocity_error = estimated.apply(nav["velocity_body_mps"][i_nav]) - true.apply(
        truth["velocity_body_mps"][i_truth]
    )
    result = {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (aligned_ns - start_ns) * 1e-9,
        "converged": conv["converged"],
        "convergence_s": None if conv["at_ns"] is None else (conv["at_ns"] - start_ns) * 1e-9,
        "convergence_per_axis_s": {
            axis: None if ns is None else (ns - start_ns) * 1e-9
            for axis, ns in conv["per_axis_ns"].items()
        },
        "final_sigma_enu_deg": dict(
            zip(CONVERGED_SIGMA_DEG, conv["final_sigma_enu_deg"], strict=True)
        ),
        "evaluated_from_s": (evaluate_from_ns - start_ns) * 1e-9,
        "evaluated_samples": len(i_nav),
        "errors_deg": {},
        "velocity_rms_enu_mps": {
            axis: rms(velocity_error[:, k]) for k, axis in enumerate(("east", "north", "up"))
        },
    }
    for name in ("roll", "pitch", "heading"):
        values = angles[name]
        lowest, highest = float(values.min()), float(values.max())
        result["errors_deg"][name] = {
            "max_negative_deg": lowest,
            "max_positive_deg": highest,
            "rms_deg": rms(values),
            "max_negative_pass": bool(abs(lowest) <= ATTITUDE_MAX_ERROR_DEG[name]),
            "max_positive_pass": bool(abs(highest) <= ATTITUDE_MAX_ERROR_DEG[name]),
            "rms_pass": bool(rms(values) <= ATTITUDE_RMS_DEG[name]),
        }
    return result


# ---------------------------------------------------------------------------------------------
# Wind tables: common reading.


@dataclass
class WindRun:
    """The arrays of one processed wind bag."""

    start_ns: int
    aligned_ns: int
    wind_stamp_ns: np.ndarray
    wind_t_s: np.ndarray  # header stamps as the compensator sees them, s since the epoch
    measured_sensor_mps: np.ndarray
    corrected_enu_mps: np.ndarray
    truth_enu_mps: np.ndarray  # truth/wind interpolated to the anemometer stamps
    nav: object  # wind_comp.nav_messages.NavArrays
    nav_latitude_deg: np.ndarray


def read_wind_run(out_bag: str) -> WindRun:
    with BagReader(out_bag) as reader:
        samples = [anemometer_sample(m) for m in decoded(reader, "anemometer/wind")]
        wind_stamp_ns = np.array(
            [stamp_ns(m) for m in decoded(reader, "anemometer/wind")], dtype=np.int64
        )
        true_stamp_ns, corrected = vector_columns(reader, "wind/true")
        truth_stamp_ns, truth = vector_columns(reader, "truth/wind")
        nav, rejected = odometry_arrays(decoded(reader, "nav/odometry"))
        latitude = np.array([m.latitude for m in decoded(reader, "nav/fix")], dtype=float)
    if rejected:
        raise RuntimeError(f"{out_bag}: nav/odometry messages rejected: {rejected}")
    if not np.array_equal(true_stamp_ns, wind_stamp_ns):
        raise RuntimeError(f"{out_bag}: wind/true stamps differ from anemometer/wind stamps")
    start_ns = int(min(truth_stamp_ns[0], wind_stamp_ns[0]))
    return WindRun(
        start_ns=start_ns,
        aligned_ns=round(float(nav.t_s[0]) * 1e9),
        wind_stamp_ns=wind_stamp_ns,
        wind_t_s=np.array([s.t_s for s in samples]),
        measured_sensor_mps=np.array([s.wind_sensor_mps for s in samples]),
        corrected_enu_mps=corrected,
        truth_enu_mps=interpolate_vectors(wind_stamp_ns, truth_stamp_ns, truth, start_ns),
        nav=nav,
        nav_latitude_deg=latitude,
    )


def nav_attitude_at(run: WindRun, config) -> tuple[Rotation, np.ndarray]:
    """Navigation attitude at the anemometer stamps (as the compensator interpolates it)."""
    track = NavTrack.from_arrays(
        run.nav.t_s,
        run.nav.quat_xyzw,
        run.nav.angular_rate_body_rad_s,
        run.nav.velocity_enu_mps,
        max_gap_s=config.max_nav_gap_s,
    )
    interpolated = track.interpolate(run.wind_t_s)
    return interpolated.attitude_nb, interpolated.valid


def heading_only_wind(measured_sensor_mps, heading_rad, config) -> np.ndarray:
    """The measured air velocity as if the platform were level and still: rotated by the
    mounting and by a heading only (no tilt, no lever-arm rotation, no platform velocity)."""
    mounted_body = mounting_rotation_from_rpy_deg(config.anemometer_rpy_deg).apply(
        measured_sensor_mps
    )
    return Rotation.from_euler("z", np.asarray(heading_rad)[:, None]).apply(mounted_body)


def mean_wind(vectors_enu: np.ndarray) -> dict:
    """Scalar mean horizontal speed, and speed and meteorological direction of the vector
    mean. The paper's table gives one mean speed; both are kept because a wind that turns
    (as an uncorrected reading on a turning platform does) has a short vector mean."""
    mean_u, mean_v = vectors_enu[:, 0].mean(), vectors_enu[:, 1].mean()
    return {
        "mean_speed_mps": float(np.mean(np.hypot(vectors_enu[:, 0], vectors_enu[:, 1]))),
        "vector_mean_speed_mps": float(np.hypot(mean_u, mean_v)),
        "direction_deg": float(meteorological_direction_deg(mean_u, mean_v)),
        "samples": len(vectors_enu),
    }


# ---------------------------------------------------------------------------------------------
# Table 2: wind tunnel.


def analyse_tunnel(out_bag: str, scenario_duration_s: float) -> dict:
    config = compensator_config_from_files(PROCESSING_PARAMS)
    run = read_wind_run(out_bag)
    after = run.wind_stamp_ns >= run.aligned_ns
    valid = after & np.all(np.isfinite(run.corrected_enu_mps), axis=1)
    attitude, nav_valid = nav_attitude_at(run, config)
    heading_rad = attitude.as_euler("ZYX")[:, 0]
    # Uncorrected, as a level and still anemometer would read: only the mounting rotation and
    # ONE heading, the circular mean of the navigation heading over the run. A plain
    # anemometer has no attitude sensor; a fixed installation heading is what it can use, so
    # this shows all the correction buys, tilt, lever arm, velocity and turning together.
    yaw = Rotation.from_quat(run.nav.quat_xyzw).as_euler("ZYX")[:, 0]
    nav_after = run.nav.t_s * 1e9 >= run.aligned_ns
    mean_heading_rad = float(
        np.arctan2(np.mean(np.sin(yaw[nav_after])), np.mean(np.cos(yaw[nav_after])))
    )
    mean_heading_wind = heading_only_wind(
        run.measured_sensor_mps[after], np.full(after.sum(), mean_heading_rad), config
    )
    # Also with the heading of each sample (a compass), to separate the turning from the rest.
    compass = after & nav_valid
    compass_wind = heading_only_wind(run.measured_sensor_mps[compass], heading_rad[compass], config)
    return {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (run.aligned_ns - run.start_ns) * 1e-9,
        "samples_after_alignment": int(after.sum()),
        "nan_samples_after_alignment": int((after & ~valid).sum()),
        "nan_samples_total": int((~np.all(np.isfinite(run.corrected_enu_mps), axis=1)).sum()),
        "corrected": mean_wind(run.corrected_enu_mps[valid]),
        "truth": mean_wind(run.truth_enu_mps[valid]),
        "uncorrected_mean_heading": {
            **mean_wind(mean_heading_wind),
            "mean_heading_enu_deg": math.degrees(mean_heading_rad),
        },
        "uncorrected_compass_heading": mean_wind(compass_wind),
    }


# ---------------------------------------------------------------------------------------------
# Table 3: vertical wind.


def analyse_vertical(out_bag: str, scenario_duration_s: float) -> dict:
    run = read_wind_run(out_bag)
    after = run.wind_stamp_ns >= run.aligned_ns
    valid = after & np.all(np.isfinite(run.corrected_enu_mps), axis=1)
    before_w = run.measured_sensor_mps[valid, 2]
    after_w = run.corrected_enu_mps[valid, 2]
    truth_w = run.truth_enu_mps[valid, 2]
    residual_rms = rms(after_w - truth_w)
    uncorrected_rms = rms(before_w - truth_w)
    corrected_speed = np.hypot(run.corrected_enu_mps[valid, 0], run.corrected_enu_mps[valid, 1])
    truth_speed = np.hypot(run.truth_enu_mps[valid, 0], run.truth_enu_mps[valid, 1])
    speed_error = float(corrected_speed.mean() / truth_speed.mean() - 1.0)
    share = residual_rms / uncorrected_rms
    return {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (run.aligned_ns - run.start_ns) * 1e-9,
        "samples": int(valid.sum()),
        "nan_samples_after_alignment": int((after & ~valid).sum()),
        "before_sensor_w": describe(before_w),
        "after_enu_w": describe(after_w),
        "truth_enu_w": describe(truth_w),
        "residual_rms_mps": residual_rms,
        "uncorrected_error_rms_mps": uncorrected_rms,
        "residual_share_of_uncorrected": share,
        "range_share_after_before": describe(after_w)["range_mps"]
        / describe(before_w)["range_mps"],
        "mean_speed_corrected_mps": float(corrected_speed.mean()),
        "mean_speed_truth_mps": float(truth_speed.mean()),
        "speed_error_fraction": speed_error,
        "residual_share_pass": bool(share <= VERTICAL_RESIDUAL_SHARE_TARGET),
        "speed_error_pass": bool(abs(speed_error) <= VERTICAL_SPEED_ERROR_TARGET),
    }


def describe(values: np.ndarray) -> dict:
    return {
        "min_mps": float(values.min()),
        "max_mps": float(values.max()),
        "range_mps": float(values.max() - values.min()),
        "std_mps": float(values.std()),
        "mean_mps": float(values.mean()),
    }


# ---------------------------------------------------------------------------------------------
# Table 4: sea.


def analyse_sea(out_bag: str, scenario_duration_s: float) -> dict:
    config = compensator_config_from_files(PROCESSING_PARAMS)
    run = read_wind_run(out_bag)
    after = run.wind_stamp_ns >= run.aligned_ns
    valid = after & np.all(np.isfinite(run.corrected_enu_mps), axis=1)
    error = run.corrected_enu_mps[valid] - run.truth_enu_mps[valid]

    # Windows as the wind products align them: multiples of 600 s of the stamps.
    window_index = run.wind_stamp_ns // int(SEA_MEAN_WINDOW_S * 1e9)
    windows, too_short = [], []
    for index in np.unique(window_index[valid]):
        in_window = valid & (window_index == index)
        stamps = run.wind_stamp_ns[in_window]
        if (stamps[-1] - stamps[0]) * 1e-9 < MIN_MEAN_WINDOW_COVERAGE_S:
            too_short.append(int(in_window.sum()))
            continue
        corrected = run.corrected_enu_mps[in_window].mean(axis=0)
        truth = run.truth_enu_mps[in_window].mean(axis=0)
        speed_error = float(np.hypot(*corrected[:2]) - np.hypot(*truth[:2]))
        direction_error = float(
            wrap_deg(
                meteorological_direction_deg(*corrected[:2])
                - meteorological_direction_deg(*truth[:2])
            )
        )
        windows.append(
            {
                "start_s": (int(index) * SEA_MEAN_WINDOW_S * 1e9 - run.start_ns) * 1e-9,
                "covered_s": (stamps[-1] - stamps[0]) * 1e-9,
                "samples": int(in_window.sum()),
                "truth_speed_mps": float(np.hypot(*truth[:2])),
                "truth_direction_deg": float(meteorological_direction_deg(*truth[:2])),
                "speed_error_mps": speed_error,
                "direction_error_deg": direction_error,
                "speed_pass": bool(abs(speed_error) <= SEA_MEAN_SPEED_ERROR_MPS),
                "direction_pass": bool(abs(direction_error) <= SEA_MEAN_DIRECTION_ERROR_DEG),
            }
        )

    # The Miller terms, recomputed from the output bag's navigation exactly as process_bag
    # feeds it: ω_ib minus the Earth rate at the latitude of the solution before.
    latitudes = np.concatenate(([math.nan], run.nav_latitude_deg[:-1]))
    rates_nb = remove_earth_rate(run.nav.angular_rate_body_rad_s, run.nav.quat_xyzw, latitudes)
    batch = correct_batch(
        config,
        run.nav.t_s,
        run.nav.quat_xyzw,
        rates_nb,
        run.nav.velocity_enu_mps,
        run.wind_t_s,
        run.measured_sensor_mps,
    )
    batch_valid = batch.status == WindStatus.VALID
    recompute_difference = float(
        np.max(np.abs(batch.true_wind_enu_mps[valid] - run.corrected_enu_mps[valid]))
    )
    attitude, _ = nav_attitude_at(run, config)
    heading_rad = attitude.as_euler("ZYX")[:, 0]
    use = valid & batch_valid
    truth = run.truth_enu_mps[use]
    tilt = batch.tilt_term_enu_mps[use]
    rotation = batch.rotation_term_enu_mps[use]
    translation = batch.translation_term_enu_mps[use]
    # Uncorrected wind: the measured air velocity rotated by the mounting and by the
    # navigation heading of each sample (interpolated as the compensator does), nothing else:
    # what a buoy with a compass but no motion correction reports. Omitting the tilt term
    # means this heading-only rotation in place of the full attitude, so the three shares
    # measure the tilt, the lever-arm rotation and the platform velocity separately and the
    # heading, which any buoy measures, is common to all.
    levelled = heading_only_wind(run.measured_sensor_mps[use], heading_rad[use], config)
    full_rms = vector_rms(truth - (tilt + rotation + translation))
    uncorrected_rms = vector_rms(truth - levelled)
    omitted = {
        "tilt": levelled + rotation + translation,
        "rotation": tilt + translation,
        "translation": tilt + rotation,
    }
    shares = {
        term: (vector_rms(truth - wind) - full_rms) / uncorrected_rms
        for term, wind in omitted.items()
    }
    term_sizes = {
        "tilt_minus_heading_only": vector_rms(tilt - levelled),
        "rotation": vector_rms(rotation),
        "translation": vector_rms(translation),
    }
    return {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (run.aligned_ns - run.start_ns) * 1e-9,
        "samples": int(valid.sum()),
        "nan_samples_after_alignment": int((after & ~valid).sum()),
        "rms_error_enu_mps": {
            axis: rms(error[:, k]) for k, axis in enumerate(("east", "north", "up"))
        },
        "rms_error_vector_mps": vector_rms(error),
        "uncorrected_error_rms_vector_mps": uncorrected_rms,
        "full_correction_error_rms_vector_mps": full_rms,
        "mean_windows": windows,
        "samples_in_windows_too_short_to_report": too_short,
        "term_share_of_uncorrected_error": shares,
        "term_rms_mps": term_sizes,
        "recomputed_vs_bag_max_abs_mps": recompute_difference,
    }


ANALYSES = {
    "attitude": analyse_attitude,
    "tunnel": analyse_tunnel,
    "vertical": analyse_vertical,
    "sea": analyse_sea,
}


def run_case(case: Case, in_bag: str, out_bag: str) -> dict:
    """Process one cached bag and analyse the output (in a worker process)."""
    scenario_duration_s = load_scenario(case.scenario, list(case.overrides), None).duration_s
    with contextlib.redirect_stderr(io.StringIO()):
        if case.pipeline == "fuse":
            config = fusion_config_from_files(PROCESSING_PARAMS)
            _, _, wall_s, _, _ = fuse_bag(in_bag, out_bag, config, overwrite=True)
        else:
            summary = process_bag(
                in_bag,
                out_bag,
                fusion_config_from_files(PROCESSING_PARAMS),
                compensator_config_from_files(PROCESSING_PARAMS),
                overwrite=True,
            )
            wall_s = summary.wall_s
    started = time.monotonic()
    result = ANALYSES[case.analysis](out_bag, scenario_duration_s)
    result["pipeline"] = "fuse_bag" if case.pipeline == "fuse" else "process_bag"
    result["pipeline_wall_s"] = wall_s
    result["analysis_wall_s"] = time.monotonic() - started
    result["overrides"] = list(case.overrides)
    return result


def run_cases(cases: list[Case], bag_of: dict[str, Path]) -> dict[str, dict]:
    RUNS_DIR.mkdir(parents=True, exist_ok=True)
    results = {}
    with ProcessPoolExecutor(WORKERS) as pool:
        futures = {
            pool.submit(
                run_case, case, str(bag_of[case.key]), str(RUNS_DIR / case.key.replace("/", "_"))
            ): case
            for case in cases
        }
        for done, future in enumerate(as_completed(futures), 1):
            case = futures[future]
            results[case.key] = future.result()
            log(
                f"bench: [{done}/{len(cases)}] {results[case.key]['pipeline']} {case.label}: "
                f"{results[case.key]['pipeline_wall_s']:.1f} s"
            )
    return results


# ---------------------------------------------------------------------------------------------
# Table 5: speed.


def run_speed(in_bag: Path) -> dict:
    """fuse_bag and process_bag on the long bag, SPEED_RUNS times each, alternating, nothing else
    running in the bench. The figure of a tool is its fastest run: on a shared machine the
    other runs measure the neighbours as much as the code (all runs are kept in the results)."""
    out = RUNS_DIR / "speed"
    out.mkdir(parents=True, exist_ok=True)
    # Other work on the machine slows this down; the load average says how much there was.
    load_before = os.getloadavg()[0]
    walls: dict[str, list[float]] = {"fuse_bag": [], "process_bag": []}
    duration_s = math.nan
    for run in range(1, SPEED_RUNS + 1):
        # The bags the bench just wrote would otherwise be flushed to disk during the timing.
        os.sync()
        log(f"bench: speed: fuse_bag on the long bag, run {run} of {SPEED_RUNS}")
        _, _, fuse_wall_s, duration_s, _ = fuse_bag(
            str(in_bag), str(out / "fused"), fusion_config_from_files(PROCESSING_PARAMS), True
        )
        walls["fuse_bag"].append(fuse_wall_s)
        os.sync()
        log(f"bench: speed: process_bag on the long bag, run {run} of {SPEED_RUNS}")
        summary = process_bag(
            str(in_bag),
            str(out / "processed"),
            fusion_config_from_files(PROCESSING_PARAMS),
            compensator_config_from_files(PROCESSING_PARAMS),
            overwrite=True,
        )
        walls["process_bag"].append(summary.wall_s)
    steps = {}
    for name, runs_wall_s in walls.items():
        multiple = duration_s / min(runs_wall_s)
        steps[name] = {
            "data_s": duration_s,
            "wall_s": min(runs_wall_s),
            "runs_wall_s": runs_wall_s,
            "runs_real_time_multiple": [duration_s / wall for wall in runs_wall_s],
            "real_time_multiple": multiple,
            "pass": bool(multiple >= SPEED_TARGET_REAL_TIME),
        }
    return {
        "bag": in_bag.name,
        "target_real_time_multiple": SPEED_TARGET_REAL_TIME,
        "load_average_1min_before": load_before,
        "load_average_1min_after": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        **steps,
    }


# ---------------------------------------------------------------------------------------------
# Printing.


def mark(passed: bool) -> str:
    return "PASS" if passed else "MISS"


def fmt(value, spec: str = "+.3f") -> str:
    return (
        "—"
        if value is None or (isinstance(value, float) and math.isnan(value))
        else (format(value, spec))
    )


def pair(values, spec: str = "+.2f") -> str:
    return f"({format(values[0], spec)}, {format(values[1], spec)})"


def print_attitude(results: dict, quick: bool) -> None:
    print("\nTable 1 — attitude: fuse_bag vs truth/odometry (paper 000, Table 1)")
    print(
        "errors = estimate − truth of Euler ZYX angles (deg), after convergence; targets "
        "|err| ≤ 0.10/0.10/0.15°, RMS ≤ 0.05/0.05/0.08° (roll/pitch/heading)"
    )
    print(
        "convergence: filter's own 1σ (ENU attitude error E, N, U) below 0.05/0.05/0.08° "
        "from then on; times from scenario start"
    )
    for scenario, r in results.items():
        shortened = quick and QUICK_DURATION_S[scenario] is not None
        per_axis = ", ".join(
            f"{axis} {fmt(t, '.1f')}" for axis, t in r["convergence_per_axis_s"].items()
        )
        conv = (
            f"converged at {r['convergence_s']:.1f} s ({per_axis})"
            if r["converged"]
            else f"NOT converged ({per_axis}; final 1σ "
            + "/".join(f"{s:.3f}" for s in r["final_sigma_enu_deg"].values())
            + f"°): evaluated from alignment + {NOT_CONVERGED_FALLBACK_S:.0f} s"
        )
        print(
            f"\n{scenario}: {r['scenario_duration_s']:g} s"
            f"{' (shortened by --quick)' if shortened else ' (as shipped)'}, aligned at "
            f"{r['aligned_s']:.1f} s, {conv}; {r['evaluated_samples']} samples from "
            f"{r['evaluated_from_s']:.1f} s"
        )
        paper_row = PAPER_TABLE1_ROW.get(scenario)
        print(
            f"  {'angle':8s} {'max neg':>13s} {'max pos':>13s} {'RMS':>12s}   "
            f"{'paper system':>16s} {'paper MTi-3':>16s}"
        )
        for name in ("roll", "pitch", "heading"):
            e = r["errors_deg"][name]
            paper = PAPER_TABLE1_DEG[paper_row][name] if paper_row else None
            print(
                f"  {name:8s} {e['max_negative_deg']:+8.3f} {mark(e['max_negative_pass'])}"
                f" {e['max_positive_deg']:+8.3f} {mark(e['max_positive_pass'])}"
                f" {e['rms_deg']:7.3f} {mark(e['rms_pass'])}   "
                f"{pair(paper['combined_min_max_deg']) if paper else '—':>16s} "
                f"{pair(paper['mti3_min_max_deg']) if paper else '—':>16s}"
            )
        v = r["velocity_rms_enu_mps"]
        print(f"  velocity RMS error E/N/U: {v['east']:.4f} / {v['north']:.4f} / {v['up']:.4f} m/s")
    print(
        "\n(paper static row: MTi-3 at rest 2000 s; dynamic row: tilt table ±15° at 5°/s. "
        "max neg/pos: lowest and highest error, PASS when its magnitude meets the target.)"
    )


def print_seed_spread(shipped: dict, other_seeds: dict) -> None:
    print("\nTable 1b — attitude over seeds: the sea scenarios with other sensor errors and noise")
    print(
        "max |error| (RMS) after convergence, deg, as in Table 1; 'shipped' is the scenario's own "
        "seed; the accelerometer's y bias (roll) is learned only as the waves turn gravity"
    )
    print(
        f"  {'scenario':11s} {'seed':>7s} {'conv s':>7s} "
        + " ".join(f"{name:>18s}" for name in ("roll", "pitch", "heading"))
    )
    met = total = 0
    for scenario, by_seed in other_seeds.items():
        rows = [("shipped", shipped[scenario])] if scenario in shipped else []
        rows += [(str(seed), result) for seed, result in by_seed.items()]
        for seed, r in rows:
            cells = []
            passed = True
            for name in ("roll", "pitch", "heading"):
                e = r["errors_deg"][name]
                worst = max(-e["max_negative_deg"], e["max_positive_deg"])
                ok = e["max_negative_pass"] and e["max_positive_pass"] and e["rms_pass"]
                passed &= ok
                cells.append(f"{worst:.3f} ({e['rms_deg']:.3f}) {mark(ok)}")
            met += passed
            total += 1
            conv = f"{r['convergence_s']:.0f}" if r["converged"] else "never"
            print(f"  {scenario:11s} {seed:>7s} {conv:>7s} " + " ".join(f"{c:>18s}" for c in cells))
    print(f"  {met} of {total} runs meet every attitude target")


def print_tunnel(results: dict) -> None:
    print("\nTable 2 — wind tunnel: process_bag, means after alignment (paper 000, Table 2)")
    print(
        "speed: scalar mean of the horizontal speed (Δ columns); vector: speed of the vector "
        "mean; direction: meteorological, of the vector mean; Δ vs our still-level reference"
    )
    header = (
        f"  {'run':38s} {'valid':>6s} {'NaN':>4s} {'speed m/s':>10s} {'vector':>8s} "
        f"{'dir °':>8s} {'Δ m/s':>8s} {'Δ %':>7s} {'Δdir °':>8s}"
    )
    for speed in TUNNEL_SPEEDS_MPS:
        reference = results[f"tunnel/{speed}/reference"]
        motion = results[f"tunnel/{speed}/motion"]
        ref = reference["corrected"]
        print(f"\n{speed} m/s ({motion['scenario_duration_s']:g} s runs)")
        print(header)
        rows = [
            ("still level reference, corrected", reference, ref, True),
            ("sway+rotation, corrected", motion, motion["corrected"], True),
            (
                "sway+rotation, uncorrected (mean hdg)",
                motion,
                motion["uncorrected_mean_heading"],
                False,
            ),
            (
                "sway+rotation, levelled by hdg only",
                motion,
                motion["uncorrected_compass_heading"],
                False,
            ),
            ("truth (sway+rotation run)", motion, motion["truth"], False),
        ]
        for label, run, figures, count_nan in rows:
            delta = figures["mean_speed_mps"] - ref["mean_speed_mps"]
            print(
                f"  {label:38s} {figures['samples']:6d} "
                f"{run['nan_samples_after_alignment'] if count_nan else '':>4} "
                f"{figures['mean_speed_mps']:10.4f} {figures['vector_mean_speed_mps']:8.4f} "
                f"{figures['direction_deg']:8.3f} "
                f"{delta:+8.4f} {100 * delta / ref['mean_speed_mps']:+7.2f} "
                f"{wrap_deg(figures['direction_deg'] - ref['direction_deg']):+8.3f}"
            )
        still, corrected = PAPER_TABLE2[speed]["still"], PAPER_TABLE2[speed]["corrected"]
        p_delta = corrected["speed_mps"] - still["speed_mps"]
        print(
            f"  paper: still {still['speed_mps']:.4f} m/s {still['direction_deg']:.4f}°, "
            f"corrected {corrected['speed_mps']:.4f} m/s {corrected['direction_deg']:.4f}° → "
            f"Δ {p_delta:+.4f} m/s ({100 * p_delta / still['speed_mps']:+.2f} %), "
            f"{corrected['direction_deg'] - still['direction_deg']:+.3f}° (directions relative "
            "to the tunnel axis; ours are meteorological, the tunnel wind from 90°)"
        )
        error = motion["corrected"]["mean_speed_mps"] - ref["mean_speed_mps"]
        direction_error = wrap_deg(motion["corrected"]["direction_deg"] - ref["direction_deg"])
        within = (
            abs(error) < PAPER_TABLE2_BOUNDS["speed_error_mps"]
            and abs(direction_error) < PAPER_TABLE2_BOUNDS["direction_error_deg"]
        )
        print(
            f"  ours within the paper's bounds (|Δ| < 0.2 m/s, |Δdir| < 1°): "
            f"{'yes' if within else 'NO'}; mean heading used uncorrected: "
            f"{motion['uncorrected_mean_heading']['mean_heading_enu_deg']:.1f}° ENU"
        )


def print_vertical(results: dict) -> None:
    print("\nTable 3 — vertical wind: process_bag (paper 000, Table 3)")
    print(
        "before = measured w in anemometer axes; after = wind/true up; residual share = "
        "RMS(after − truth) / RMS(before − truth); targets ≤ 5 %, |speed error| ≤ 1 %"
    )
    print(
        f"  {'run':8s} {'before min~max':>17s} {'range':>6s} {'std':>6s}   "
        f"{'after min~max':>17s} {'range':>6s} {'std':>6s} {'mean':>7s}   "
        f"{'resid.':>7s} {'':4s} {'range':>6s}  {'speed err':>9s}"
    )
    for speed in VERTICAL_SPEEDS_MPS:
        r = results[f"vertical/{speed}"]
        b, a = r["before_sensor_w"], r["after_enu_w"]
        print(
            f"  {speed:>2d} m/s   {b['min_mps']:+7.3f}~{b['max_mps']:+7.3f}  {b['range_mps']:6.3f} "
            f"{b['std_mps']:6.3f}   {a['min_mps']:+7.3f}~{a['max_mps']:+7.3f}  "
            f"{a['range_mps']:6.3f} {a['std_mps']:6.3f} {a['mean_mps']:+7.3f}   "
            f"{100 * r['residual_share_of_uncorrected']:6.2f}% "
            f"{mark(r['residual_share_pass'])} {100 * r['range_share_after_before']:5.1f}%  "
            f"{100 * r['speed_error_fraction']:+7.3f}% {mark(r['speed_error_pass'])}"
        )
        p = PAPER_TABLE3[speed]
        p_before, p_after = p["before_min_max_mps"], p["after_min_max_mps"]
        range_share = (p_after[1] - p_after[0]) / (p_before[1] - p_before[0])
        print(
            f"  paper    {p_before[0]:+7.3f}~{p_before[1]:+7.3f}  {p_before[1] - p_before[0]:6.3f}"
            f" {'':6s}   {p_after[0]:+7.3f}~{p_after[1]:+7.3f}  {p_after[1] - p_after[0]:6.3f} "
            f"{'':6s} {p['mean_after_mps']:+7.3f}   {'':7s} {'':4s} {100 * range_share:5.1f}%"
        )
        print(
            f"           residual RMS {r['residual_rms_mps']:.4f} m/s of uncorrected "
            f"{r['uncorrected_error_rms_mps']:.4f}"
            f" m/s; mean speed {r['mean_speed_corrected_mps']:.4f} vs truth "
            f"{r['mean_speed_truth_mps']:.4f} m/s; {r['samples']} samples, "
            f"{r['nan_samples_after_alignment']} NaN"
        )
    print(
        f"  (paper: error reduced to {100 * PAPER_RESIDUAL_SHARE:.0f} % of the uncorrected one; "
        "its ratio matches the range share column)"
    )


def print_sea(results: dict) -> None:
    print("\nTable 4 — sea: process_bag, corrected wind vs truth/wind")
    print(
        "uncorrected = measured vector rotated by mounting + heading of each sample only; "
        "term share = (RMS err without the term − RMS err full) / RMS err uncorrected"
    )
    for scenario in SEA_SCENARIOS:
        r = results[f"sea/{scenario}"]
        e = r["rms_error_enu_mps"]
        print(
            f"\n{scenario} ({r['scenario_duration_s']:g} s, {r['samples']} samples, "
            f"{r['nan_samples_after_alignment']} NaN after alignment)"
        )
        print(
            f"  per-sample RMS error E/N/U: {e['east']:.4f} / {e['north']:.4f} / {e['up']:.4f} "
            f"m/s (vector {r['rms_error_vector_mps']:.4f}); uncorrected "
            f"{r['uncorrected_error_rms_vector_mps']:.4f} m/s"
        )
        for window in r["mean_windows"]:
            print(
                f"  10-min window from {window['start_s']:6.0f} s ({window['covered_s']:5.0f} s "
                f"of data{', partial' if window['covered_s'] < 0.95 * SEA_MEAN_WINDOW_S else ''}"
                f"): truth {window['truth_speed_mps']:.3f} m/s from "
                f"{window['truth_direction_deg']:.2f}°; error {window['speed_error_mps']:+.4f} "
                f"m/s {mark(window['speed_pass'])} (≤ 0.05), "
                f"{window['direction_error_deg']:+.3f}° {mark(window['direction_pass'])} (≤ 0.3)"
            )
        shares = r["term_share_of_uncorrected_error"]
        sizes = r["term_rms_mps"]
        print(
            "  share of the uncorrected error each Miller term removes (terms are correlated: "
            "shares need not add to 100 % and may exceed it): "
            + ", ".join(f"{term} {100 * share:.1f} %" for term, share in shares.items())
        )
        print(
            f"  term sizes (RMS): tilt beyond heading {sizes['tilt_minus_heading_only']:.3f}, "
            f"rotation {sizes['rotation']:.3f}, translation {sizes['translation']:.3f} m/s; "
            f"correct_batch vs wind/true max |Δ| {r['recomputed_vs_bag_max_abs_mps']:.1e} m/s"
        )


def print_speed(result: dict, quick: bool) -> None:
    print(
        "\nTable 5 — offline speed: open_ocean, in the bench process, nothing else running in "
        f"the bench (machine load average {result['load_average_1min_before']:.2f} before, "
        f"{result['load_average_1min_after']:.2f} after, {result['cpus']} CPUs)"
    )
    if quick:
        print(f"  (--quick: {SPEED_DURATION_S['quick']:g} s of data instead of one hour)")
    print(
        f"  {'step':12s} {'data s':>8s} {'wall s':>8s} {'× real time':>12s}  target ≥ 100×   "
        "× real time of each run (the best counts)"
    )
    for name in ("fuse_bag", "process_bag"):
        s = result[name]
        runs = " / ".join(f"{multiple:.1f}" for multiple in s["runs_real_time_multiple"])
        print(
            f"  {name:12s} {s['data_s']:8.0f} {s['wall_s']:8.1f} "
            f"{s['real_time_multiple']:12.1f}  {mark(s['pass']):14s} {runs}"
        )


def print_live(result: dict, title: str) -> None:
    print(f"\n{title}")
    if result.get("error"):
        print(f"  FAILED: {result['error']}")
    print(
        f"  {result['duration_s']:g} s at real time, ROS domain {result['ros_domain_id']}, "
        f"receive times from {result['receive_time_source']}; load average before "
        f"{result['load_average_1min_before']:.2f} on {result['cpus']} CPUs"
    )
    print(
        f"  latency = output − input receive time, same header stamp; 'in service' drops the "
        f"first {result['in_service_after_s']:g} s of output (the burst released at alignment); "
        "'src p99' uses the publishers' source stamps instead"
    )
    print(
        f"  {'pair':66s} {'pairs':>6s} {'median ms':>10s} {'p99 ms':>8s} {'max ms':>8s} "
        f"{'p99≤5':>5s} {'src p99':>8s}"
    )
    for name, stats in result["latency"].items():
        if not stats["pairs"]:
            print(f"  {name:66s} {0:6d}  no pairs")
            continue
        print(
            f"  {name:66s} {stats['pairs']:6d} {stats['median_ms']:10.2f} "
            f"{stats['p99_ms']:8.2f} {stats['max_ms']:8.2f} {mark(stats['p99_pass'])} "
            f"{stats['source_stamp_p99_ms']:8.2f}"
        )
    cpu = result["fusion_cpu"]
    fusion = "pass-through fusion_node" if result["passthrough"] else "fusion_node"
    if cpu.get("share_of_one_core") is None:
        print(f"  {fusion} CPU: not measured ({cpu.get('note', '')})")
    else:
        print(
            f"  {fusion} CPU: {100 * cpu['share_of_one_core']:.1f} % of one core over "
            f"{cpu['window_s']:.1f} s with imu/data_raw at {cpu['imu_rate_hz']:.1f} Hz"
        )
    print(f"  messages received: {result['received']}")


# ---------------------------------------------------------------------------------------------


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="bench", description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="short runs, for a smoke test")
    parser.add_argument(
        "--only",
        action="append",
        choices=SECTIONS,
        help="run only this part (repeatable); wind = tables 2, 3 and 4",
    )
    return parser.parse_args(argv)


def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    sections = set(arguments.only or SECTIONS)
    quick = arguments.quick
    started = time.monotonic()
    OUT_DIR.mkdir(parents=True, exist_ok=True)

    cases = plan_cases(sections, quick)
    fingerprint = simulator_fingerprint()
    wanted, bag_of = {}, {}
    for case in cases:
        path = cached_bag_path(case.scenario, case.overrides, fingerprint)
        wanted[path] = (case.scenario, case.overrides)
        bag_of[case.key] = path
    if "speed" in sections:
        speed_bag = cached_bag_path("open_ocean", speed_overrides(quick), fingerprint)
        wanted[speed_bag] = ("open_ocean", speed_overrides(quick))
    simulation_walls = ensure_bags(wanted)

    results = {
        "meta": {
            "quick": quick,
            "sections": sorted(sections),
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "cpus": os.cpu_count(),
            "workers": WORKERS,
            "processing_params_files": [str(Path(p).relative_to(REPO)) for p in PROCESSING_PARAMS],
            "simulation_params_files": [str(Path(p).relative_to(REPO)) for p in SIMULATION_PARAMS],
            "simulated_this_run_wall_s": simulation_walls,
        }
    }
    case_results = run_cases(cases, bag_of) if cases else {}
    if "attitude" in sections:
        attitude = {c.scenario: case_results[c.key] for c in cases if c.key.startswith("attitude/")}
        other_seeds = {
            scenario: {
                seed: case_results[f"attitude_seed/{scenario}/{seed}"] for seed in SEED_SPREAD
            }
            for scenario in SEED_SPREAD_SCENARIOS
        }
        results["attitude"] = {
            "targets": {
                "max_abs_error_deg": ATTITUDE_MAX_ERROR_DEG,
                "rms_deg": ATTITUDE_RMS_DEG,
                "convergence_sigma_enu_deg": CONVERGED_SIGMA_DEG,
            },
            "paper_table1_deg": PAPER_TABLE1_DEG,
            "scenarios": attitude,
            "other_seeds": other_seeds,
        }
        print_attitude(attitude, quick)
        print_seed_spread(attitude, other_seeds)
    if "wind" in sections:
        tunnel = {k: v for k, v in case_results.items() if k.startswith("tunnel/")}
        vertical = {k: v for k, v in case_results.items() if k.startswith("vertical/")}
        sea = {k: v for k, v in case_results.items() if k.startswith("sea/")}
        results["wind_tunnel"] = {
            "paper_table2": {str(k): v for k, v in PAPER_TABLE2.items()},
            "runs": {
                f"{speed}_mps": {
                    "reference": tunnel[f"tunnel/{speed}/reference"],
                    "motion": tunnel[f"tunnel/{speed}/motion"],
                    "speed_error_mps": tunnel[f"tunnel/{speed}/motion"]["corrected"][
                        "mean_speed_mps"
                    ]
                    - tunnel[f"tunnel/{speed}/reference"]["corrected"]["mean_speed_mps"],
                    "direction_error_deg": float(
                        wrap_deg(
                            tunnel[f"tunnel/{speed}/motion"]["corrected"]["direction_deg"]
                            - tunnel[f"tunnel/{speed}/reference"]["corrected"]["direction_deg"]
                        )
                    ),
                }
                for speed in TUNNEL_SPEEDS_MPS
            },
        }
        results["vertical_wind"] = {
            "paper_table3": {str(k): v for k, v in PAPER_TABLE3.items()},
            "paper_residual_share": PAPER_RESIDUAL_SHARE,
            "targets": {
                "residual_share": VERTICAL_RESIDUAL_SHARE_TARGET,
                "speed_error_fraction": VERTICAL_SPEED_ERROR_TARGET,
            },
            "runs": {f"{k.split('/')[1]}_mps": v for k, v in vertical.items()},
        }
        results["sea"] = {
            "targets": {
                "mean_speed_error_mps": SEA_MEAN_SPEED_ERROR_MPS,
                "mean_direction_error_deg": SEA_MEAN_DIRECTION_ERROR_DEG,
            },
            "scenarios": {k.split("/")[1]: v for k, v in sea.items()},
        }
        print_tunnel(tunnel)
        print_vertical(vertical)
        print_sea(sea)
    if "speed" in sections:
        results["speed"] = run_speed(speed_bag)
        print_speed(results["speed"], quick)
    if "live" in sections:
        import bench_live

        live_duration_s = LIVE_DURATION_S["quick" if quick else "full"]
        results["live"] = bench_live.run_live(live_duration_s, OUT_DIR / "live_logs")
        print_live(
            results["live"],
            "Table 6 — live: run_scenario sea_state with fusion_node and compensation_node",
        )
        # The same run with stand-ins that compute nothing: what the middleware, the executor
        # and this machine cost on the same path, to read Table 6 against.
        results["live_passthrough"] = bench_live.run_live(
            live_duration_s, OUT_DIR / "live_logs_passthrough", passthrough=True
        )
        print_live(
            results["live_passthrough"],
            "Table 6b — the floor: the same run with pass-through stand-ins for both nodes "
            "(tools/passthrough_node.py)",
        )
    if "consistency" in sections:
        import bias_consistency

        results["consistency"] = bias_consistency.run_consistency(
            CONSISTENCY_SEEDS["quick" if quick else "full"],
            CONSISTENCY_DURATION_S,
            CONSISTENCY_CHECKPOINTS_S,
        )
        bias_consistency.print_table(results["consistency"]["table"])

    results["meta"]["wall_s"] = time.monotonic() - started
    with open(OUT_DIR / "results.json", "w") as stream:
        json.dump(results, stream, indent=2, default=json_default)
    print(
        f"\nbench: {results['meta']['wall_s']:.0f} s wall; figures in "
        f"{(OUT_DIR / 'results.json').relative_to(REPO)}"
    )


def json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


if __name__ == "__main__":
    main()
