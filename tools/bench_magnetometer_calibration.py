"""Which motions of a moored buoy let ``calibrate_magnetometer`` recover the iron from the record.

    python -m tools.bench_magnetometer_calibration [--quick] [--only CASE ...]

Each case simulates (``simulate_bag``) the moored buoy of ``measured_moored_no_gnss`` with its
uncalibrated magnetometer (hard iron (18, −27.5, 12) µT, soft iron 1.08/0.93/1.02 with
off-diagonals up to 0.07, 0.1 µT noise at 10 Hz) and without its motion pack, so that the
magnetometer alone gives the heading, with one roll/pitch amplitude and one yaw motion, for
RECORD_S. It runs the ``calibrate_magnetometer`` command on the bag (written or refused, and
why), holds the fit it writes (or, refused, the one it would have written) against the
simulator's iron, and for a written calibration runs ``fuse_bag`` over the same record with it
(moored, the buoy's site) and holds the fused heading against the truth after SETTLING_S,
noting whether the fusion still suspended the magnetometer. Prints a table and writes
out/bench/magnetometer_calibration.json. ``--quick`` runs the scenario's own sea (9/7.5°)
only.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation, Slerp

from buoy_common.bag_io import BagReader
from buoy_common.contract import NAV_ODOMETRY_TOPIC, TRUTH_ODOMETRY_TOPIC, stamp_to_ns
from buoy_nav.calibrate_magnetometer import read_field
from buoy_nav.calibration import CalibrationError, fit_magnetometer
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_fusion import fuse_bag
from sensor_sim.scenario import load_scenario
from sensor_sim.simulate_bag import parse_arguments as simulate_arguments
from sensor_sim.simulate_bag import simulate
from tools.bench_plan import PROCESSING_PARAMS, REPO
from tools.bench_uncertainty import MOORED, suspensions_in

OUT = REPO / "out" / "bench"
WORK = OUT / "magnetometer_calibration"
SCENARIO = "measured_moored_no_gnss"
RECORD_S = 720.0
"""One mooring swing (600 s) or one full turn and back at 1°/s, with margin."""
SETTLING_S = 120.0
"""The fused heading is judged after this much of the record: alignment and convergence."""
BASE_OVERRIDES = ("sensors.ahrs.fitted=false", f"duration_s={RECORD_S:g}")
TILTS = {
    "2°": ("motion.roll_amplitude_deg=2", "motion.pitch_amplitude_deg=2"),
    "9/7.5°": (),
    "20°": ("motion.roll_amplitude_deg=20", "motion.pitch_amplitude_deg=20"),
}
"""Roll/pitch amplitudes at the scenario's 6.5 s period; 9/7.5° is the scenario's own sea."""
YAW_MOTIONS = {
    "fixed heading, ±3° wobble": ("motion.mooring_yaw_amplitude_deg=0",),
    "±20° swing": ("motion.mooring_yaw_amplitude_deg=20",),
    "±90° swing": ("motion.mooring_yaw_amplitude_deg=90",),
    "full turn and back": (
        "motion.mooring_yaw_amplitude_deg=0",
        "motion.rotation_range_deg=360",
        "motion.rotation_rate_deg_s=1",
        "motion.corner_time_s=5",
    ),
}
"""The ±3° wave-period wobble of the scenario stays under every motion; the swings are the
mooring's over 600 s; the turn is a slow one on the mooring, 360° at 1°/s and back."""
CASES = {
    f"{tilt} | {yaw}": (*BASE_OVERRIDES, *tilt_overrides, *yaw_overrides)
    for tilt, tilt_overrides in TILTS.items()
    for yaw, yaw_overrides in YAW_MOTIONS.items()
}


def iron_errors(hard_iron_t, soft_iron, scenario) -> dict:
    """The calibration against the simulator's iron: hard-iron error (µT, norm) and the largest
    soft-iron element error, both matrices scaled to unit determinant (the fit keeps the field
    magnitude, so its scale is the record's, not the simulator's)."""
    errors = scenario.sensors.magnetometer
    expected = np.linalg.inv(np.reshape(errors.soft_iron, (3, 3)))
    found = np.reshape(soft_iron, (3, 3))
    difference = found / np.cbrt(np.linalg.det(found)) - expected / np.cbrt(np.linalg.det(expected))
    return {
        "hard_iron_error_ut": float(
            np.linalg.norm(np.asarray(hard_iron_t) * 1e6 - errors.hard_iron_ut)
        ),
        "soft_iron_error": float(np.abs(difference).max()),
    }


def the_fit(in_bag: Path, scenario) -> dict:
    """The fit of the record whether or not the command accepts it, against the truth."""
    try:
        fit = fit_magnetometer(read_field(str(in_bag)))
    except CalibrationError as error:
        return {"fit": str(error)}
    return {
        **iron_errors(fit.hard_iron_t, fit.soft_iron, scenario),
        "residual_nt": fit.residual_t * 1e9,
        "noise_nt": fit.noise_t * 1e9,
        "hard_iron_sigma_ut": (fit.hard_iron_sigma_t * 1e6).tolist(),
        "soft_iron_sigma": float(np.max(fit.soft_iron_sigma)),
    }


def run_command(in_bag: Path, out_yaml: Path) -> tuple[int, str]:
    """``calibrate_magnetometer`` on the bag: exit code and its last stderr line."""
    command = [str(Path(sys.executable).parent / "calibrate_magnetometer")]
    command += [str(in_bag), str(out_yaml), "--overwrite"]
    done = subprocess.run(command, capture_output=True, text=True)
    lines = done.stderr.strip().splitlines()
    return done.returncode, (lines[-1].removeprefix("calibrate_magnetometer: ") if lines else "")


def heading_errors_deg(out_bag: Path) -> dict:
    """RMS and largest heading error (deg) of ``nav/odometry`` against the truth after
    SETTLING_S: the yaw of R_nav R_true⁻¹."""
    with BagReader(out_bag) as reader:
        nav = [reader.decode(r) for r in reader.messages([NAV_ODOMETRY_TOPIC])]
        truth = [reader.decode(r) for r in reader.messages([TRUTH_ODOMETRY_TOPIC])]
    truth_s = np.array([stamp_to_ns(m.header.stamp) for m in truth]) * 1e-9
    nav_s = np.array([stamp_to_ns(m.header.stamp) for m in nav]) * 1e-9
    keep = (nav_s >= truth_s[0] + SETTLING_S) & (nav_s <= truth_s[-1])
    true = Slerp(truth_s - truth_s[0], Rotation.from_quat([_xyzw(m) for m in truth]))
    fused = Rotation.from_quat([_xyzw(m) for m in nav])[keep]
    error = (fused * true(nav_s[keep] - truth_s[0]).inv()).as_euler("ZYX", degrees=True)[:, 0]
    return {
        "heading_rms_deg": float(np.sqrt(np.mean(error**2))),
        "heading_max_deg": float(np.abs(error).max()),
    }


def _xyzw(odometry) -> tuple[float, float, float, float]:
    q = odometry.pose.pose.orientation
    return q.x, q.y, q.z, q.w


def fuse_with(directory: Path, in_bag: Path, calibration_yaml: Path, scenario) -> dict:
    """``fuse_bag`` over the record with the written calibration: heading errors and the
    fusion's suspensions."""
    site = directory / "site.yaml"
    site.write_text(
        "/**:\n  ros__parameters:\n"
        f"    site.latitude_deg: {scenario.origin_latitude_deg}\n"
        f"    site.longitude_deg: {scenario.origin_longitude_deg}\n    {MOORED}\n"
    )
    config = fusion_config_from_files([*PROCESSING_PARAMS, str(site), str(calibration_yaml)])
    out_bag = directory / "fused"
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        fused = fuse_bag(str(in_bag), str(out_bag), config, overwrite=True)
    lines = fused.fusion.summary()
    (directory / "fusion.log").write_text("\n".join(lines) + "\n")
    return {**heading_errors_deg(out_bag), "suspended": suspensions_in(lines)}


def run_case(key: str) -> dict:
    """Simulate, calibrate, judge and (when written) fuse one motion (in a worker)."""
    overrides = CASES[key]
    directory = WORK / re.sub(r"[^A-Za-z0-9.]+", "_", key).strip("_")
    directory.mkdir(parents=True, exist_ok=True)
    in_bag, calibration_yaml = directory / "in", directory / "magnetometer.yaml"
    arguments = [SCENARIO, str(in_bag), "--overwrite"]
    for override in overrides:
        arguments += ["--set", override]
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        simulate(simulate_arguments(arguments))
    scenario = load_scenario(SCENARIO, list(overrides), None)
    exit_code, message = run_command(in_bag, calibration_yaml)
    result = {
        "written": exit_code == 0,
        "refusal": message if exit_code else "",
        **the_fit(in_bag, scenario),
    }
    if exit_code == 0:
        values = yaml.safe_load(calibration_yaml.read_text())["/**"]["ros__parameters"]
        result |= iron_errors(
            values["fusion.magnetometer_hard_iron_t"],
            values["fusion.magnetometer_soft_iron"],
            scenario,
        )
        result |= fuse_with(directory, in_bag, calibration_yaml, scenario)
    return result


def _cell(value, digits: int) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def print_table(results: dict) -> None:
    print(
        "| roll/pitch | yaw motion | calibrate_magnetometer | hard-iron error µT | soft-iron error "
        "| residual nT | heading RMS / max ° | magnetometer suspended |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for key, result in results.items():
        tilt, yaw = key.split(" | ")
        verdict = "written" if result["written"] else f"refused: {result['refusal']}"
        heading = (
            f"{result['heading_rms_deg']:.2f} / {result['heading_max_deg']:.2f}"
            if "heading_rms_deg" in result
            else "–"
        )
        suspended = ("yes" if result["suspended"] else "no") if "suspended" in result else "–"
        print(
            f"| {tilt} | {yaw} | {verdict} | {_cell(result.get('hard_iron_error_ut'), 2)} | "
            f"{_cell(result.get('soft_iron_error'), 3)} | {_cell(result.get('residual_nt'), 0)} | "
            f"{heading} | {suspended} |"
        )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="the scenario's own sea (9/7.5°) only")
    parser.add_argument("--only", nargs="+", choices=sorted(CASES), help="run these cases")
    args = parser.parse_args(argv)
    keys = args.only or [key for key in CASES if not args.quick or key.startswith("9/7.5°")]
    WORK.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max_workers=2) as pool:
        futures = {key: pool.submit(run_case, key) for key in keys}
        results = {key: future.result() for key, future in futures.items()}
    print_table(results)
    (OUT / "magnetometer_calibration.json").write_text(json.dumps(results, indent=1, default=float))
    print(
        f"figures in {(OUT / 'magnetometer_calibration.json').relative_to(REPO)}", file=sys.stderr
    )


if __name__ == "__main__":
    main()
