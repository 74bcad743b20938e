"""Sensor sets beyond RTK: accuracy of each set on the sea scenarios, the outage test, the
cost of a motion pack's lag.

    python -m tools.bench_sensor_sets [--quick] [--only table|outages|lag] [--scenario NAME]

Every case simulates its bag (``simulate_bag`` with the set's sensors), runs ``process_bag``
with the set's parameters and compares with the bag's truth, through the same analyses as
``make bench`` (``bench_analysis``). Results go to ``out/bench/sensor_sets.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.contract import AHRS_TOPIC, NAV_ODOMETRY_TOPIC, TRUTH_ODOMETRY_TOPIC
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from sensor_sim.scenario import load_scenario
from sensor_sim.simulate_bag import parse_arguments as simulate_arguments
from sensor_sim.simulate_bag import simulate
from tools.bench_analysis import (
    analyse_attitude,
    analyse_sea,
    heading_only_wind,
    nav_attitude_at,
    odometry_series,
    read_wind_run,
    wrap_deg,
)
from tools.bench_plan import PROCESSING_PARAMS, SIMULATION_PARAMS
from wind_comp.config import compensator_config_from_files

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "out" / "bench"
WORK = OUT / "sensor_sets"
HARD_IRON_UT = (4.0, -2.5, 1.5)
SOFT_IRON = (1.04, 0.02, -0.01, 0.02, 0.97, 0.015, -0.01, 0.015, 1.01)
MAGNETOMETER = (
    "sensors.magnetometer.fitted=true",
    f"sensors.magnetometer.hard_iron_ut={list(HARD_IRON_UT)}",
    f"sensors.magnetometer.soft_iron={list(SOFT_IRON)}",
)
MOTION_PACK = ("sensors.ahrs.fitted=true", "sensors.ahrs.yaw_reference=magnetic_north")
NO_GNSS = ("sensors.gnss.receiver=none",)
# A moored buoy stays on its mooring: the scenarios' drift with the current is removed.
MOORED = ("current=null",)


def outage_intervals(duration_s: float, period_s: float = 180.0, length_s: float = 60.0):
    """[start, end) of 60 s without GNSS every 180 s, the first after two minutes."""
    starts = np.arange(120.0, duration_s - length_s, period_s)
    return [[float(s), float(s + length_s)] for s in starts]


def magnetometer_calibration_lines(calibrated: bool, accel_bias_known_mg: float | None):
    """Fusion parameters of a calibrated magnetometer (the exact inverse of the simulated iron,
    which ``calibrate_magnetometer`` estimates from the turning run)."""
    lines = []
    if calibrated:
        inverse = np.linalg.inv(np.reshape(SOFT_IRON, (3, 3))).ravel()
        hard = [h * 1e-6 for h in HARD_IRON_UT]
        lines += [
            f"    fusion.magnetometer_hard_iron_t: {hard}",
            f"    fusion.magnetometer_soft_iron: {[float(v) for v in inverse]}",
        ]
    if accel_bias_known_mg is not None:
        lines.append(f"    fusion.accel_turn_on_bias_mg: {accel_bias_known_mg}")
    return lines


SETS = {
    # name: (simulation overrides, fusion parameter lines, description)
    "a_rtk": ((), [], "(a) IMU + dual-antenna RTK"),
    "b_single_mag": (
        ("sensors.gnss.receiver=single_antenna", *MAGNETOMETER),
        magnetometer_calibration_lines(True, None),
        "(b) IMU + single-antenna GNSS + magnetometer",
    ),
    "c_mag_moored": (
        (*NO_GNSS, *MAGNETOMETER, *MOORED),
        ["    fusion.moored: true", *magnetometer_calibration_lines(True, None)],
        "(c) IMU + magnetometer, moored, no GNSS (5 mg bias)",
    ),
    "c_mag_moored_bias_known": (
        (*NO_GNSS, *MAGNETOMETER, *MOORED, "sensors.imu.accel_turn_on_bias_mg=0.5"),
        ["    fusion.moored: true", *magnetometer_calibration_lines(True, 0.5)],
        "(c) IMU + magnetometer, moored, no GNSS, bias known to 0.5 mg",
    ),
    "d_motion_pack": (
        (*NO_GNSS, *MOTION_PACK, *MOORED),
        ["    fusion.moored: true", "    fusion.ahrs_lag_s: 0.2"],
        "(d) IMU + motion pack (AHRS, lag 0.2 s), moored, no GNSS",
    ),
}


def parameter_file(directory: Path, scenario, lines: list[str], magnetic: bool) -> str:
    path = directory / "params.yaml"
    site = [
        f"    site.latitude_deg: {scenario.origin_latitude_deg}",
        f"    site.longitude_deg: {scenario.origin_longitude_deg}",
    ]
    reference = ["    ahrs.yaw_reference: magnetic_north"] if magnetic else []
    path.write_text("/**:\n  ros__parameters:\n" + "\n".join([*site, *reference, *lines]) + "\n")
    return str(path)


def run_case(name: str, scenario_name: str, overrides: tuple, lines: list, duration_s: float):
    """Simulate, process and analyse one case (in a worker)."""
    directory = WORK / f"{scenario_name}_{name}"
    directory.mkdir(parents=True, exist_ok=True)
    overrides = (*overrides, f"duration_s={duration_s}")
    scenario = load_scenario(scenario_name, list(overrides), None)
    in_bag, out_bag = directory / "in", directory / "out"
    arguments = [scenario_name, str(in_bag), "--overwrite"]
    for override in overrides:
        arguments += ["--set", override]
    for params in SIMULATION_PARAMS:
        arguments += ["--params-file", params]
    with contextlib.redirect_stderr(io.StringIO()):
        simulate(simulate_arguments(arguments))
        params = [*PROCESSING_PARAMS, parameter_file(directory, scenario, lines, True)]
        process_bag(
            str(in_bag),
            str(out_bag),
            fusion_config_from_files(params),
            compensator_config_from_files(params),
            overwrite=True,
        )
    return {
        "attitude": analyse_attitude(str(out_bag), duration_s),
        "wind": analyse_sea(str(out_bag), duration_s),
        "vertical_residual_share": vertical_residual_share(str(out_bag), params),
    }


def vertical_residual_share(out_bag: str, params: list[str]) -> float:
    """RMS of the corrected vertical wind error over that of the uncorrected one (the
    measured air velocity turned by mounting and heading only)."""
    config = compensator_config_from_files(params)
    run = read_wind_run(out_bag)
    valid = (run.wind_stamp_ns >= run.aligned_ns) & np.all(
        np.isfinite(run.corrected_enu_mps), axis=1
    )
    attitude, _ = nav_attitude_at(run, config)
    heading = attitude.as_euler("ZYX")[:, 0]
    levelled = heading_only_wind(run.measured_sensor_mps[valid], heading[valid], config)
    truth_up = run.truth_enu_mps[valid, 2]
    corrected = np.sqrt(np.mean((run.corrected_enu_mps[valid, 2] - truth_up) ** 2))
    uncorrected = np.sqrt(np.mean((levelled[:, 2] - truth_up) ** 2))
    return float(corrected / uncorrected)


def outage_split(out_bag: str, intervals, start_ns: int) -> dict:
    """Attitude (RMS and max, deg) and per-sample wind (vector RMS, m/s) errors inside and
    outside the GNSS outages, after the first two minutes."""
    with BagReader(out_bag) as reader:
        nav = odometry_series(reader, NAV_ODOMETRY_TOPIC)
        truth = odometry_series(reader, TRUTH_ODOMETRY_TOPIC)
    common, i_nav, i_truth = np.intersect1d(nav.stamps_ns, truth.stamps_ns, return_indices=True)
    error = wrap_deg(
        np.degrees(
            Rotation.from_quat(nav.quat_xyzw[i_nav]).as_euler("ZYX")
            - Rotation.from_quat(truth.quat_xyzw[i_truth]).as_euler("ZYX")
        )
    )
    run = read_wind_run(out_bag)
    wind_error = run.corrected_enu_mps - run.truth_enu_mps

    def inside(stamps_ns):
        t = (stamps_ns - start_ns) * 1e-9
        flag = np.zeros(t.shape, dtype=bool)
        for begin, end in intervals:
            flag |= (t >= begin) & (t < end)
        return flag, t >= 120.0

    result = {"gnss_returns": gnss_return_steps(nav, truth, i_nav, i_truth, intervals, start_ns)}
    nav_in, nav_late = inside(common)
    wind_in, wind_late = inside(run.wind_stamp_ns)
    finite = np.all(np.isfinite(wind_error), axis=1)
    for name, nav_mask, wind_mask in (
        ("inside", nav_in & nav_late, wind_in & wind_late & finite),
        ("outside", ~nav_in & nav_late, ~wind_in & wind_late & finite),
    ):
        angles = error[nav_mask]
        result[name] = {
            "attitude_rms_deg": {
                axis: float(np.sqrt(np.mean(angles[:, k] ** 2)))
                for k, axis in ((2, "roll"), (1, "pitch"), (0, "heading"))
            },
            "attitude_max_deg": {
                axis: float(np.abs(angles[:, k]).max())
                for k, axis in ((2, "roll"), (1, "pitch"), (0, "heading"))
            },
            "wind_rms_mps": float(np.sqrt(np.mean(np.sum(wind_error[wind_mask] ** 2, axis=1)))),
        }
    return result


def gnss_return_steps(nav, truth, i_nav, i_truth, intervals, start_ns: int) -> list[dict]:
    """What the fusion does to its attitude when GNSS returns after each outage: the attitude
    error (rotation vector of R_nav R_trueᵀ, deg) just before the return, the largest change of
    that error from one solution to the next in the 5 s after it (the correction's step), and
    the filter's own 1σ just before (root sum of the three attitude variances, deg)."""
    stamps_ns = nav.stamps_ns[i_nav]
    error_deg = np.degrees(
        (
            Rotation.from_quat(nav.quat_xyzw[i_nav])
            * Rotation.from_quat(truth.quat_xyzw[i_truth]).inv()
        ).as_rotvec()
    )
    sigma_deg = np.degrees(
        np.sqrt(np.trace(nav.attitude_covariance_enu_rad2[i_nav], axis1=1, axis2=2))
    )
    returns = []
    for _, end_s in intervals:
        end_ns = start_ns + int(end_s * 1e9)
        before = np.searchsorted(stamps_ns, end_ns) - 1
        after = np.searchsorted(stamps_ns, end_ns + 5_000_000_000)
        if before < 0 or after <= before + 1:
            continue
        changes = np.linalg.norm(np.diff(error_deg[before:after], axis=0), axis=1)
        returns.append(
            {
                "return_s": float(end_s),
                "error_before_deg": float(np.linalg.norm(error_deg[before])),
                "largest_step_deg": float(changes.max()),
                "sigma_before_deg": float(sigma_deg[before]),
                "step_over_sigma": float(changes.max() / sigma_deg[before]),
            }
        )
    return returns


def ahrs_lag_cost(scenario_name: str, duration_s: float) -> dict:
    """RMS and max of the motion pack's own roll/pitch error against the truth (what its lag
    costs when used as is)."""
    directory = WORK / f"{scenario_name}_d_motion_pack"
    with BagReader(str(directory / "in")) as reader:
        truth = odometry_series(reader, TRUTH_ODOMETRY_TOPIC)
        stamps, quats = [], []
        for message in reader.messages([AHRS_TOPIC]):
            stamps.append(message.log_time_ns)
            q = reader.decode(message).orientation
            quats.append((q.x, q.y, q.z, q.w))
    stamps = np.array(stamps)
    index = np.searchsorted(truth.stamps_ns, stamps)
    keep = (index < truth.stamps_ns.size) & (
        truth.stamps_ns[np.minimum(index, truth.stamps_ns.size - 1)] == stamps
    )
    pack = Rotation.from_quat(np.array(quats)[keep]).as_euler("ZYX")
    true = Rotation.from_quat(truth.quat_xyzw[index[keep]]).as_euler("ZYX")
    error = wrap_deg(np.degrees(pack - true))
    return {
        axis: {
            "rms_deg": float(np.sqrt(np.mean(error[:, k] ** 2))),
            "max_deg": float(np.max(np.abs(error[:, k]))),
        }
        for k, axis in ((2, "roll"), (1, "pitch"))
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="300 s runs instead of 600 s")
    parser.add_argument("--scenario", action="append", help="sea_state and/or open_ocean")
    parser.add_argument("--set", dest="sets", action="append", help="sensor sets to run")
    parser.add_argument("--outages", action="store_true", help="also the outage test")
    arguments = parser.parse_args(argv)
    duration = 300.0 if arguments.quick else 600.0
    scenarios = arguments.scenario or ["sea_state", "open_ocean"]
    cases = {}
    for scenario_name in scenarios:
        for name in arguments.sets or list(SETS):
            overrides, lines, _ = SETS[name]
            cases[(scenario_name, name)] = (overrides, lines)
        if arguments.outages:
            cases[(scenario_name, "e_rtk_outages")] = (
                (f"sensors.gnss.fix_outages_s={outage_intervals(duration)}",),
                [],
            )
    results = {}
    with ProcessPoolExecutor(2) as pool:
        futures = {
            key: pool.submit(run_case, key[1], key[0], overrides, lines, duration)
            for key, (overrides, lines) in cases.items()
        }
        for key, future in futures.items():
            results["/".join(key)] = future.result()
            print(f"done {key}", file=sys.stderr)
    for (scenario_name, name), result in zip(cases, results.values(), strict=True):
        start_ns = load_scenario(scenario_name).start_time_ns
        if name == "e_rtk_outages":
            out_bag = WORK / f"{scenario_name}_{name}" / "out"
            result["outage_split"] = outage_split(
                str(out_bag), outage_intervals(duration), start_ns
            )
        if name == "d_motion_pack":
            result["motion_pack_own_error"] = ahrs_lag_cost(scenario_name, duration)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "sensor_sets.json").write_text(json.dumps(results, indent=1, default=str))
    print_table(results)
    for key, result in results.items():
        for extra in ("outage_split", "motion_pack_own_error"):
            if extra in result:
                print(f"{key} {extra}: {json.dumps(result[extra])}")


def print_table(results: dict) -> None:
    print(
        "| scenario | set | roll max/RMS ° | pitch max/RMS ° | heading max/RMS ° | "
        "wind RMS m/s | 10-min speed err m/s | 10-min dir err ° | vertical residual share |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for key, result in results.items():
        scenario_name, name = key.split("/")
        errors = result["attitude"]["errors_deg"]
        cells = []
        for axis in ("roll", "pitch", "heading"):
            e = errors[axis]
            largest = max(abs(e["max_negative_deg"]), abs(e["max_positive_deg"]))
            cells.append(f"{largest:.2f} / {e['rms_deg']:.3f}")
        wind = result["wind"]
        windows = wind.get("mean_windows", [])
        speed = max((abs(w["speed_error_mps"]) for w in windows), default=float("nan"))
        direction = max((abs(w["direction_error_deg"]) for w in windows), default=float("nan"))
        print(
            f"| {scenario_name} | {name} | {' | '.join(cells)} | "
            f"{wind['rms_error_vector_mps']:.3f} | {speed:.3f} | "
            f"{direction:.2f} | {result['vertical_residual_share']:.3f} |"
        )


if __name__ == "__main__":
    main()
