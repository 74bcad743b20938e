"""The fluxes of the corrected wind against the simulator's truth (``make bench``, section
``fluxes``; also run short by ``tests/system/test_fluxes_on_the_simulator.py``).

``open_ocean`` (a JONSWAP sea of Hs 3 m, the buoy rolling and pitching up to 20°, a turning
mooring, a turbulent 10 m/s wind) with a surface layer that carries fluxes: the along-wind and
vertical turbulence correlated at -0.3 (u'w' = -0.3 σu σw = -0.096 m²/s², u* = 0.31 m/s) and a
sonic temperature of 25 °C whose 0.1 K fluctuations correlate at 0.4 with the vertical wind
(w'T' = 0.016 K m/s), the truth sampled at the anemometer's stamps. ``process_bag`` computes the
fluxes of ``wind/true`` with the sonic temperature (``wind/fluxes_<window>``); the same core
computes those of ``truth/wind`` with the same temperature over the same samples. Per complete
window (coverage ≥ 0.9): u* and w'Ts' of each, and their relative difference, which is the
error the motion correction leaves in the fluxes (the turbulence's own sampling error is common
to both). Targets: u* within 5 %, w'T' within 10 %, over 30-min windows.

    python -m tools.bench_fluxes [--duration-s 3600] [--window-s 1800] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    NANOSECONDS_PER_SECOND,
    SONIC_TEMPERATURE_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_TRUE_TOPIC,
    wind_fluxes_topic,
)
from wind_comp.compensation_messages import stats_values
from wind_comp.flux_products import FluxAverager

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
BUOY_PARAMETERS = REPO / "src" / "buoy_common" / "config" / "buoy.yaml"
SCENARIO = "open_ocean"
SURFACE_LAYER = (
    "wind.momentum_flux_correlation=-0.3",
    "wind.sonic_temperature_degc=25.0",
    "wind.temperature_sigma_k=0.1",
    "wind.heat_flux_correlation=0.4",
    "sensors.rates.truth_hz=20.0",  # the anemometer's rate: truth at the anemometer's stamps
)
FRICTION_VELOCITY_TARGET = 0.05
"""Relative error of u* allowed over 30-min windows."""
HEAT_FLUX_TARGET = 0.10
"""Relative error of w'Ts' allowed over 30-min windows."""
MIN_COVERAGE = 0.9


def _run(command: list[str]) -> None:
    result = subprocess.run(command, capture_output=True, text=True, timeout=7200)
    if result.returncode not in (0,):
        raise RuntimeError(f"{' '.join(command)} failed: {result.stderr[-2000:]}")


def simulate_and_process(duration_s: float, window_s: float, work: Path) -> Path:
    """Simulate the surface layer for ``duration_s`` and process it with flux windows of
    ``window_s``; returns the processed bag."""
    simulated, processed = work / "simulated", work / "processed"
    overrides = [a for o in (f"duration_s={duration_s}", *SURFACE_LAYER) for a in ("--set", o)]
    _run([str(BIN / "simulate_bag"), SCENARIO, str(simulated), *overrides,
          "--params-file", str(BUOY_PARAMETERS)])  # fmt: skip
    flux_window = work / "flux_window.yaml"
    flux_window.write_text(
        f"/**:\n  ros__parameters:\n    compensation:\n      flux_window_s: {window_s}\n"
    )
    _run([str(BIN / "process_bag"), str(simulated), str(processed),
          "--params-file", str(BUOY_PARAMETERS), "--params-file", str(flux_window)])  # fmt: skip
    return processed


def _vectors(reader: BagReader, topic: str) -> tuple[np.ndarray, np.ndarray]:
    messages = [reader.decode(m) for m in reader.messages([topic])]
    stamps = np.array([m.header.stamp.sec * NANOSECONDS_PER_SECOND + m.header.stamp.nanosec
                       for m in messages])  # fmt: skip
    return stamps, np.array([[m.vector.x, m.vector.y, m.vector.z] for m in messages])


def flux_comparison(processed: Path, window_s: float) -> list[dict]:
    """Per window of ``process_bag``'s fluxes: u* and w'Ts' of the corrected wind and of the
    truth over the same samples (the truth masked where the corrected wind is invalid)."""
    with BagReader(processed) as reader:
        true_ns, corrected = _vectors(reader, WIND_TRUE_TOPIC)
        truth_ns, truth = _vectors(reader, TRUTH_WIND_TOPIC)
        temperatures = [reader.decode(m) for m in reader.messages([SONIC_TEMPERATURE_TOPIC])]
        products = [
            stats_values(reader.decode(m)) for m in reader.messages([wind_fluxes_topic(window_s)])
        ]
    common, in_truth, in_corrected = np.intersect1d(truth_ns, true_ns, return_indices=True)
    truth_wind = truth[in_truth]
    truth_wind[~np.isfinite(corrected[in_corrected]).all(axis=1)] = np.nan
    averager = FluxAverager(window_s)
    for message in temperatures:
        stamp = message.header.stamp
        averager.add_temperature(stamp.sec + stamp.nanosec * 1e-9, message.temperature)
    truth_fluxes = {
        product.window_start_s: product
        for product in averager.add_batch(common * 1e-9, truth_wind) + averager.flush()
    }
    rows = []
    for product in products:
        if product["coverage"] < MIN_COVERAGE:
            continue
        truth_product = truth_fluxes[product["window_start_s"]]
        rows.append(
            {
                "window_start_s": product["window_start_s"],
                "coverage": product["coverage"],
                "n_temperature": product["n_temperature"],
                "friction_velocity_truth_mps": truth_product.friction_velocity_mps,
                "friction_velocity_mps": product["friction_velocity_mps"],
                "friction_velocity_error": product["friction_velocity_mps"]
                / truth_product.friction_velocity_mps
                - 1.0,
                "w_ts_truth_k_mps": truth_product.w_ts_k_mps,
                "w_ts_k_mps": product["w_ts_k_mps"],
                "w_ts_error": product["w_ts_k_mps"] / truth_product.w_ts_k_mps - 1.0,
                "tilt_deg": product["tilt_deg"],
                "quality_flag": int(product["quality_flag"]),
            }
        )
    return rows


def table(rows: list[dict], window_s: float) -> str:
    lines = [
        f"Fluxes of the corrected wind against the truth, {SCENARIO}, {window_s:g}-s windows "
        f"(targets: u* within {FRICTION_VELOCITY_TARGET:.0%}, w'Ts' within "
        f"{HEAT_FLUX_TARGET:.0%} over 30-min windows)",
        "| window start (s) | u* truth (m/s) | u* corrected (m/s) | error | w'Ts' truth (K m/s) "
        "| w'Ts' corrected (K m/s) | error | tilt (deg) | flag |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['window_start_s']:.0f} | {row['friction_velocity_truth_mps']:.4f} | "
            f"{row['friction_velocity_mps']:.4f} | {row['friction_velocity_error']:+.2%} | "
            f"{row['w_ts_truth_k_mps']:.5f} | {row['w_ts_k_mps']:.5f} | {row['w_ts_error']:+.2%} "
            f"| {row['tilt_deg']:.2f} | {row['quality_flag']} |"
        )
    return "\n".join(lines)


def run(duration_s: float, window_s: float, out: Path | None = None) -> list[dict]:
    """Simulate, process and compare (in ``out``, or a temporary directory removed after)."""
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        return flux_comparison(simulate_and_process(duration_s, window_s, out), window_s)
    with tempfile.TemporaryDirectory(prefix="bench_fluxes_") as work:
        return flux_comparison(simulate_and_process(duration_s, window_s, Path(work)), window_s)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration-s", type=float, default=3600.0)
    parser.add_argument("--window-s", type=float, default=1800.0)
    parser.add_argument("--out", type=Path, help="keep the bags here")
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    arguments = parser.parse_args(argv)
    rows = run(arguments.duration_s, arguments.window_s, arguments.out)
    print(json.dumps(rows) if arguments.json else table(rows, arguments.window_s))


if __name__ == "__main__":
    main()
