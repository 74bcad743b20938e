"""Is every corrected wind sample's stated uncertainty honest, on every sensor set?

    python -m tools.bench_uncertainty [--quick] [--only CASE ...] [--duration-s S]

Each case simulates a scenario (``simulate_bag``) with the sensors of one set and their
imperfections, processes it (``process_bag``) with the set's parameters, and holds every valid
sample of ``wind/true_with_covariance`` against the bag's truth: the share of samples whose error
exceeds three of their standard deviations and the number beyond five, per ENU axis; the share
of samples valid; the fused roll and pitch error beside the motion pack's own (the best other
attitude source present); and the sources the fusion suspended. The contract's promise is at
most about 1 % beyond 3σ and none beyond 5σ. Prints a table and writes
out/bench/uncertainty.json.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
from array import array
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from buoy_common import cdr
from buoy_common.bag_io import BagError, BagReader
from buoy_common.contract import (
    AHRS_TOPIC,
    NANOSECONDS_PER_SECOND,
    NAV_ODOMETRY_TOPIC,
    TRUTH_MSGTYPES,
    TRUTH_ODOMETRY_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_TRUE_WITH_COVARIANCE_TOPIC,
    stamp_to_ns,
)
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from sensor_sim.scenario import load_scenario
from sensor_sim.simulate_bag import parse_arguments as simulate_arguments
from sensor_sim.simulate_bag import simulate
from tools.bench_plan import PROCESSING_PARAMS, REPO, SIMULATION_PARAMS
from tools.fdchp_simulated import PARAMS as FDCHP_PARAMS
from tools.fdchp_simulated import SEAS
from wind_comp.config import compensator_config_from_files

OUT = REPO / "out" / "bench"
WORK = OUT / "uncertainty"
ATTITUDE_SETTLING_S = 120.0
"""The fused and the motion pack's attitude are compared after this much of a run: the alignment
and the first convergence are behind. The wind is judged from its first sample: a sample the
suite calls valid while it converges owes its σ as much as any other."""
STAMP_MATCH_NS = 1000
_TRUTH_WIND_MSGTYPE = TRUTH_MSGTYPES[TRUTH_WIND_TOPIC]
MOORED = "fusion.moored: true"
HARD_IRON_T = (18e-6, -27.5e-6, 12e-6)
SOFT_IRON = (1.08, 0.05, -0.03, 0.05, 0.93, 0.07, -0.03, 0.07, 1.02)
"""The uncalibrated magnetometer of the imperfect scenarios."""
CALIBRATED = (
    f"fusion.magnetometer_hard_iron_t: {list(HARD_IRON_T)}",
    "fusion.magnetometer_soft_iron: "
    f"{np.linalg.inv(np.reshape(SOFT_IRON, (3, 3))).ravel().round(12).tolist()}",
)
"""That magnetometer calibrated: what calibrate_magnetometer estimates from a turning run."""


@dataclass(frozen=True)
class Case:
    """One sensor set on one scenario: simulation overrides and fusion parameter lines."""

    scenario: str
    description: str
    overrides: tuple[str, ...] = ()
    fusion_lines: tuple[str, ...] = ()
    buoy_params: tuple[str, ...] = ()
    """Parameter files of the buoy after the shipped ones, for the simulator and the fusion
    alike (the simulated FDCHP's geometry and rates)."""


GYRO_BIAS_INSTABILITY_DEG_H = 150.0
"""How much the FDCHP-like buoy's gyro wanders (the fusion is told its default, 5 °/h)."""
GYRO_BIAS_CORRELATION_TIME_S = 100.0
SIGNIFICANT_WAVE_HEIGHT_M = 0.3
"""The short sea of the OOI record."""
FDCHP_LIKE_MOORED_BUOY = (
    "sensors.gnss.receiver=none",
    "current=null",
    "sensors.magnetometer.fitted=false",
    "sensors.ahrs.fitted=true",
    "sensors.ahrs.yaw_reference=magnetic_north",
    "sensors.ahrs.sample_every=1",
    "sensors.ahrs.error_deg=1.5",
    "sensors.ahrs.claimed_sigma_deg=[1.0, 1.0, 2.0]",
    "sensors.rates.imu_hz=10.0",
    "waves.peak_period_s=2.0",
    f"waves.significant_height_m={SIGNIFICANT_WAVE_HEIGHT_M}",
    "waves.max_tilt_deg=10.0",
    f"sensors.imu.gyro_bias_instability_deg_h={GYRO_BIAS_INSTABILITY_DEG_H}",
    f"sensors.imu.gyro_bias_correlation_time_s={GYRO_BIAS_CORRELATION_TIME_S}",
)
"""An FDCHP-like moored buoy: a motion pack at 10 Hz whose slow attitude is off by 1.5° while it
claims 1°, no magnetometer, no GNSS, the OOI record's short sea, a gyro wandering 30 times
more than the fusion's default model."""


def fdchp_case(sea: str, description: str) -> Case:
    """A simulated FDCHP in one of :data:`tools.fdchp_simulated.SEAS`."""
    scenario, _, overrides = SEAS[sea]
    return Case(scenario, description, tuple(overrides), buoy_params=(str(FDCHP_PARAMS),))


CASES = {
    "a_rtk": Case("sea_state", "(a) dual-antenna RTK, 10 Hz", ("current=null",)),
    "a_imperfect": Case("set_a_imperfect", "(a) dual antenna at 1 Hz, 0.31 s off the IMU grid"),
    "b_imperfect": Case(
        "set_b_imperfect", "(b) one antenna at 1 Hz + uncalibrated magnetometer, drifting"
    ),
    "c_imperfect": Case(
        "set_c_imperfect", "(c) uncalibrated magnetometer, no GNSS, moored", (), (MOORED,)
    ),
    "d_imperfect": Case(
        "set_d_imperfect", "(d) lagging motion pack + magnetometer, no GNSS, moored", (), (MOORED,)
    ),
    "d_not_moored": Case(
        "set_d_imperfect", "(d) as above, fusion.moored false: no velocity reference"
    ),
    "b_calibrated": Case(
        "set_b_imperfect",
        "(b) one antenna + the magnetometer calibrated, drifting",
        (),
        CALIBRATED,
    ),
    "c_calibrated": Case(
        "set_c_imperfect",
        "(c) the magnetometer calibrated, no GNSS, moored",
        (),
        (MOORED, *CALIBRATED),
    ),
    "e_calibrated": Case(
        "set_e_imperfect",
        "(e) as (b) calibrated, through 60 s silent outages",
        (),
        CALIBRATED,
    ),
    "e_imperfect": Case("set_e_imperfect", "(e) as (b) uncalibrated, through 60 s silent outages"),
    "e_moored_wrongly": Case(
        "set_e_imperfect",
        "(e) calibrated, fusion.moored set on this drifting buoy: a wrong constraint",
        (),
        (MOORED, *CALIBRATED),
    ),
    "moored_single_gnss": Case(
        "measured_moored_single_gnss",
        "measured: moored, one antenna at 1 Hz, uncalibrated magnetometer",
        (),
        (MOORED,),
    ),
    "moored_no_gnss": Case(
        "measured_moored_no_gnss",
        "measured: moored, lagging pack, uncalibrated magnetometer, no GNSS",
        (),
        (MOORED,),
    ),
    "measured_not_moored": Case(
        "measured_moored_no_gnss", "measured: as above, fusion.moored false"
    ),
    "fdchp_sway": fdchp_case(
        "sway_6_to_9_s", "simulated FDCHP: sonic 0.753 m above a motion pack, 10 Hz, moored"
    ),
    "fdchp_wandering_gyro": Case(
        "open_ocean",
        "FDCHP-like, a gyro wandering 150 °/h told the default 5 °/h",
        FDCHP_LIKE_MOORED_BUOY,
        (MOORED, "fusion.ahrs_lag_s: 0.2"),
    ),
    "fdchp_short_sea": fdchp_case(
        "jonswap_tp_2_s", "simulated FDCHP in a short sea (Hs 0.3 m, Tp 2 s), as the OOI record's"
    ),
}


def parameter_lines(scenario) -> list[str]:
    """The processing parameters a scenario's buoy implies: its site, the motion pack's yaw
    reference and the sensors' places the scenario gives."""
    lines = [
        f"    site.latitude_deg: {scenario.origin_latitude_deg}",
        f"    site.longitude_deg: {scenario.origin_longitude_deg}",
    ]
    ahrs = scenario.sensors.ahrs
    if ahrs.fitted:
        lines.append(f"    ahrs.yaw_reference: {ahrs.yaw_reference}")
    extrinsics = scenario.sensors.extrinsics
    if extrinsics is not None:
        places = {
            "gnss.primary_antenna": extrinsics.primary_antenna_body_m,
            "gnss.secondary_antenna": extrinsics.secondary_antenna_body_m,
            "anemometer.position": extrinsics.anemometer_position_body_m,
            "anemometer.rpy_deg": extrinsics.anemometer_rpy_deg,
        }
        lines += [f"    {name}: {list(map(float, value))}" for name, value in places.items()]
    return lines


def write_parameters(directory: Path, scenario, case: Case) -> str:
    path = directory / "params.yaml"
    lines = [*parameter_lines(scenario), *(f"    {line}" for line in case.fusion_lines)]
    path.write_text("/**:\n  ros__parameters:\n" + "\n".join(lines) + "\n")
    return str(path)


def run_case(key: str, duration_s: float, work: Path = WORK) -> dict:
    """Simulate, process and judge one case (in a worker), its bags under ``work``/``key``."""
    case = CASES[key]
    directory = work / key
    directory.mkdir(parents=True, exist_ok=True)
    overrides = (*case.overrides, f"duration_s={duration_s}")
    scenario = load_scenario(case.scenario, list(overrides), None)
    in_bag, out_bag = directory / "in", directory / "out"
    arguments = [case.scenario, str(in_bag), "--overwrite"]
    for override in overrides:
        arguments += ["--set", override]
    # A scenario that places the sensors itself is simulated as it says (parameter files would
    # override its places); the others as the shipped buoy, which processing assumes.
    if scenario.sensors.extrinsics is None:
        for params in (*SIMULATION_PARAMS, *case.buoy_params):
            arguments += ["--params-file", params]
    log = io.StringIO()
    with contextlib.redirect_stderr(log), contextlib.redirect_stdout(log):
        simulate(simulate_arguments(arguments))
        params = [
            *PROCESSING_PARAMS,
            *case.buoy_params,
            write_parameters(directory, scenario, case),
        ]
        summary = process_bag(
            str(in_bag),
            str(out_bag),
            fusion_config_from_files(params),
            compensator_config_from_files(params),
            overwrite=True,
        )
    (directory / "process.log").write_text(log.getvalue() + "\n".join(summary.fusion_lines))
    return {
        "description": case.description,
        "duration_s": duration_s,
        "wind": judge_wind(out_bag),
        "attitude": judge_attitude(in_bag, out_bag),
        "suspended": suspensions_in(summary.fusion_lines),
        "aligned": not any("never aligned" in line for line in summary.fusion_lines),
    }


def _vector(v) -> list[float]:
    return [v.x, v.y, v.z]


@dataclass(frozen=True)
class WindErrors:
    """The corrected wind samples of a processed bag against its truth: (N,) stamps (ns) and
    validity of every sample, and for the valid ones with a truth sample of the same stamp their
    stamps, (M, 3) errors (m/s, ENU) and stated standard deviations (m/s)."""

    stamps_ns: np.ndarray
    valid: np.ndarray
    matched_ns: np.ndarray
    error_mps: np.ndarray
    sigma_mps: np.ndarray

    def summary(self, from_ns: int, to_ns: int) -> dict:
        """Shares beyond 3σ, counts beyond 5σ (per ENU axis) and the like over [from, to)."""
        judged = (self.stamps_ns >= from_ns) & (self.stamps_ns < to_ns)
        chosen = (self.matched_ns >= from_ns) & (self.matched_ns < to_ns)
        error, sigma = self.error_mps[chosen], self.sigma_mps[chosen]
        normalised = np.abs(error) / sigma
        empty = not error.size
        return {
            "judged": int(judged.sum()),
            "valid_share": float(self.valid[judged].sum() / max(judged.sum(), 1)),
            "matched": int(chosen.sum()),
            "beyond_3_sigma_share": None if empty else (normalised > 3).mean(axis=0).tolist(),
            "beyond_5_sigma": None if empty else (normalised > 5).sum(axis=0).tolist(),
            "rms_error_mps": None if empty else np.sqrt((error**2).mean(axis=0)).tolist(),
            "max_error_mps": None if empty else np.abs(error).max(axis=0).tolist(),
            "median_sigma_mps": None if empty else np.median(sigma, axis=0).tolist(),
        }


def wind_errors(out_bag: Path) -> WindErrors:
    """:class:`WindErrors` of ``wind/true_with_covariance`` in ``out_bag``.

    One pass over the bag into flat arrays, the truth's vectors (a simulated day holds millions)
    read by the fast CDR reader: a day is judged in a minute or two and a few hundred MiB."""
    wind_ns, wind_values, wind_variances = array("q"), array("d"), array("d")
    truth_ns, truth_values = array("q"), array("d")
    with BagReader(out_bag) as reader:
        for record in reader.messages([WIND_TRUE_WITH_COVARIANCE_TOPIC, TRUTH_WIND_TOPIC]):
            if record.msgtype == _TRUTH_WIND_MSGTYPE:
                stamp_ns, vector = _stamped_vector(reader, record)
                truth_ns.append(stamp_ns)
                truth_values.extend(vector)
                continue
            message = reader.decode(record)
            wind_ns.append(stamp_to_ns(message.header.stamp))
            wind_values.extend(_vector(message.twist.twist.linear))
            wind_variances.extend(message.twist.covariance[[0, 7, 14]].tolist())
    stamps = np.frombuffer(wind_ns, dtype=np.int64)
    values = np.frombuffer(wind_values).reshape(-1, 3)
    variances = np.frombuffer(wind_variances).reshape(-1, 3)
    truth_stamps = np.frombuffer(truth_ns, dtype=np.int64)
    truth_vectors = np.frombuffer(truth_values).reshape(-1, 3)
    valid = np.all(np.isfinite(values), axis=1)
    nearest = np.clip(np.searchsorted(truth_stamps, stamps), 0, truth_stamps.size - 1)
    matched = valid & (np.abs(truth_stamps[nearest] - stamps) < STAMP_MATCH_NS)
    return WindErrors(
        stamps,
        valid,
        stamps[matched],
        values[matched] - truth_vectors[nearest[matched]],
        np.sqrt(variances[matched]),
    )


def _stamped_vector(reader: BagReader, record) -> tuple[int, tuple[float, float, float]]:
    """Stamp (ns) and vector of a Vector3Stamped record."""
    fields = cdr.read_vector3_stamped(record.raw)
    if fields is None:
        message = reader.decode(record)
        return stamp_to_ns(message.header.stamp), tuple(_vector(message.vector))
    sec, nanosec, _, vector = fields
    return sec * NANOSECONDS_PER_SECOND + nanosec, vector


def judge_wind(out_bag: Path) -> dict:
    """:meth:`WindErrors.summary` of the whole run."""
    errors = wind_errors(out_bag)
    return errors.summary(int(errors.stamps_ns[0]), int(errors.stamps_ns[-1]) + 1)


def _attitude_errors_deg(bag: Path, topic: str, truth) -> np.ndarray | None:
    """(N, 3) roll, pitch and heading errors (deg, ZYX of R_estimated R_true⁻¹) of the
    orientations on ``topic`` of ``bag`` against the truth, after :data:`ATTITUDE_SETTLING_S`;
    None when the bag has none."""
    with BagReader(bag) as reader:
        try:
            messages = [reader.decode(r) for r in reader.messages([topic])]
        except BagError:
            return None
    if not messages:
        return None
    stamps = np.array([stamp_to_ns(m.header.stamp) for m in messages])
    quats = np.array([_quaternion(_q(m)) for m in messages])
    truth_ns, truth_attitude = truth
    keep = (stamps >= truth_ns[0] + int(ATTITUDE_SETTLING_S * 1e9)) & (stamps <= truth_ns[-1])
    if not np.any(keep):
        return None
    seconds = (truth_ns - truth_ns[0]) * 1e-9
    true = Slerp(seconds, truth_attitude)((stamps[keep] - truth_ns[0]) * 1e-9)
    error = (Rotation.from_quat(quats[keep]) * true.inv()).as_euler("ZYX", degrees=True)
    return error[:, ::-1]


def _roll_pitch_rms_deg(errors_deg: np.ndarray | None) -> list[float] | None:
    if errors_deg is None:
        return None
    return np.sqrt((errors_deg[:, :2] ** 2).mean(axis=0)).tolist()


def _q(message):
    """The orientation of an Odometry or an Imu message."""
    return message.pose.pose.orientation if hasattr(message, "pose") else message.orientation


def judge_attitude(in_bag: Path, out_bag: Path) -> dict:
    """RMS roll and pitch errors (deg) of the fusion and of the motion pack's own attitude, and
    the fusion's largest roll, pitch and heading errors (deg), after the settling time."""
    with BagReader(in_bag) as reader:
        truth_messages = [reader.decode(r) for r in reader.messages([TRUTH_ODOMETRY_TOPIC])]
    truth = (
        np.array([stamp_to_ns(m.header.stamp) for m in truth_messages]),
        Rotation.from_quat([_quaternion(_q(m)) for m in truth_messages]),
    )
    fused = _attitude_errors_deg(out_bag, NAV_ODOMETRY_TOPIC, truth)
    return {
        "fused_roll_pitch_rms_deg": _roll_pitch_rms_deg(fused),
        "fused_max_error_deg": None if fused is None else np.abs(fused).max(axis=0).tolist(),
        "motion_pack_roll_pitch_rms_deg": _roll_pitch_rms_deg(
            _attitude_errors_deg(in_bag, AHRS_TOPIC, truth)
        ),
    }


def _quaternion(q) -> tuple[float, float, float, float]:
    return q.x, q.y, q.z, q.w


def suspensions_in(lines: list[str]) -> list[str]:
    """The fusion summary's lines that say a source was suspended."""
    return [line.strip() for line in lines if " suspended:" in line]


def _figure(values, digits: int = 3) -> str:
    if values is None:
        return "–"
    return "/".join(f"{v:.{digits}f}" if isinstance(v, float) else str(v) for v in values)


def print_table(results: dict) -> None:
    print(
        "| case | valid | beyond 3σ (E/N/U) | beyond 5σ | RMS error m/s | max error m/s | "
        "median σ m/s | roll/pitch RMS deg: fused, pack | fused max error deg: roll/pitch/"
        "heading | aligned | suspended |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for key, result in results.items():
        wind, attitude = result["wind"], result["attitude"]
        print(
            f"| {key}: {result['description']} | {wind['valid_share']:.0%} | "
            f"{_figure(wind['beyond_3_sigma_share'])} | {_figure(wind['beyond_5_sigma'])} | "
            f"{_figure(wind['rms_error_mps'], 2)} | {_figure(wind['max_error_mps'], 2)} | "
            f"{_figure(wind['median_sigma_mps'], 2)} | "
            f"{_figure(attitude['fused_roll_pitch_rms_deg'], 2)}, "
            f"{_figure(attitude['motion_pack_roll_pitch_rms_deg'], 2)} | "
            f"{_figure(attitude['fused_max_error_deg'], 2)} | "
            f"{'yes' if result['aligned'] else 'never'} | "
            f"{'; '.join(result['suspended']) or '–'} |"
        )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="5-minute runs instead of 15")
    parser.add_argument("--only", nargs="+", choices=sorted(CASES), help="run these cases")
    parser.add_argument("--duration-s", type=float, help="length of every run, s")
    args = parser.parse_args(argv)
    duration_s = args.duration_s or (300.0 if args.quick else 900.0)
    keys = args.only or list(CASES)
    WORK.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max_workers=2) as pool:
        futures = {key: pool.submit(run_case, key, duration_s) for key in keys}
        results = {key: future.result() for key, future in futures.items()}
    print_table(results)
    (OUT / "uncertainty.json").write_text(json.dumps(results, indent=1, default=float))
    print(f"figures in {(OUT / 'uncertainty.json').relative_to(REPO)}", file=sys.stderr)
    worst = max(
        (max(r["wind"]["beyond_3_sigma_share"] or [0.0]) for r in results.values()),
        default=math.nan,
    )
    print(f"largest share beyond 3σ on any axis: {worst:.2%}", file=sys.stderr)


if __name__ == "__main__":
    main()
