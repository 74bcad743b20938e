"""The real record without GNSS: does the fused platform velocity's stated σ cover its error?

Imports OOI's FDCHP record with the shipped column map and processes it (``process_bag``)
with ``ooi_fdchp_params.yaml`` and any ``--params-file`` on top, as ``tools/bench_fdchp.py``
does, and prints over the samples Edson keeps (30 s trimmed at each end):

- the fused horizontal velocity below 0.05 Hz (``nav/velocity``), which for a moored buoy is
  error (it moves by centimetres per second there): its standard deviation per axis, the median
  stated 1σ, and the share of samples where it exceeds three of the stated σ;
- the corrected wind's validity and the real record's criterion of
  ``tests/system/test_real_record_uncertainty.py``: valid samples whose horizontal speed the
  correction changes by more than Edson's largest change plus three of their own σ;
- the mooring's innovation warnings ``process_bag`` logged (their ratio and widening), and
  the widenings of the gyro's drift and of the velocity's noise by the mean velocity
  (:mod:`buoy_nav.mean_velocity_watch`);
- where in frequency the velocity lies: per band, its RMS beside the heave velocity the pack's
  vertical specific force gives (a buoy on the waves moves about as fast horizontally as
  vertically, so a horizontal velocity well above the heave's is error), and the normalised
  RMS of its block means for blocks of 5 to 60 s, as the mean-velocity watch judges its 30-s
  blocks (the excursion term from ``fusion.moored_position_sigma_horizontal_m``).

    python -m tools.fdchp_velocity_sigma [--record test_record|2014-12-18T18] [--rows N]
        [--params-file YAML ...]

``--rows 6000`` processes the first 10 min only, as the test does. Results go to
out/bench/fdchp_velocity_sigma.json.
"""

from __future__ import annotations

import argparse
import json
import re

import numpy as np
from scipy import signal, stats

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    IMU_RAW_TOPIC,
    NAV_VELOCITY_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_WITH_COVARIANCE_TOPIC,
)
from buoy_nav.config import fusion_config_from_files
from tools.bench_fdchp import (
    KEPT,
    OUT_DIR,
    PARAMS,
    RATE_HZ,
    SLOW_HZ,
    below,
    import_and_process_with_summary,
)
from tools.ooi_records import (
    OOI_RECORDS,
    OoiRecord,
    edsons_largest_speed_change_mps,
    first_rows,
    horizontal_speed_mps,
)

WARNING = re.compile(r"mooring innovations ([\d.]+)× .*?σ widened ([\d.]+)×")
DRIFT_WARNING = re.compile(
    r"mean velocity over \d+-s blocks is ([\d.]+)× .*?gyro's drift widened ([\d.]+)×"
)
NOISE_WARNING = re.compile(
    r"mean velocity over \d+-s blocks is ([\d.]+)× .*?velocity's noise widened ([\d.]+)×"
)


def velocity_and_sigma(reader: BagReader) -> tuple[np.ndarray, np.ndarray]:
    """``nav/velocity``'s east and north velocity (m/s) and their stated 1σ (m/s)."""
    velocity, sigma = [], []
    for message in reader.messages([NAV_VELOCITY_TOPIC]):
        twist = reader.decode(message).twist
        velocity.append((twist.twist.linear.x, twist.twist.linear.y))
        sigma.append(np.sqrt((twist.covariance[0], twist.covariance[7])))
    return np.array(velocity), np.array(sigma)


def wind_and_sigma(reader: BagReader) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured wind (sonic axes), corrected wind (ENU; NaN where invalid), both m/s, and the
    corrected wind's horizontal 1σ (the larger of east and north, m/s)."""
    measured = []
    for message in reader.messages([WIND_RAW_TOPIC]):
        vector = reader.decode(message).vector
        measured.append((vector.x, vector.y, vector.z))
    corrected, sigma = [], []
    for message in reader.messages([WIND_TRUE_WITH_COVARIANCE_TOPIC]):
        twist = reader.decode(message).twist
        linear = twist.twist.linear
        corrected.append((linear.x, linear.y, linear.z))
        sigma.append(np.sqrt(max(twist.covariance[0], twist.covariance[7])))
    return np.array(measured), np.array(corrected), np.array(sigma)


def velocity_figures(velocity: np.ndarray, sigma: np.ndarray) -> dict:
    slow = below(SLOW_HZ, velocity)[KEPT]
    stated = sigma[KEPT]
    return {
        "slow_velocity_std_en_mps": slow.std(axis=0).round(3).tolist(),
        "stated_sigma_median_en_mps": np.median(stated, axis=0).round(3).tolist(),
        "slow_velocity_beyond_3_sigma_share_en": (np.abs(slow) > 3.0 * stated)
        .mean(axis=0)
        .round(3)
        .tolist(),
    }


VELOCITY_BANDS_HZ = ((0.005, 0.02), (0.02, 0.05), (0.05, 0.1), (0.1, 0.2), (0.2, 0.5), (0.5, 1.0))
BLOCKS_S = (5.0, 10.0, 20.0, 30.0, 60.0)
BLOCK_QUANTILE = float(stats.chi2.ppf(0.999, 2))


def band_rms(series: np.ndarray, low_hz: float, high_hz: float) -> np.ndarray:
    """RMS (per column) of ``series`` (samples at RATE_HZ along axis 0) between the two
    frequencies, from its Welch spectrum."""
    frequency, density = signal.welch(
        series - series.mean(axis=0), fs=RATE_HZ, nperseg=4096, axis=0
    )
    inside = (frequency >= low_hz) & (frequency < high_hz)
    return np.sqrt(density[inside].sum(axis=0) * (frequency[1] - frequency[0]))


def velocity_bands(velocity_en_mps: np.ndarray, up_specific_force_mps2: np.ndarray) -> list:
    """Per band: the fused horizontal velocity's RMS (m/s, east and north) and the heave
    velocity's, the vertical specific force divided by 2πf (m/s)."""
    frequency, density = signal.welch(
        up_specific_force_mps2 - up_specific_force_mps2.mean(), fs=RATE_HZ, nperseg=4096
    )
    rows = []
    for low_hz, high_hz in VELOCITY_BANDS_HZ:
        inside = (frequency >= low_hz) & (frequency < high_hz)
        heave_density = density[inside] / (2.0 * np.pi * frequency[inside]) ** 2
        heave = float(np.sqrt(heave_density.sum() * (frequency[1] - frequency[0])))
        rows.append(
            {
                "band_hz": [low_hz, high_hz],
                "heave_velocity_mps": round(heave, 3),
                "velocity_en_mps": band_rms(velocity_en_mps, low_hz, high_hz).round(3).tolist(),
            }
        )
    return rows


def block_ratios(velocity_en_mps, sigma_en_mps, excursion_sigma_m: float) -> list:
    """Per block length: the normalised RMS of the blocks' mean velocity against their mean
    stated variance plus the excursion term 2 σ_h² / T², and the blocks beyond the 0.999
    quantile, as the mean-velocity watch judges them."""
    rows = []
    for block_s in BLOCKS_S:
        length = round(block_s * RATE_HZ)
        count = len(velocity_en_mps) // length
        means = velocity_en_mps[: count * length].reshape(count, length, 2).mean(axis=1)
        variances = (sigma_en_mps[: count * length] ** 2).reshape(count, length, 2).mean(axis=1)
        variances += 2.0 * excursion_sigma_m**2 / block_s**2
        normalised = (means**2 / variances).sum(axis=1)[1:]  # the first block holds the start
        rows.append(
            {
                "block_s": block_s,
                "ratio": round(float(np.sqrt(normalised.mean() / 2.0)), 2),
                "beyond_quantile": int(np.count_nonzero(normalised > BLOCK_QUANTILE)),
                "blocks": int(normalised.size),
            }
        )
    return rows


def up_specific_force_mps2(imported) -> np.ndarray:
    """The pack's vertical (body z) specific force of every IMU sample (m/s²)."""
    with BagReader(imported) as reader:
        return np.array(
            [
                reader.decode(message).linear_acceleration.z
                for message in reader.messages([IMU_RAW_TOPIC])
            ]
        )


def criterion_figures(
    record: OoiRecord, measured: np.ndarray, corrected: np.ndarray, sigma: np.ndarray
) -> dict:
    """Validity and the speed-change criterion over every processed sample of ``record``
    (without a valid sample, the counts alone)."""
    valid = np.isfinite(corrected).all(axis=1)
    change = np.abs(horizontal_speed_mps(corrected) - horizontal_speed_mps(measured))[valid]
    margin = change - (edsons_largest_speed_change_mps(record) + 3.0 * sigma[valid])
    figures = {"samples": int(valid.size), "valid": int(valid.sum()), "beyond_plausible": 0}
    if not change.size:
        return figures
    return figures | {
        "beyond_plausible": int(np.count_nonzero(margin > 0.0)),
        "closest_margin_mps": round(float(np.max(margin)), 3),
        "speed_change_median_p99_mps": np.percentile(change, (50, 99)).round(2).tolist(),
    }


def mooring_warnings(log: str, pattern: re.Pattern = WARNING) -> dict:
    """The count of the ``pattern``'s warnings in ``log``, their ratios' and widenings' ranges."""
    found = np.array([(float(a), float(b)) for a, b in pattern.findall(log)]).reshape(-1, 2)
    if not found.size:
        return {"count": 0}
    return {
        "count": len(found),
        "ratio_range": [float(found[:, 0].min()), float(found[:, 0].max())],
        "widened_range": [float(found[:, 1].min()), float(found[:, 1].max())],
    }


def measure(rows: int | None, parameter_files: list[str], name: str = "test_record") -> dict:
    """The figures of the module docstring for the OOI record ``name`` (its first ``rows``
    rows; None: all), processed with ``ooi_fdchp_params.yaml`` and ``parameter_files``."""
    record = OOI_RECORDS[name]
    work = OUT_DIR / "fdchp_velocity_sigma"
    work.mkdir(parents=True, exist_ok=True)
    processed, summary = import_and_process_with_summary(
        first_rows(record, rows, work), work, [PARAMS, *parameter_files], record.column_map
    )
    with BagReader(processed) as reader:
        velocity, velocity_sigma = velocity_and_sigma(reader)
        measured, corrected, wind_sigma = wind_and_sigma(reader)
    files = [str(path) for path in (PARAMS, *parameter_files)]
    excursion_sigma_m = fusion_config_from_files(files).moored_position_sigma_horizontal_m
    return {
        "record": name,
        "rows": rows,
        "params_files": [str(PARAMS), *parameter_files],
        "velocity": velocity_figures(velocity, velocity_sigma),
        "wind": criterion_figures(record, measured, corrected, wind_sigma),
        "mooring_warnings": mooring_warnings("\n".join(summary.fusion_lines)),
        "gyro_drift_widenings": mooring_warnings("\n".join(summary.fusion_lines), DRIFT_WARNING),
        "velocity_noise_widenings": mooring_warnings(
            "\n".join(summary.fusion_lines), NOISE_WARNING
        ),
        "velocity_bands": velocity_bands(velocity, up_specific_force_mps2(work / "fdchp")),
        "block_ratios": block_ratios(velocity, velocity_sigma, excursion_sigma_m),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        prog="fdchp_velocity_sigma", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--rows", type=int, help="process only the record's first ROWS rows")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML applied after ooi_fdchp_params.yaml (repeatable)",
    )
    parser.add_argument(
        "--record",
        choices=sorted(OOI_RECORDS),
        default="test_record",
        help="which OOI record: the text test record, or the binary records of 2014-12-18 18:00",
    )
    arguments = parser.parse_args(argv)
    result = measure(arguments.rows, arguments.params_file, arguments.record)
    print(json.dumps(result, indent=2))
    (OUT_DIR / "fdchp_velocity_sigma.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
