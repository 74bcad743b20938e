"""`make bench` section ``antennas``: paper 001's comparison of attitude models.

Paper 001 (multi-antenna GPS/SINS attitude determination) compares, on a simulated flight, the
"traditional" model (position and velocity, the attitude from the antennas' heading) with its
baseline-vector model; three antennas fix all three angles. Its figures: traditional 0.25° yaw,
0.4° pitch, 0.5° roll; baseline vector 0.02° yaw and pitch, 0.1° roll.

Here the same three models run side by side on the simulator (the engine fed in-process, the
same sensor samples for all three):

* heading-only: GNSS position, velocity and the dual-antenna heading (``use_gnss_baseline``
  off);
* baseline vector: the primary → secondary vector (the default);
* three antennas: plus the primary → tertiary vector, the tertiary antenna at
  :data:`TERTIARY_ANTENNA_BODY_M`.

Trajectories: the simulator models a buoy, not an aircraft. The "flight-like" case is the
``tilt_table`` scenario (large, fast attitude changes: ±15° swings at 5 °/s about body x) and
the buoy cases are ``static`` and ``sea_state``. RMS errors are taken from 60 s after the
alignment; the convergence time is when the error of that angle last leaves the paper's
accuracy (0.02°, 0.02°, 0.1° for yaw, pitch, roll), measured from the alignment.
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_nav.aiding import (
    GnssBaseline,
    GnssBaselineTertiary,
    GnssFix,
    GnssHeading,
    GnssVelocity,
)
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine
from sensor_sim.scenario import load_scenario
from sensor_sim.sensor_models import GnssSimulator, ImuSimulator
from sensor_sim.truth import TruthModel

PAPER001_DEG = {
    "traditional": {"yaw": 0.25, "pitch": 0.4, "roll": 0.5},
    "baseline vector": {"yaw": 0.02, "pitch": 0.02, "roll": 0.1},
}
TERTIARY_ANTENNA_BODY_M = (0.0, 0.75, 1.0)
MODELS = {
    "heading only": {"use_gnss_baseline": False},
    "baseline vector": {},
    "three antennas": {"tertiary_antenna_body_m": TERTIARY_ANTENNA_BODY_M},
}
TRAJECTORIES = {
    "flight-like (tilt_table)": "tilt_table",
    "static": "static",
    "sea_state": "sea_state",
}
# Short runs keep the section a part of the default bench: 9 runs on two workers.
DURATION_S = {"full": 120.0, "quick": 90.0}
WORKERS = max(1, min(2, os.cpu_count() or 1))
IMU_RATE_HZ = 100.0
GNSS_RATE_HZ = 10.0
EVALUATE_AFTER_ALIGNMENT_S = 60.0
ANGLES = ("roll", "pitch", "yaw")
PAPER_ACCURACY_DEG = {"roll": 0.1, "pitch": 0.02, "yaw": 0.02}
# Targets with three antennas (default sensors): the max error of each axis on every
# trajectory after 60 s.
THREE_ANTENNA_MAX_DEG = 0.05


def run_model(scenario_name: str, duration_s: float, overrides: dict) -> dict:
    """The engine with ``overrides`` on a scenario; its attitude errors against the truth."""
    scenario = load_scenario(scenario_name, [f"duration_s={duration_s:g}"])
    truth = TruthModel(scenario)
    config = FusionConfig(**overrides)
    imu = ImuSimulator(truth, scenario.sensors.imu, scenario.seed)
    gnss = GnssSimulator(
        truth,
        scenario.sensors.gnss,
        config.primary_antenna_body_m,
        config.secondary_antenna_body_m,
        scenario.seed,
        TERTIARY_ANTENNA_BODY_M,
    )
    t_imu = np.arange(0.0, duration_s, 1.0 / IMU_RATE_HZ)
    t_gnss = np.arange(0.0, duration_s, 1.0 / GNSS_RATE_HZ)
    gyro, force = imu.measure(t_imu)
    sample = gnss.measure(t_gnss)
    engine = FusionEngine(config)
    solutions = []
    next_gnss = 0
    started = time.monotonic()
    for k, t in enumerate(t_imu):
        while next_gnss < t_gnss.size and t_gnss[next_gnss] <= t:
            i = next_gnss
            stamp = t_gnss[i]
            if sample.fix_valid[i]:
                engine.add_measurement(
                    stamp,
                    GnssFix(
                        sample.latitude_deg[i],
                        sample.longitude_deg[i],
                        sample.altitude_m[i],
                        sample.position_covariance_enu_m2[i],
                    ),
                )
                engine.add_measurement(
                    stamp,
                    GnssVelocity(
                        sample.velocity_enu_mps[i], sample.velocity_covariance_enu_m2s2[i]
                    ),
                )
            if sample.heading_valid[i]:
                engine.add_measurement(
                    stamp, GnssHeading(sample.heading_yaw_rad[i], sample.heading_variance_rad2[i])
                )
                engine.add_measurement(stamp, GnssBaseline(sample.baseline_enu_m[i]))
                engine.add_measurement(
                    stamp, GnssBaselineTertiary(sample.tertiary_baseline_enu_m[i])
                )
            next_gnss += 1
        solutions += engine.add_imu(t, gyro[k], force[k])
    solutions += engine.flush()
    stamps = np.array([s.t_s for s in solutions])
    true = truth.evaluate(stamps).attitude
    estimated = Rotation.from_quat([s.attitude_xyzw for s in solutions])
    difference = estimated.as_euler("ZYX")[:, ::-1] - true.as_euler("ZYX")[:, ::-1]
    errors = np.degrees((difference + math.pi) % (2 * math.pi) - math.pi)
    aligned = stamps[0]
    evaluated = stamps >= aligned + EVALUATE_AFTER_ALIGNMENT_S
    result = {"aligned_s": float(aligned), "wall_s": time.monotonic() - started}
    for k, angle in enumerate(ANGLES):
        outside = np.flatnonzero(np.abs(errors[:, k]) > PAPER_ACCURACY_DEG[angle])
        if outside.size == 0:
            convergence = 0.0
        elif outside[-1] == stamps.size - 1:
            convergence = None  # still outside at the end
        else:
            convergence = float(stamps[outside[-1] + 1] - aligned)
        result[angle] = {
            "rms_deg": float(np.sqrt(np.mean(errors[evaluated, k] ** 2))),
            "max_abs_deg": float(np.max(np.abs(errors[evaluated, k]))),
            "convergence_s": convergence,
        }
    return result


def run_antennas(quick: bool) -> dict:
    duration_s = DURATION_S["quick" if quick else "full"]
    with ProcessPoolExecutor(WORKERS) as pool:
        futures = {
            (label, model): pool.submit(run_model, scenario, duration_s, overrides)
            for label, scenario in TRAJECTORIES.items()
            for model, overrides in MODELS.items()
        }
        results = {
            label: {model: futures[(label, model)].result() for model in MODELS}
            for label in TRAJECTORIES
        }
    return {
        "duration_s": duration_s,
        "tertiary_antenna_body_m": TERTIARY_ANTENNA_BODY_M,
        "paper001_deg": PAPER001_DEG,
        "runs": results,
    }


def print_antennas(results: dict) -> None:
    print(
        "\nTable A — paper 001: attitude models side by side "
        f"({results['duration_s']:g} s, RMS and max from 60 s after alignment; convergence: "
        "time after alignment from which the error stays within the paper's accuracy)"
    )
    paper = results["paper001_deg"]
    print(
        f"  paper 001: traditional yaw {paper['traditional']['yaw']}°, pitch "
        f"{paper['traditional']['pitch']}°, roll {paper['traditional']['roll']}°; baseline "
        f"vector yaw {paper['baseline vector']['yaw']}°, pitch {paper['baseline vector']['pitch']}"
        f"°, roll {paper['baseline vector']['roll']}°"
    )
    header = "".join(f"{a + ' RMS/max (conv s)':>28s}" for a in ANGLES)
    for trajectory, models in results["runs"].items():
        print(f"\n  {trajectory}")
        print(f"  {'model':16s}{header}")
        for model, run in models.items():
            cells = []
            for angle in ANGLES:
                r = run[angle]
                convergence = "never" if r["convergence_s"] is None else f"{r['convergence_s']:.0f}"
                cells.append(f"{r['rms_deg']:.4f}/{r['max_abs_deg']:.4f} ({convergence})")
            verdict = ""
            if model == "three antennas":
                worst = max(run[a]["max_abs_deg"] for a in ANGLES)
                met = worst <= THREE_ANTENNA_MAX_DEG
                verdict = f"  max ≤ {THREE_ANTENNA_MAX_DEG}°: {'met' if met else 'NOT met'}"
            print(f"  {model:16s}" + "".join(f"{c:>28s}" for c in cells) + verdict)
