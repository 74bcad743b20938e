"""The named flux tests on simulated windows of known fluxes (``make bench``, section ``fluxes``;
also ``tests/system/test_flux_quality_on_the_simulator.py``).

The surface layer of ``tools/bench_fluxes.py`` (``open_ocean``, 10 m/s, u* 0.31 m/s, w'T' 0.016
K m/s) is simulated and processed by ``process_bag``; then the same flux core
(``wind_comp.flux_products.FluxAverager`` with the shipped thresholds) flags, per window:

- ``truth``: the simulator's true wind at the anemometer's stamps (masked where the corrected
  wind is invalid), with the sonic temperature;
- ``corrected``: ``wind/true``, the motion-corrected wind ``process_bag`` wrote (its flags are
  those of ``wind/fluxes_<window>``);
- ``tenfold_stress``: the corrected wind whose fluctuations about each window's mean are
  scaled by √10: the same eddies, √10 stronger, over the same mean wind. The stress grows
  tenfold while σw/u*, the stress's direction and r_wT stay those of a real surface layer, as
  a sonic whose gain is wrong or turbulence from elsewhere (a mast's wake) would give; only
  the stress against the mean wind (the drag coefficient) can tell;
- ``motion_left``: the corrected wind minus half the platform's velocity (``nav/velocity``,
  the IMU's, interpolated to the wind's stamps): a correction that took out only half the
  buoy's motion. The wave orbital velocities are mostly a quarter period apart in the
  horizontal and the vertical, so they add variance to w far more than covariance to u'w'.

    python -m tools.bench_flux_quality [--duration-s 3600] [--window-s 1800] [--out DIR] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

import numpy as np

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    NAV_VELOCITY_TOPIC,
    SONIC_TEMPERATURE_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_TRUE_TOPIC,
    stamp_to_ns,
)
from buoy_processing.report.data import stamped_vectors
from tools import bench_fluxes
from wind_comp.flux_products import FluxAverager, FluxProduct
from wind_comp.flux_quality import FLUX_FLAG_TESTS

STRESS_FACTOR = 10.0
MOTION_LEFT_SHARE = 0.5
MIN_COVERAGE = 0.9
CASES = ("truth", "corrected", "tenfold_stress", "motion_left")


def _platform_velocity_enu_mps(reader: BagReader, stamps_ns: np.ndarray) -> np.ndarray:
    """``nav/velocity`` (ENU, m/s) interpolated to ``stamps_ns``."""
    rows = []
    for message in reader.messages([NAV_VELOCITY_TOPIC]):
        sample = reader.decode(message)
        linear = sample.twist.twist.linear
        rows.append((stamp_to_ns(sample.header.stamp), linear.x, linear.y, linear.z))
    table = np.array(rows, dtype=float)
    return np.column_stack([np.interp(stamps_ns, table[:, 0], table[:, k]) for k in (1, 2, 3)])


def _about_window_means_scaled(
    t_s: np.ndarray, wind_mps: np.ndarray, window_s: float, factor: float
) -> np.ndarray:
    """``wind_mps`` (N, 3) with its fluctuations about each aligned window's mean scaled by
    ``factor``; NaN samples stay NaN."""
    scaled = wind_mps.copy()
    windows = np.floor(t_s / window_s)
    for window in np.unique(windows):
        members = windows == window
        mean = np.nanmean(wind_mps[members], axis=0)
        scaled[members] = mean + factor * (wind_mps[members] - mean)
    return scaled


def case_winds(processed: Path, window_s: float) -> tuple[np.ndarray, dict, list, np.ndarray]:
    """Stamps (s), the wind (ENU, m/s) of each case of :data:`CASES`, the sonic temperatures
    (stamp s, °C) of the processed bag, and the platform's vertical velocity (ENU up, m/s) at
    the stamps, for the motion-left test."""
    with BagReader(processed) as reader:
        corrected = stamped_vectors(reader, WIND_TRUE_TOPIC)
        truth = stamped_vectors(reader, TRUTH_WIND_TOPIC)
        temperatures = [
            (stamp_to_ns(m.header.stamp) * 1e-9, m.temperature)
            for m in (reader.decode(raw) for raw in reader.messages([SONIC_TEMPERATURE_TOPIC]))
        ]
        common, in_truth, in_corrected = np.intersect1d(
            truth.stamps_ns, corrected.stamps_ns, return_indices=True
        )
        platform = _platform_velocity_enu_mps(reader, common)
    wind = corrected.vectors[in_corrected]
    true_wind = truth.vectors[in_truth]
    true_wind[~np.isfinite(wind).all(axis=1)] = np.nan
    t_s = common * 1e-9
    winds = {
        "truth": true_wind,
        "corrected": wind,
        "tenfold_stress": _about_window_means_scaled(t_s, wind, window_s, math.sqrt(STRESS_FACTOR)),
        "motion_left": wind - MOTION_LEFT_SHARE * platform,
    }
    return t_s, winds, temperatures, platform[:, 2]


def case_windows(
    t_s, wind_mps, temperatures, platform_up_mps, window_s: float
) -> list[FluxProduct]:
    averager = FluxAverager(window_s)
    for stamp, value in temperatures:
        averager.add_temperature(stamp, value)
    return averager.add_batch(t_s, wind_mps, platform_up_mps) + averager.flush()


def quality_rows(processed: Path, window_s: float) -> list[dict]:
    """Per complete window (coverage ≥ :data:`MIN_COVERAGE` in the corrected wind) and case:
    u*, the values the tests judge and every test's flag."""
    t_s, winds, temperatures, platform_up = case_winds(processed, window_s)
    windows = {
        case: case_windows(t_s, winds[case], temperatures, platform_up, window_s) for case in CASES
    }
    complete = {p.window_start_s for p in windows["corrected"] if p.coverage >= MIN_COVERAGE}
    rows = []
    for case in CASES:
        for product in windows[case]:
            if product.window_start_s not in complete:
                continue
            rows.append(
                {
                    "case": case,
                    "window_start_s": product.window_start_s,
                    "mean_speed_mps": product.mean_speed_mps,
                    "friction_velocity_mps": product.friction_velocity_mps,
                    "drag_ratio": product.drag_coefficient / product.drag_coefficient_neutral_10m,
                    "sigma_w_over_u_star": product.sigma_w_mps / product.friction_velocity_mps,
                    "cross_wind_stress_ratio": product.cross_wind_stress_ratio,
                    "w_ts_correlation": product.w_ts_correlation,
                    "stationarity_u_w_percent": product.stationarity_u_w_percent,
                    **{test.name: getattr(product, test.field) for test in FLUX_FLAG_TESTS},
                    "quality_flag": product.quality_flag,
                }
            )
    return rows


def table(rows: list[dict], window_s: float) -> str:
    names = [test.name for test in FLUX_FLAG_TESTS]
    lines = [
        f"Flux tests on {bench_fluxes.SCENARIO}, {window_s:g}-s windows (flags: 1 pass, 2 not "
        "evaluated, 3 suspect, 4 fail)",
        "| case | window start (s) | U (m/s) | u* (m/s) | C_D/C_D10N | σw/u* "
        f"| \\|v'w'\\|/\\|u'w'\\| | r_wT | stationarity (%) | {' | '.join(names)} | overall |",
        "|---|---|---|---|---|---|---|---|---|" + "---|" * len(names) + "---|",
    ]
    for row in rows:
        flags = " | ".join(str(row[name]) for name in names)
        lines.append(
            f"| {row['case']} | {row['window_start_s']:.0f} | {row['mean_speed_mps']:.2f} | "
            f"{row['friction_velocity_mps']:.3f} | {row['drag_ratio']:.2f} | "
            f"{row['sigma_w_over_u_star']:.2f} | {row['cross_wind_stress_ratio']:.2f} | "
            f"{row['w_ts_correlation']:.2f} | {row['stationarity_u_w_percent']:.1f} | {flags} | "
            f"{row['quality_flag']} |"
        )
    return "\n".join(lines)


def run(duration_s: float, window_s: float, out: Path | None = None) -> dict:
    """Simulate and process (in ``out``, or a temporary directory removed after); the fluxes
    against the truth (:func:`tools.bench_fluxes.flux_comparison`) and the flux tests."""
    with tempfile.TemporaryDirectory(prefix="bench_flux_quality_") as work:
        directory = out or Path(work)
        directory.mkdir(parents=True, exist_ok=True)
        processed = bench_fluxes.simulate_and_process(duration_s, window_s, directory)
        return {
            "fluxes": bench_fluxes.flux_comparison(processed, window_s),
            "flux_quality": quality_rows(processed, window_s),
        }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration-s", type=float, default=3600.0)
    parser.add_argument("--window-s", type=float, default=1800.0)
    parser.add_argument("--out", type=Path, help="keep the bags here")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    arguments = parser.parse_args(argv)
    results = run(arguments.duration_s, arguments.window_s, arguments.out)
    if arguments.json:
        print(json.dumps(results["flux_quality"], default=int))
    else:
        print(table(results["flux_quality"], arguments.window_s))


if __name__ == "__main__":
    main()
