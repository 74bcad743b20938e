"""The real record: OOI's FDCHP flux-buoy record, our processing beside Edson's.

Imports ``fdchp_test_dp.dat`` with the shipped column map (``import_records``), processes it with
the motion-pack sensor set (``process_bag`` with ``ooi_fdchp_params.yaml``), runs Edson's
published processing on the same record (``tools/edson_fdchp.py``; skipped, with the published
fluxes only, when no ion-functions checkout is at hand), and prints over the samples Edson keeps
(30 s trimmed at each end):

- the wave-band variance of the corrected vertical wind as a share of the uncorrected;
- the mean coherence of the vertical wind with the buoy's vertical acceleration in the wave
  band, before and after correction;
- mean and standard deviation of the corrected wind (East, North, Up; referenced to magnetic
  north on both sides);
- the fluxes u'w', v'w', w'Ts', u*, with the flux QC, from ``wind_comp.fluxes`` for ours, and
  both Edson's own and ``wind_comp.fluxes`` applied to his corrected wind;
- the wave motion left that ``process_bag`` publishes for each flux window of the record
  (``wind/fluxes_<window>``: wave band, coherence, share left, "motion left" flag).

    python -m tools.bench_fdchp [--record PATH] [--ion-functions DIR] [--params-file YAML ...]

Results go to out/bench/fdchp.json, the figure of the wave band to out/bench/fdchp_wave_band.png.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    IMU_RAW_TOPIC,
    NAV_ODOMETRY_TOPIC,
    NAV_VELOCITY_TOPIC,
    SONIC_TEMPERATURE_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
)
from buoy_common.import_records import import_records
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import ProcessSummary, process_bag
from buoy_processing.report.data import published_fluxes, stamped_vectors
from tools import edson_fdchp, fdchp_figures
from wind_comp.config import compensator_config_from_files
from wind_comp.fluxes import linear_detrend, rotation_into_mean_wind, window_fluxes
from wind_comp.motion_residual import (
    motion_residual,
    platform_velocity_left,
    vertical_acceleration_mps2,
)

REPO = Path(__file__).resolve().parent.parent
RECORD = Path(os.environ.get("FDCHP_RECORD", "/work/shared/data/ooi_fdchp/fdchp_test_dp.dat"))
CONFIG = REPO / "src/buoy_common/config/records"
COLUMN_MAP = CONFIG / "ooi_fdchp.yaml"
PARAMS = CONFIG / "ooi_fdchp_params.yaml"
OUT_DIR = REPO / "out/bench"
FIGURE = OUT_DIR / "fdchp_wave_band.png"
RATE_HZ = 10.0
KEPT = slice(300, 11700)
"""The samples Edson's fluxes use: the first 12 000 rows less 30 s at each end."""
BANDS_HZ = ((0.0, 0.005), (0.005, 0.02), (0.02, 0.05), (0.05, 0.3), (0.3, 1.0), (1.0, 5.1))
"""Frequency bands of the flux split: the low frequencies where a platform velocity drifts, the
wave band, the turbulence above it."""
SLOW_HZ = 0.05
EDSON_HIGH_PASS_HZ = 1.0 / 12.0
"""Corner of the high-pass Edson's processing applies to the integrated platform velocity."""
SLOW_TILT_HZ = EDSON_HIGH_PASS_HZ
"""Below this Edson's processing takes the tilt from the accelerometers (above it from the
gyros); so does the test of where the flux difference comes from."""
UNDER_APPLIED_GAINS = (0.97, 0.9, 0.8)
"""Shares of our platform velocity applied in the sweep that shows what the figures reward."""
ENU_FROM_NWU = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def import_and_process(record: Path, work: Path, parameter_files) -> Path:
    """Import an FDCHP L0 record into ``work`` with the shipped column map and process it with
    ``parameter_files`` (later files win); returns the processed bag."""
    return import_and_process_with_summary(record, work, parameter_files)[0]


def import_and_process_with_summary(
    record: Path, work: Path, parameter_files, column_map: Path = COLUMN_MAP
) -> tuple[Path, ProcessSummary]:
    """:func:`import_and_process`, with what ``process_bag`` says of the run (``column_map``:
    the record's, the text test record's by default)."""
    imported, processed = work / "fdchp", work / "fdchp_processed"
    import_records(record, column_map, imported, overwrite=True)
    files = [str(path) for path in parameter_files]
    with contextlib.redirect_stdout(io.StringIO()):
        summary = process_bag(
            imported,
            processed,
            fusion_config_from_files(files),
            compensator_config_from_files(files),
            overwrite=True,
        )
    return processed, summary


def process_record(record: Path, work: Path, extra_parameter_files=()) -> Path:
    """Import and process the record into ``work`` with the shipped parameters and then
    ``extra_parameter_files``; returns the processed bag."""
    return import_and_process(record, work, [PARAMS, *extra_parameter_files])


def read_processed(processed: Path) -> dict[str, np.ndarray]:
    """Stamps, sensor-axes and corrected wind, sonic temperature and specific force."""
    with BagReader(processed) as reader:
        measured = stamped_vectors(reader, WIND_RAW_TOPIC)
        corrected = stamped_vectors(reader, WIND_TRUE_TOPIC)
    imported = processed.with_name("fdchp")
    with BagReader(imported) as reader:
        temperature = [
            reader.decode(m).temperature for m in reader.messages([SONIC_TEMPERATURE_TOPIC])
        ]
        force = [
            (lambda a: (a.x, a.y, a.z))(reader.decode(m).linear_acceleration)
            for m in reader.messages([IMU_RAW_TOPIC])
        ]
    return {
        "time_s": measured.stamps_ns * 1e-9,
        "measured": measured.vectors,
        "corrected": corrected.vectors,
        "temperature_degc": np.array(temperature),
        "specific_force": np.array(force),
    }


def band_split(time_s, wind, temperature) -> dict:
    """u'w', v'w', w'Ts' and the variance of w per band of :data:`BANDS_HZ`: real parts of the
    cross-spectra of the series rotated into their mean wind and detrended (NaN filled by
    linear interpolation), integrated over each band."""
    filled = np.array(wind, dtype=float)
    for axis in range(3):
        valid = np.isfinite(filled[:, axis])
        filled[:, axis] = np.interp(time_s, time_s[valid], filled[valid, axis])
    rotation, _ = rotation_into_mean_wind(filled.mean(axis=0))
    u, v, w = (linear_detrend(time_s, c) for c in (filled @ rotation.T).T)
    ts = linear_detrend(time_s, temperature)
    split = {}
    for name, a, b in (("u_w", u, w), ("v_w", v, w), ("w_ts", w, ts), ("w_w", w, w)):
        frequency, density = signal.csd(a, b, fs=RATE_HZ, nperseg=4096, detrend=False)
        step = frequency[1] - frequency[0]
        split[name] = [
            round(float(np.real(density[(frequency >= lo) & (frequency < hi)]).sum() * step), 5)
            for lo, hi in BANDS_HZ
        ]
    return split


def platform_velocity_enu(processed: Path, time_s) -> np.ndarray:
    """``nav/velocity`` (E, N, U; m/s) interpolated to ``time_s``."""
    with BagReader(processed) as reader:
        rows = []
        for message in reader.messages([NAV_VELOCITY_TOPIC]):
            decoded = reader.decode(message)
            stamp = decoded.header.stamp
            linear = decoded.twist.twist.linear
            rows.append((stamp.sec + stamp.nanosec * 1e-9, linear.x, linear.y, linear.z))
    rows = np.array(rows)
    return np.column_stack([np.interp(time_s, rows[:, 0], rows[:, i]) for i in (1, 2, 3)])


def below(cutoff_hz: float, series: np.ndarray) -> np.ndarray:
    """What of ``series`` (samples along axis 0, at RATE_HZ) lies below ``cutoff_hz``:
    second-order Butterworth, forward and backward (no phase)."""
    low_pass = signal.butter(2, cutoff_hz, fs=RATE_HZ, output="sos")
    return signal.sosfiltfilt(low_pass, series, axis=0)


def slow_tilt_from_accelerometers(
    processed: Path, time_s, specific_force_body: np.ndarray
) -> Rotation:
    """The rotation (ENU) that takes our attitude's slow tilt to the accelerometers': what of
    the direction of ``up`` in body axes lies below :data:`SLOW_TILT_HZ`, ours (``nav/odometry``
    at ``time_s``) turned onto the low-passed specific force (m/s², body), the tilt Edson's
    processing takes from the accelerometers."""
    with BagReader(processed) as reader:
        rows = []
        for message in reader.messages([NAV_ODOMETRY_TOPIC]):
            decoded = reader.decode(message)
            stamp, q = decoded.header.stamp, decoded.pose.pose.orientation
            rows.append((stamp.sec + stamp.nanosec * 1e-9, q.x, q.y, q.z, q.w))
    rows = np.array(rows)
    nearest = np.clip(np.searchsorted(rows[:, 0], time_s), 0, len(rows) - 1)
    attitude = Rotation.from_quat(rows[nearest, 1:])
    ours = below(SLOW_TILT_HZ, attitude.inv().apply((0.0, 0.0, 1.0)))
    measured = below(SLOW_TILT_HZ, specific_force_body)
    ours /= np.linalg.norm(ours, axis=1, keepdims=True)
    measured /= np.linalg.norm(measured, axis=1, keepdims=True)
    return Rotation.from_rotvec(attitude.apply(np.cross(measured, ours)))


def direction_difference(ours_enu: np.ndarray, his_enu: np.ndarray) -> dict:
    """Mean and standard deviation (°) of our horizontal wind direction less his, and of its
    part below :data:`SLOW_TILT_HZ`."""
    difference = np.degrees(
        np.angle((ours_enu[:, 0] + 1j * ours_enu[:, 1]) / (his_enu[:, 0] + 1j * his_enu[:, 1]))
    )
    valid = np.isfinite(difference)
    slow = below(SLOW_TILT_HZ, np.where(valid, difference, 0.0))[valid]
    return {
        "mean": round(float(difference[valid].mean()), 1),
        "std": round(float(difference[valid].std()), 1),
        "slow_std": round(float(slow.std()), 1),
    }


def wind_statistics(wind_enu: np.ndarray) -> dict:
    return {
        "mean_enu_mps": np.nanmean(wind_enu, axis=0).round(3).tolist(),
        "std_enu_mps": np.nanstd(wind_enu, axis=0).round(3).tolist(),
        "mean_horizontal_speed_mps": round(float(np.nanmean(np.hypot(*wind_enu[:, :2].T))), 3),
    }


def flux_figures(time_s, wind, temperature) -> dict:
    window = window_fluxes(time_s, wind, temperature)
    return {k: v for k, v in asdict(window).items() if k not in ("window_start_s", "window_end_s")}


def compare(record: Path, ion_functions: str | None, extra_parameter_files=()) -> dict:
    """Our processing of ``record`` beside Edson's (when ion-functions is at hand); the figures
    of fdchp.json, the wave-band figure drawn."""
    processed = process_record(record, OUT_DIR / "fdchp", extra_parameter_files)
    kept = kept_series(processed)
    result = {
        "record": str(record),
        "flux_windows_motion_left": flux_windows_motion_left(processed),
        "samples": int(kept["time_s"].size),
        "invalid_corrected_samples": int(np.count_nonzero(~np.isfinite(kept["corrected"][:, 2]))),
        "ours": our_figures(kept),
        # The figures reward a correction that applies less of the platform velocity than the
        # sensors say, on a record whose corrected w keeps some of it in phase.
        "ours_platform_velocity_under_applied": under_applied_sweep(kept),
        "ours_platform_velocity_high_passed": variant_figures(kept, kept["high_passed"]),
        "ours_high_passed_and_slow_tilt_from_accelerometers": variant_figures(
            kept, kept["as_edson"]
        ),
        "edson_published_fluxes": dict(
            zip(("u_w_m2_s2", "v_w_m2_s2", "w_ts_k_mps"), edson_fdchp.PUBLISHED_FLUXES, strict=True)
        ),
    }
    vertical_winds = {"uncorrected": kept["uncorrected_w"]}
    try:
        module = edson_fdchp.load_reference(edson_fdchp.ion_functions_dir(ion_functions))
    except edson_fdchp.ReferenceUnavailableError as error:
        result["edson"] = {"unavailable": str(error)}
    else:
        run = edson_fdchp.run_reference(edson_fdchp.load_record(record), module)
        edson_fdchp.check_published_fluxes(run)
        edson_wind = run.wind_nwu_mps @ ENU_FROM_NWU.T
        result["edson"] = edson_figures(kept, edson_wind, run.fluxes)
        vertical_winds["Edson"] = edson_wind[:, 2]
    vertical_winds["ours"] = kept["corrected"][:, 2]
    fdchp_figures.draw_wave_band(
        FIGURE,
        vertical_winds,
        kept["acceleration"],
        kept["platform_up"],
        kept["motion"].band_hz,
        RATE_HZ,
    )
    return result


def flux_windows_motion_left(processed: Path) -> list[dict]:
    """The wave motion left of each flux window as ``process_bag`` published it."""
    with BagReader(processed) as reader:
        windows = published_fluxes(reader)
    names = ("window_start_s", "window_end_s", "n_valid", "n_invalid", "wave_band_low_hz")
    names += ("wave_band_high_hz", "motion_left_coherence", "motion_left_coherence_threshold")
    names += ("motion_left_share",)
    names += ("motion_left_flag", "quality_flag")
    return [{name: getattr(window, name) for name in names} for window in windows]


def kept_series(processed: Path) -> dict:
    """Over the samples Edson keeps (:data:`KEPT`): time (s), our uncorrected vertical wind and
    corrected wind (E, N, U; m/s), the vertical acceleration (m/s²), the sonic temperature
    (°C), the platform's vertical velocity (m/s), our wind as Edson's processing would make it
    (``high_passed``, ``as_edson``) and our wave-band motion figures (``motion``); and the
    platform velocity (``velocity``; E, N, U, m/s) over every sample."""
    ours = read_processed(processed)
    uncorrected_w = ours["measured"][KEPT, 2]
    acceleration = vertical_acceleration_mps2(ours["specific_force"])[KEPT]
    corrected = ours["corrected"][KEPT]
    velocity = platform_velocity_enu(processed, ours["time_s"])
    # Our wind with the platform velocity high-passed as Edson's is: the slow part taken out.
    slow_velocity = below(EDSON_HIGH_PASS_HZ, velocity)
    # And with the slow tilt taken from the accelerometers too: the air relative to the buoy
    # turned by the tilt difference.
    tilt = slow_tilt_from_accelerometers(processed, ours["time_s"], ours["specific_force"])
    return {
        "time_s": ours["time_s"][KEPT],
        "uncorrected_w": uncorrected_w,
        "acceleration": acceleration,
        "temperature": ours["temperature_degc"][KEPT],
        "corrected": corrected,
        "velocity": velocity,
        "platform_up": velocity[KEPT, 2],
        "high_passed": (ours["corrected"] - slow_velocity)[KEPT],
        "as_edson": (tilt.apply(ours["corrected"] - velocity) + velocity - slow_velocity)[KEPT],
        "motion": motion_residual(uncorrected_w, corrected[:, 2], acceleration, RATE_HZ),
    }


def our_figures(kept: dict) -> dict:
    """Wave-band motion, wind statistics, fluxes and their split by band of our corrected wind,
    with the slow part of the platform velocity and what of it is left in the vertical wind."""
    t, corrected, temperature = kept["time_s"], kept["corrected"], kept["temperature"]
    return {
        "motion": asdict(kept["motion"]),
        "wind": wind_statistics(corrected),
        "fluxes": flux_figures(t, corrected, temperature),
        "flux_bands": band_split(t, corrected, temperature),
        "slow_platform_velocity_std_enu_mps": below(SLOW_HZ, kept["velocity"])[KEPT]
        .std(axis=0)
        .round(3)
        .tolist(),
        "platform_velocity_left": _parts(
            platform_velocity_left(
                corrected[:, 2], kept["platform_up"], RATE_HZ, kept["motion"].band_hz
            )
        ),
    }


def under_applied_sweep(kept: dict) -> dict:
    """Wave-band motion figures of our vertical wind with only a share of the platform
    velocity applied, per share of :data:`UNDER_APPLIED_GAINS`."""
    return {
        f"{gain:g}": asdict(
            motion_residual(
                kept["uncorrected_w"],
                kept["corrected"][:, 2] - (1.0 - gain) * kept["platform_up"],
                kept["acceleration"],
                RATE_HZ,
                kept["motion"].band_hz,
            )
        )
        for gain in UNDER_APPLIED_GAINS
    }


def variant_figures(kept: dict, wind_enu: np.ndarray) -> dict:
    """Wave-band motion, fluxes and their split by band of a variant of our wind (E, N, U;
    m/s), its wave band found afresh."""
    return {
        "motion": asdict(
            motion_residual(kept["uncorrected_w"], wind_enu[:, 2], kept["acceleration"], RATE_HZ)
        ),
        "fluxes": flux_figures(kept["time_s"], wind_enu, kept["temperature"]),
        "flux_bands": band_split(kept["time_s"], wind_enu, kept["temperature"]),
    }


def edson_figures(kept: dict, edson_wind: np.ndarray, edson_fluxes) -> dict:
    """The figures of Edson's corrected wind (E, N, U; m/s) and fluxes beside ours."""
    t, temperature, band = kept["time_s"], kept["temperature"], kept["motion"].band_hz
    return {
        "motion": asdict(
            motion_residual(
                kept["uncorrected_w"], edson_wind[:, 2], kept["acceleration"], RATE_HZ, band
            )
        ),
        "wind": wind_statistics(edson_wind),
        "platform_velocity_left": _parts(
            platform_velocity_left(edson_wind[:, 2], kept["platform_up"], RATE_HZ, band)
        ),
        "fluxes": dict(zip(("u_w_m2_s2", "v_w_m2_s2", "w_ts_k_mps"), edson_fluxes, strict=True)),
        "our_flux_core_on_his_wind": flux_figures(t, edson_wind, temperature),
        "flux_bands": band_split(t, edson_wind, temperature),
        # His horizontal wind with our vertical (platform velocity high-passed, slow tilt from
        # the accelerometers, as his): what the horizontal wind alone makes of the difference.
        "fluxes_his_horizontal_our_vertical": flux_figures(
            t, np.column_stack((edson_wind[:, :2], kept["as_edson"][:, 2])), temperature
        ),
        "direction_difference_deg": direction_difference(kept["as_edson"], edson_wind),
    }


def _parts(left: complex) -> dict:
    return {"in_phase": left.real, "quadrature": left.imag}


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:>12.4f}"
    if isinstance(value, list):
        return f"{' '.join(f'{v:6.2f}' for v in value):>22}"
    return f"{value!s:>12}"


def _row(label: str, *values) -> str:
    return f"{label:36s}" + "".join(_cell(v) for v in values)


def print_comparison(result: dict) -> None:
    ours, edson = result["ours"], result.get("edson", {})
    low, high = ours["motion"]["band_hz"]
    print(
        f"\nReal record: OOI FDCHP, {result['samples']} samples at 10 Hz (those Edson keeps), "
        f"wave band {low:.3f}-{high:.3f} Hz, {result['invalid_corrected_samples']} of ours invalid"
    )
    if "unavailable" in edson:
        print(f"  Edson's processing not run: {edson['unavailable']}")
        edson = {}
    print_wave_band(ours, edson, result["ours_platform_velocity_under_applied"])
    print_flux_windows_motion_left(result["flux_windows_motion_left"])
    print_wind_and_fluxes(ours, edson, result["edson_published_fluxes"])
    print_flux_bands(ours, edson)
    print_high_passed_variants(ours, result)
    print_his_wind_with_ours(edson)


def print_wave_band(ours: dict, edson: dict, under_applied: dict) -> None:
    """The wave-band variance and coherence of the vertical wind, and the platform velocity
    left in it, uncorrected, Edson's and ours; and ours with a share of the platform velocity."""
    motion, theirs = ours["motion"], edson.get("motion", {})
    print(_row("", "uncorrected", "Edson", "ours"))
    print(
        _row(
            "wave-band variance of w, share",
            1.0,
            theirs.get("variance_share", "-"),
            motion["variance_share"],
        )
    )
    print(
        _row(
            "coherence of w with heave accel.",
            motion["coherence_before"],
            theirs.get("coherence_after", "-"),
            motion["coherence_after"],
        )
    )
    print(
        _row(
            "platform w left, in phase",
            "-",
            edson.get("platform_velocity_left", {}).get("in_phase", "-"),
            ours["platform_velocity_left"]["in_phase"],
        )
    )
    print(
        _row(
            "  and a quarter period out",
            "-",
            edson.get("platform_velocity_left", {}).get("quadrature", "-"),
            ours["platform_velocity_left"]["quadrature"],
        )
    )
    sweep = ", ".join(
        f"{gain}: {m['variance_share']:.3f} / {m['coherence_after']:.3f}"
        for gain, m in under_applied.items()
    )
    print(f"  ours with a share of the platform velocity applied (share / coherence): {sweep}")


def print_flux_windows_motion_left(windows: list[dict]) -> None:
    """Each published flux window's wave band, coherence, share left and flag."""
    for window in windows:
        length_s = window["window_end_s"] - window["window_start_s"]
        print(
            f"  flux window of {length_s:g} s ({window['n_valid']} valid, {window['n_invalid']} "
            f"invalid samples): wave band {window['wave_band_low_hz']:.3f}-"
            f"{window['wave_band_high_hz']:.3f} Hz, coherence {window['motion_left_coherence']:.3f}"
            f" (counts above {window['motion_left_coherence_threshold']:.3f}), platform w left "
            f"{window['motion_left_share']:.3f}, motion left flag "
            f"{window['motion_left_flag']} (window flag {window['quality_flag']})"
        )


def print_wind_and_fluxes(ours: dict, edson: dict, published: dict) -> None:
    """Mean and spread of the wind, Edson's and ours; the fluxes published, of Edson's run and
    ours, with our flux QC."""
    for key, label in (("mean_enu_mps", "mean E, N, U, m/s"), ("std_enu_mps", "std E, N, U, m/s")):
        print(_row(label, "Edson", edson.get("wind", {}).get(key, "-")))
        print(_row("", "ours", ours["wind"][key]))
    print(_row("", "published", "Edson (run)", "ours"))
    for key, label in (
        ("u_w_m2_s2", "u'w', m2/s2"),
        ("v_w_m2_s2", "v'w', m2/s2"),
        ("w_ts_k_mps", "w'Ts', K m/s"),
    ):
        mine = ours["fluxes"][key]
        print(_row(label, published[key], edson.get("fluxes", {}).get(key, "-"), mine))
    f = ours["fluxes"]
    print(
        f"  ours: u* {f['friction_velocity_mps']:.3f} m/s, stress {f['stress_n_m2']:.3f} N/m2 "
        f"(air density {f['air_density_kg_m3']:.3f} kg/m3), tilt {f['tilt_deg']:.2f} deg, "
        f"spikes u, v, w, Ts {f['spikes']}, stationarity u'w' "
        f"{f['stationarity_u_w_percent']:.0f} %, w'Ts' {f['stationarity_w_ts_percent']:.0f} %"
    )


def print_flux_bands(ours: dict, edson: dict) -> None:
    bands = ", ".join(f"{lo:g}-{hi:g}" for lo, hi in BANDS_HZ)
    print(f"  by band ({bands} Hz):")
    for key in ("u_w", "v_w", "w_ts", "w_w"):
        print(f"    {key:5s} ours  {ours['flux_bands'][key]}")
        if "flux_bands" in edson:
            print(f"    {key:5s} Edson {edson['flux_bands'][key]}")


def print_high_passed_variants(ours: dict, result: dict) -> None:
    """Our slow platform velocity, and our fluxes and wave band with the platform velocity
    high-passed and the slow tilt taken from the accelerometers, as Edson's processing does."""
    print(
        f"  our platform velocity below {SLOW_HZ} Hz, std E, N, U: "
        f"{ours['slow_platform_velocity_std_enu_mps']} m/s"
    )
    for key, label in (
        (
            "ours_platform_velocity_high_passed",
            f"platform velocity high-passed at {EDSON_HIGH_PASS_HZ:.3f} Hz",
        ),
        (
            "ours_high_passed_and_slow_tilt_from_accelerometers",
            f"the same and the tilt below {SLOW_TILT_HZ:.3f} Hz from the accelerometers",
        ),
    ):
        variant = result[key]
        f, m = variant["fluxes"], variant["motion"]
        print(
            f"  ours, {label}: u'w' {f['u_w_m2_s2']:.4f}, v'w' {f['v_w_m2_s2']:.4f}, "
            f"w'Ts' {f['w_ts_k_mps']:.5f}, stationarity u'w' {f['stationarity_u_w_percent']:.0f} %;"
            f" wave band: share {m['variance_share']:.4f}, coherence {m['coherence_after']:.4f}"
        )
        for band_key in ("u_w", "w_w"):
            print(f"    {band_key:5s} {variant['flux_bands'][band_key]}")


def print_his_wind_with_ours(edson: dict) -> None:
    """Fluxes of Edson's horizontal wind with our vertical, the difference of the wind
    directions, and our flux core on his corrected wind (when his processing ran)."""
    if "fluxes_his_horizontal_our_vertical" in edson:
        f = edson["fluxes_his_horizontal_our_vertical"]
        d = edson["direction_difference_deg"]
        print(
            f"  his horizontal wind with our vertical (the variant above): u'w' "
            f"{f['u_w_m2_s2']:.4f}, v'w' {f['v_w_m2_s2']:.4f}, w'Ts' {f['w_ts_k_mps']:.5f}; our "
            f"wind direction less his: mean {d['mean']} deg, std {d['std']} deg (below "
            f"{SLOW_TILT_HZ:.3f} Hz {d['slow_std']} deg)"
        )
    if "our_flux_core_on_his_wind" in edson:
        core = edson["our_flux_core_on_his_wind"]
        print(
            f"  wind_comp.fluxes on Edson's corrected wind: u'w' {core['u_w_m2_s2']:.5f}, "
            f"v'w' {core['v_w_m2_s2']:.5f}, w'Ts' {core['w_ts_k_mps']:.5f}; tilt "
            f"{core['tilt_deg']:.2f} deg, stationarity u'w' "
            f"{core['stationarity_u_w_percent']:.0f} %, w'Ts' "
            f"{core['stationarity_w_ts_percent']:.0f} %"
        )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="bench_fdchp", description=__doc__.split("\n")[0])
    parser.add_argument("--record", default=str(RECORD), help="fdchp_test_dp.dat")
    parser.add_argument("--ion-functions", help="checkout of oceanobservatories/ion-functions")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML applied after ooi_fdchp_params.yaml (repeatable): our processing "
        "with other parameters",
    )
    arguments = parser.parse_args(argv)
    record = Path(arguments.record)
    if not record.is_file():
        print(f"bench_fdchp: no record at {record} (set FDCHP_RECORD)", file=sys.stderr)
        sys.exit(2)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    result = compare(record, arguments.ion_functions, arguments.params_file)
    print_comparison(result)
    (OUT_DIR / "fdchp.json").write_text(json.dumps(result, indent=2, default=float))


if __name__ == "__main__":
    main()
