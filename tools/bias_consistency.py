"""Monte-Carlo consistency of the accelerometer-bias estimate over many seeds.

A single run says little about whether the filter's covariance is honest: an error of 3.6σ is
rare but not impossible. This runs ``sea_state`` once per seed with an IMU whose only errors are
its turn-on biases, so the true bias is exactly the simulator's draw for that seed, fuses each
run with the shipped parameters and, at each checkpoint (s after the first IMU sample), takes
per axis the normalised error z = (true − estimated bias) / σ and the 3-dof NEES of the bias.

For a consistent filter the mean of z² is 1 and the mean NEES 3; the filter still assumes the
default IMU noise, which this IMU does not have, so somewhat less is expected. The table gives
the two-sided 95 % chi-square bounds of the means over the seeds.

    python -m tools.bias_consistency [--seeds 2-201] [--duration-s 75] [--checkpoints 30 50 70]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from buoy_common.bag_io import BagReader, BagWriter
from buoy_nav.config import fusion_config_from_files
from buoy_processing.offline_fusion import OfflineFusion, relative_topic, sensor_topics_of
from sensor_sim.sensor_errors import ImuErrorConfig
from sensor_sim.sensor_models import ImuSimulator
from sensor_sim.simulate_bag import simulate
from sensor_sim.streams import IMU_SEED_KEY

REPO = Path(__file__).resolve().parents[1]
BUOY_PARAMS = str(REPO / "src/buoy_common/config/buoy.yaml")
SIMULATION_PARAMS = [BUOY_PARAMS]
FUSION_PARAMS = [BUOY_PARAMS, str(REPO / "src/buoy_nav/config/fusion.yaml")]
SCENARIO = "sea_state"
# Every IMU error but the turn-on biases switched off: then the truth of the bias is known.
TURN_ON_BIASES_ONLY = """/**/imu_sim_node:
  ros__parameters:
    imu:
      gyro_noise_deg_sqrt_h: 0.0
      gyro_bias_instability_deg_h: 0.0
      accel_noise_mps_sqrt_h: 0.0
      accel_bias_instability_mg: 0.0
      scale_factor_error_percent: 0.0
"""
AXES = ("x", "y", "z")
WORKERS = 2


def true_accel_bias_mps2(seed: int) -> np.ndarray:
    """The simulator's turn-on accelerometer bias for ``seed`` (body axes, m/s²)."""
    return ImuSimulator(None, ImuErrorConfig(), [seed, IMU_SEED_KEY]).accel_turn_on_bias_mps2


def run_seed(seed: int, duration_s: float, checkpoints_s: tuple[float, ...]) -> dict:
    """Simulate and fuse one seed; z per axis and NEES at each checkpoint (in a worker)."""
    with tempfile.TemporaryDirectory(prefix="bias_consistency-") as scratch:
        imu_params = Path(scratch) / "turn_on_biases_only.yaml"
        imu_params.write_text(TURN_ON_BIASES_ONLY)
        in_bag, out_bag = str(Path(scratch) / "in"), str(Path(scratch) / "out")
        with contextlib.redirect_stderr(io.StringIO()):
            simulate(
                argparse.Namespace(
                    scenario=SCENARIO,
                    output=in_bag,
                    overrides=[f"duration_s={duration_s:g}", f"seed={seed}"],
                    seed=None,
                    params_file=[*SIMULATION_PARAMS, str(imu_params)],
                    no_truth=True,
                    overwrite=False,
                )
            )
        truth = true_accel_bias_mps2(seed)
        pending = sorted(checkpoints_s)
        rows = []
        with BagReader(in_bag) as reader, BagWriter(out_bag) as writer:
            config = fusion_config_from_files(FUSION_PARAMS)
            fusion = OfflineFusion(config, writer)
            topics = sensor_topics_of(reader, config)
            start_ns = None
            for message in reader.messages(list(topics.values())):
                fusion.add_message(reader, relative_topic(message.topic), message)
                start_ns = start_ns if start_ns is not None else message.log_time_ns
                elapsed_s = (message.log_time_ns - start_ns) * 1e-9
                if pending and elapsed_s >= pending[0] and fusion.engine.aligned:
                    accel_bias = fusion.engine.states.accel_bias
                    covariance = fusion.engine.covariance[accel_bias, accel_bias]
                    error = truth - fusion.engine.nav_state.accel_bias_mps2
                    rows.append(
                        {
                            "checkpoint_s": pending.pop(0),
                            "z": (error / np.sqrt(np.diag(covariance))).tolist(),
                            "nees": float(error @ np.linalg.solve(covariance, error)),
                        }
                    )
    return {"seed": seed, "true_bias_mg": (truth / 9.80665e-3).tolist(), "checkpoints": rows}


def summarise(runs: list[dict], checkpoints_s: tuple[float, ...]) -> list[dict]:
    """Per checkpoint: mean z, mean z² per axis and mean NEES, with 95 % bounds of the means."""
    table = []
    for checkpoint in checkpoints_s:
        rows = [r for run in runs for r in run["checkpoints"] if r["checkpoint_s"] == checkpoint]
        if not rows:
            continue
        n = len(rows)
        z = np.array([r["z"] for r in rows])
        nees = np.array([r["nees"] for r in rows])
        table.append(
            {
                "checkpoint_s": checkpoint,
                "runs": n,
                "mean_z": dict(zip(AXES, z.mean(axis=0).tolist(), strict=True)),
                "mean_z2": dict(zip(AXES, (z**2).mean(axis=0).tolist(), strict=True)),
                "mean_z2_bounds_95": [chi2.ppf(0.025, n) / n, chi2.ppf(0.975, n) / n],
                "max_abs_z": dict(zip(AXES, np.abs(z).max(axis=0).tolist(), strict=True)),
                "mean_nees": float(nees.mean()),
                "mean_nees_bounds_95": [chi2.ppf(0.025, 3 * n) / n, chi2.ppf(0.975, 3 * n) / n],
            }
        )
    return table


def print_table(table: list[dict]) -> None:
    print(f"\nAccelerometer-bias consistency, {SCENARIO}, IMU with turn-on biases only")
    print(
        f"{'t, s':>6} {'runs':>5} {'mean z² x / y / z':>22} {'95 % bounds':>14} "
        f"{'max |z| x / y / z':>20} {'mean NEES':>10} {'95 % bounds':>14}"
    )
    for row in table:
        z2 = " / ".join(f"{row['mean_z2'][a]:.2f}" for a in AXES)
        max_z = " / ".join(f"{row['max_abs_z'][a]:.1f}" for a in AXES)
        low, high = row["mean_z2_bounds_95"]
        nees_low, nees_high = row["mean_nees_bounds_95"]
        print(
            f"{row['checkpoint_s']:6.0f} {row['runs']:5d} {z2:>22} "
            f"{f'{low:.2f}–{high:.2f}':>14} {max_z:>20} {row['mean_nees']:10.2f} "
            f"{f'{nees_low:.2f}–{nees_high:.2f}':>14}"
        )


def seed_range(text: str) -> list[int]:
    first, _, last = text.partition("-")
    return list(range(int(first), int(last or first) + 1))


def run_consistency(seeds, duration_s: float, checkpoints_s: tuple[float, ...]) -> dict:
    """Every seed's run (two at a time) and the summary table."""
    runs = []
    with ProcessPoolExecutor(WORKERS) as pool:
        futures = [pool.submit(run_seed, seed, duration_s, checkpoints_s) for seed in seeds]
        for done, future in enumerate(futures, 1):
            runs.append(future.result())
            print(
                f"bias_consistency: [{done}/{len(futures)}] seed {runs[-1]['seed']}",
                file=sys.stderr,
                flush=True,
            )
    return {
        "scenario": SCENARIO,
        "duration_s": duration_s,
        "imu": "turn-on biases only",
        "runs": runs,
        "table": summarise(runs, checkpoints_s),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--seeds",
        type=seed_range,
        default=seed_range("2-201"),
        help="seeds to run, A-B or A (default 2-201)",
    )
    parser.add_argument(
        "--duration-s", type=float, default=75.0, help="length of each run, s (default 75)"
    )
    parser.add_argument(
        "--checkpoints",
        type=float,
        nargs="+",
        default=[30.0, 50.0, 70.0],
        help="times after the first IMU sample, s (default 30 50 70)",
    )
    parser.add_argument("--json", type=Path, help="also write the runs and the table here")
    arguments = parser.parse_args(sys.argv[1:] if argv is None else argv)
    result = run_consistency(arguments.seeds, arguments.duration_s, tuple(arguments.checkpoints))
    print_table(result["table"])
    if arguments.json:
        arguments.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
