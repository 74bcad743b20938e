"""Edson's processing and ours on simulated FDCHP records, both held to the simulator's truth.

The real record has no truth: its figures (wave-band share, coherence with the heave) rank two
corrections only as far as its sensors are sound. Here the simulator plays an FDCHP: the sonic
0.753 m straight above a motion pack, every sensor at 10 Hz, no GNSS, the pack's AHRS heading to
magnetic north, the buoy on its mooring (``moored_motion_pack``). Each sea is simulated and
written in the FDCHP L0 layout (13 columns, as ``fdchp_test_dp.dat``). Edson's processing reads
that file (when a checkout of ion-functions is at hand, see ``edson_fdchp.py``); so do we, through
the shipped column map (``import_records``) and our motion-pack set (``process_bag``). For each
correction it prints:

- the error of the corrected vertical wind against ``truth/wind``: RMS, mean, and its variance
  within the wave band;
- the real record's figures (share, coherence), with the truth's own figures as their floor;
- the platform velocity the correction leaves in the vertical wind, in phase and a quarter period
  out of it (``wind_comp.motion_residual.platform_velocity_left``).

    python -m tools.fdchp_simulated [--ion-functions DIR]

Results go to out/bench/fdchp_simulated.json, the error spectra to out/bench/fdchp_simulated.png.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    AHRS_TOPIC,
    IMU_RAW_TOPIC,
    NAV_VELOCITY_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    stamp_to_ns,
)
from buoy_common.records.column_map import STANDARD_GRAVITY_MPS2
from buoy_processing.report.data import stamped_vectors
from sensor_sim import simulate_bag
from tools import bench_fdchp, edson_fdchp, fdchp_figures
from wind_comp.motion_residual import (
    band_variance,
    motion_residual,
    platform_velocity_left,
    vertical_acceleration_mps2,
)

REPO = Path(__file__).resolve().parent.parent
OUT_DIR = REPO / "out/bench"
FIGURE = OUT_DIR / "fdchp_simulated.png"
PARAMS = REPO / "tools/fdchp_simulated_params.yaml"
"""The FDCHP's geometry and rates for the simulator and our motion-pack set for the fusion."""
BUOY_PARAMS = REPO / "src/buoy_common/config/buoy.yaml"
RATE_HZ = 10.0
SETTLE_ROWS = 300
"""Rows simulated before the record starts: our alignment and Edson's filters settle in them."""
PACKET_ROWS = 12000
"""Edson's processing takes 12 000 rows (20 min) and keeps all but 30 s at each end."""
SPEED_OF_SOUND_CMPS = np.sqrt(403.0 * (20.0 + 273.15)) * 100.0
"""A 20 °C sonic temperature: the simulated sonic reports none, and only w'Ts' would use it."""
FRD_FROM_FLU = np.array([1.0, -1.0, -1.0])
FLU_FROM_FRD = np.diag(FRD_FROM_FLU)
NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
ENU_FROM_NWU = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
OPEN_OCEAN_MOORED_WITH_MOTION_PACK = [
    "sensors.gnss.receiver=none",
    "sensors.ahrs.fitted=true",
    "sensors.ahrs.yaw_reference=magnetic_north",
    "current=null",
]
SEAS = {
    "sway_6_to_9_s": ("moored_motion_pack", (35.0, 120.0), []),
    "jonswap_tp_9_s": ("open_ocean", (20.0, 115.0), OPEN_OCEAN_MOORED_WITH_MOTION_PACK),
    "jonswap_tp_2_s": (
        "open_ocean",
        (20.0, 115.0),
        [
            *OPEN_OCEAN_MOORED_WITH_MOTION_PACK,
            "waves.peak_period_s=2.0",
            "waves.significant_height_m=0.3",
            "waves.max_tilt_deg=10.0",
        ],
    ),
}
"""Scenario, site (latitude, longitude; deg) and overrides of each sea: ``moored_motion_pack``'s
paper-002 sway; ``open_ocean``'s JONSWAP sea (Hs 3 m, Tp 9 s) with a motion pack on its mooring;
and a short JONSWAP sea (Hs 0.3 m, Tp 2 s) whose heave lies in the real record's wave band
(0.42–0.82 Hz)."""


def site_params(work: Path, site_deg: tuple[float, float]) -> Path:
    """A parameter file that gives the fusion the mooring's place (no GNSS fix tells it)."""
    path = work / "site.yaml"
    latitude, longitude = site_deg
    path.write_text(
        "/**:\n  ros__parameters:\n    site:\n"
        f"      latitude_deg: {latitude}\n      longitude_deg: {longitude}\n"
    )
    return path


def simulate(
    bag: Path, scenario: str, overrides: list[str], rows: int = SETTLE_ROWS + PACKET_ROWS
) -> None:
    """Simulate ``rows`` samples of the FDCHP's 10 Hz sensors of ``scenario`` into ``bag``."""
    duration_s = rows / RATE_HZ
    arguments = [scenario, str(bag), "--set", f"duration_s={duration_s}"]
    for override in overrides:
        arguments += ["--set", override]
    arguments += ["--params-file", str(BUOY_PARAMS), "--params-file", str(PARAMS), "--overwrite"]
    with contextlib.redirect_stdout(io.StringIO()):
        simulate_bag.main(arguments)


def fdchp_record(bag: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The simulated bag as FDCHP L0 rows, their stamps (ns), and the true vertical wind (m/s)
    at them. Sonic u, v, w (cm/s, FLU) and speed of sound; the IMU sample of the same stamp in
    FRD (rad/s; specific force in g, the standard gravity the column map's unit ``g`` means;
    Edson's processing multiplies it by the normal gravity at 38.5°, 0.06 % less); the AHRS
    attitude interpolated to the row as roll, pitch and heading (rad; FRD in North-East-Down,
    heading clockwise from magnetic north)."""
    with BagReader(bag) as reader:
        sonic = stamped_vectors(reader, WIND_RAW_TOPIC)
        truth = stamped_vectors(reader, TRUTH_WIND_TOPIC)
        imu_stamps, rate, force = [], [], []
        for message in reader.messages([IMU_RAW_TOPIC]):
            sample = reader.decode(message)
            imu_stamps.append(stamp_to_ns(sample.header.stamp))
            w, f = sample.angular_velocity, sample.linear_acceleration
            rate.append((w.x, w.y, w.z))
            force.append((f.x, f.y, f.z))
        ahrs_stamps, quaternion = [], []
        for message in reader.messages([AHRS_TOPIC]):
            sample = reader.decode(message)
            ahrs_stamps.append(stamp_to_ns(sample.header.stamp))
            q = sample.orientation
            quaternion.append((q.x, q.y, q.z, q.w))
    stamps = sonic.stamps_ns
    index = np.searchsorted(imu_stamps, stamps)
    if index.max() >= len(imu_stamps) or np.any(np.asarray(imu_stamps)[index] != stamps):
        raise RuntimeError(f"{bag}: the IMU and the sonic are not sampled at the same stamps")
    inside = (stamps >= ahrs_stamps[0]) & (stamps <= ahrs_stamps[-1])
    if not inside.all():
        raise RuntimeError(f"{bag}: sonic samples before the first or after the last AHRS sample")
    body_to_enu = Slerp(np.asarray(ahrs_stamps, dtype=float), Rotation.from_quat(quaternion))(
        stamps.astype(float)
    )
    # NED from ENU swaps the first two axes and turns up into down; FRD from FLU turns y and z.
    frd_to_ned = (
        Rotation.from_matrix(NED_FROM_ENU) * body_to_enu * Rotation.from_matrix(FLU_FROM_FRD)
    )
    heading, pitch, roll = frd_to_ned.as_euler("ZYX").T
    record = np.column_stack(
        [
            sonic.vectors * 100.0,
            np.full(stamps.size, SPEED_OF_SOUND_CMPS),
            np.asarray(rate)[index] * FRD_FROM_FLU,
            np.asarray(force)[index] * FRD_FROM_FLU / STANDARD_GRAVITY_MPS2,
            roll,
            pitch,
            np.mod(heading, 2.0 * np.pi),
        ]
    )
    true_w = np.interp(stamps, truth.stamps_ns, truth.vectors[:, 2])
    return record, stamps, true_w


def ours_on(record_file: Path, work: Path, site: Path) -> tuple[np.ndarray, np.ndarray]:
    """Our corrected vertical wind and platform vertical velocity (m/s) at the record's rows."""
    processed = bench_fdchp.import_and_process(record_file, work, [BUOY_PARAMS, PARAMS, site])
    with BagReader(processed) as reader:
        corrected = stamped_vectors(reader, WIND_TRUE_TOPIC)
        velocity = []
        for message in reader.messages([NAV_VELOCITY_TOPIC]):
            sample = reader.decode(message)
            velocity.append((stamp_to_ns(sample.header.stamp), sample.twist.twist.linear.z))
    velocity = np.array(velocity)
    up = np.interp(corrected.stamps_ns, velocity[:, 0], velocity[:, 1])
    return corrected.vectors[:, 2], up


def figures(name, corrected_w, true_w, uncorrected_w, heave, platform_up, band=None) -> dict:
    residual = motion_residual(uncorrected_w, corrected_w, heave, RATE_HZ, band)
    error = corrected_w - true_w
    left = platform_velocity_left(corrected_w, platform_up, RATE_HZ, residual.band_hz)
    return {
        "correction": name,
        "band_hz": list(residual.band_hz),
        "variance_share": residual.variance_share,
        "coherence_after": residual.coherence_after,
        "error_rms_mps": float(np.sqrt(np.nanmean(error**2))),
        "error_mean_mps": float(np.nanmean(error)),
        "error_wave_band_variance_m2_s2": band_variance(error, RATE_HZ, residual.band_hz),
        "uncorrected_wave_band_variance_m2_s2": band_variance(
            uncorrected_w, RATE_HZ, residual.band_hz
        ),
        "platform_velocity_left_in_phase": left.real,
        "platform_velocity_left_quadrature": left.imag,
    }


def compare_sea(sea: str, module, work: Path) -> tuple[list[dict], dict]:
    """The truth's, Edson's (unless ``module`` is None) and our figures on one simulated sea,
    and the series of the figure: the wave band, the uncorrected w and each error of w (m/s)."""
    scenario, site_deg, overrides = SEAS[sea]
    bag = work / "simulated"
    simulate(bag, scenario, overrides)
    rows, _, true_w = fdchp_record(bag)
    rows, true_w = rows[SETTLE_ROWS:], true_w[SETTLE_ROWS:]
    record_file = work / "fdchp_simulated.dat"
    np.savetxt(record_file, rows, delimiter=",", fmt="%.10g")
    kept = slice(int(edson_fdchp.EDGE_S * RATE_HZ), PACKET_ROWS - int(edson_fdchp.EDGE_S * RATE_HZ))
    ours_w, platform_up = ours_on(record_file, work, site_params(work, site_deg))
    corrected = {"ours": ours_w[kept]}
    if module is not None:
        run = edson_fdchp.run_reference(edson_fdchp.load_record(record_file), module)
        corrected["Edson"] = (run.wind_nwu_mps @ ENU_FROM_NWU.T)[:, 2]
    platform_up, true_w = platform_up[kept], true_w[kept]
    uncorrected = rows[kept, 2] / 100.0
    heave = vertical_acceleration_mps2(rows[kept, 7:10] * STANDARD_GRAVITY_MPS2)
    truth = figures("truth", true_w, true_w, uncorrected, heave, platform_up)
    band = tuple(truth["band_hz"])
    entries = [truth] + [
        figures(label, corrected[label], true_w, uncorrected, heave, platform_up, band)
        for label in ("Edson", "ours")
        if label in corrected
    ]
    series = {"band_hz": band, "uncorrected": uncorrected}
    series |= {label: w - true_w for label, w in corrected.items()}
    return [{"sea": sea, **entry} for entry in entries], series


def print_table(rows: list[dict]) -> None:
    print(
        "\nSimulated FDCHP records (sonic 0.753 m above the motion pack, 10 Hz, no GNSS), 20 min:"
    )
    print(
        f"{'sea':26s}{'correction':>11s}{'band Hz':>13s}{'share':>8s}{'coher.':>8s}"
        f"{'err RMS':>9s}{'err mean':>9s}{'err var band':>13s}{'left in ph.':>12s}{'quadr.':>8s}"
    )
    for row in rows:
        low, high = row["band_hz"]
        print(
            f"{row['sea']:26s}{row['correction']:>11s}{f'{low:.2f}-{high:.2f}':>13s}"
            f"{row['variance_share']:8.4f}{row['coherence_after']:8.3f}"
            f"{row['error_rms_mps']:9.4f}{row['error_mean_mps']:9.4f}"
            f"{row['error_wave_band_variance_m2_s2']:13.2e}"
            f"{row['platform_velocity_left_in_phase']:12.3f}"
            f"{row['platform_velocity_left_quadrature']:8.3f}"
        )
    print(
        "  err: corrected vertical wind less truth/wind, m/s (variance m2/s2); the truth's share "
        "and coherence are the floor a perfect correction reaches"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="fdchp_simulated", description=__doc__.split("\n")[0])
    parser.add_argument("--ion-functions", help="checkout of oceanobservatories/ion-functions")
    arguments = parser.parse_args(argv)
    try:
        module = edson_fdchp.load_reference(edson_fdchp.ion_functions_dir(arguments.ion_functions))
    except edson_fdchp.ReferenceUnavailableError as error:
        print(f"fdchp_simulated: Edson's processing not run: {error}", file=sys.stderr)
        module = None
    work = OUT_DIR / "fdchp_simulated"
    work.mkdir(parents=True, exist_ok=True)
    rows, series = [], {}
    for sea in SEAS:
        print(f"fdchp_simulated: {sea} ...", file=sys.stderr, flush=True)
        figures_of_sea, series[sea] = compare_sea(sea, module, work)
        rows += figures_of_sea
    print_table(rows)
    fdchp_figures.draw_simulated_errors(FIGURE, series, RATE_HZ)
    (OUT_DIR / "fdchp_simulated.json").write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
