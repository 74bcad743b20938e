"""The analyses of ``make bench`` (tools/bench.py): each reads one processed bag, through the
wind report's readers (:mod:`buoy_processing.report.data`), into the figures of one table."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    NANOSECONDS_PER_SECOND,
    NAV_FIX_TOPIC,
    NAV_ODOMETRY_TOPIC,
    TRUTH_ODOMETRY_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
)
from buoy_processing.report.data import (
    interpolate_vectors,
    odometry_series,
    stamped_vectors,
)
from tools.bench_plan import (
    ATTITUDE_MAX_ERROR_DEG,
    ATTITUDE_RMS_DEG,
    CONVERGED_SIGMA_DEG,
    MIN_MEAN_WINDOW_COVERAGE_S,
    PROCESSING_PARAMS,
    SEA_MEAN_DIRECTION_ERROR_DEG,
    SEA_MEAN_SPEED_ERROR_MPS,
    SEA_MEAN_WINDOW_S,
    VERTICAL_RESIDUAL_SHARE_TARGET,
    VERTICAL_SPEED_ERROR_TARGET,
)
from wind_comp.compensation_messages import anemometer_sample, fix_fields, odometry_fields
from wind_comp.compensator import CorrectedBatch, SampleStatus
from wind_comp.config import compensator_config_from_files
from wind_comp.miller import mounting_rotation_from_rpy_deg
from wind_comp.nav_interpolation import NavTrack
from wind_comp.pipeline import wind_pipeline
from wind_comp.products import meteorological_direction_deg

# Truth and navigation stamps closer than this are the same instant (float rounding of stamps).
STAMP_MATCH_NS = 1000


def matching_indices(stamps_a_ns: np.ndarray, stamps_b_ns: np.ndarray):
    """Indices (ia, ib) of stamps present in both sorted arrays, within STAMP_MATCH_NS."""
    position = np.clip(np.searchsorted(stamps_b_ns, stamps_a_ns), 1, len(stamps_b_ns) - 1)
    left, right = stamps_b_ns[position - 1], stamps_b_ns[position]
    nearest = np.where(stamps_a_ns - left <= right - stamps_a_ns, position - 1, position)
    close = np.abs(stamps_b_ns[nearest] - stamps_a_ns) <= STAMP_MATCH_NS
    return np.flatnonzero(close), nearest[close]


def wrap_deg(angles_deg):
    return (np.asarray(angles_deg) + 180.0) % 360.0 - 180.0


def rms(values) -> float:
    values = np.asarray(values, dtype=float)
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def vector_rms(errors: np.ndarray) -> float:
    """RMS of the length of (N, 3) error vectors."""
    return float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))) if len(errors) else math.nan


# ---------------------------------------------------------------------------------------------
# Table 1: attitude.


def convergence(nav_stamps_ns: np.ndarray, variances_rad2: np.ndarray) -> dict:
    """First stamp after which every 1-sigma stays below its CONVERGED_SIGMA_DEG for good."""
    sigma_deg = np.degrees(np.sqrt(np.maximum(variances_rad2, 0.0)))
    per_axis_ns = {}
    for k, (axis, threshold) in enumerate(CONVERGED_SIGMA_DEG.items()):
        above = np.flatnonzero(~(sigma_deg[:, k] < threshold))
        if len(above) == 0:
            per_axis_ns[axis] = int(nav_stamps_ns[0])
        elif above[-1] == len(nav_stamps_ns) - 1:
            per_axis_ns[axis] = None
        else:
            per_axis_ns[axis] = int(nav_stamps_ns[above[-1] + 1])
    converged = all(v is not None for v in per_axis_ns.values())
    return {
        "converged": converged,
        "per_axis_ns": per_axis_ns,
        "at_ns": max(per_axis_ns.values()) if converged else None,
        "final_sigma_enu_deg": sigma_deg[-1].tolist(),
    }


def analyse_attitude(out_bag: str, scenario_duration_s: float) -> dict:
    with BagReader(out_bag) as reader:
        nav = odometry_series(reader, NAV_ODOMETRY_TOPIC)
        truth = odometry_series(reader, TRUTH_ODOMETRY_TOPIC)
    start_ns = int(truth.stamps_ns[0])
    aligned_ns = int(nav.stamps_ns[0])
    variances = np.diagonal(nav.attitude_covariance_enu_rad2, axis1=1, axis2=2)
    conv = convergence(nav.stamps_ns, variances)
    evaluate_from_ns = conv["at_ns"] if conv["converged"] else aligned_ns + int(60e9)
    # Truth (50 Hz) is stamped on every other IMU stamp: compare there, exactly, no interpolation.
    i_nav, i_truth = matching_indices(nav.stamps_ns, truth.stamps_ns)
    keep = nav.stamps_ns[i_nav] >= evaluate_from_ns
    i_nav, i_truth = i_nav[keep], i_truth[keep]
    estimated = Rotation.from_quat(nav.quat_xyzw[i_nav])
    true = Rotation.from_quat(truth.quat_xyzw[i_truth])
    # as_euler("ZYX") gives (yaw, pitch, roll) of R = Rz(yaw)·Ry(pitch)·Rx(roll).
    error_deg = wrap_deg(np.degrees(estimated.as_euler("ZYX") - true.as_euler("ZYX")))
    angles = {"heading": error_deg[:, 0], "pitch": error_deg[:, 1], "roll": error_deg[:, 2]}
    velocity_error = estimated.apply(nav.velocity_body_mps[i_nav]) - true.apply(
        truth.velocity_body_mps[i_truth]
    )
    result = {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (aligned_ns - start_ns) * 1e-9,
        "converged": conv["converged"],
        "convergence_s": None if conv["at_ns"] is None else (conv["at_ns"] - start_ns) * 1e-9,
        "convergence_per_axis_s": {
            axis: None if ns is None else (ns - start_ns) * 1e-9
            for axis, ns in conv["per_axis_ns"].items()
        },
        "final_sigma_enu_deg": dict(
            zip(CONVERGED_SIGMA_DEG, conv["final_sigma_enu_deg"], strict=True)
        ),
        "evaluated_from_s": (evaluate_from_ns - start_ns) * 1e-9,
        "evaluated_samples": len(i_nav),
        "errors_deg": {},
        "velocity_rms_enu_mps": {
            axis: rms(velocity_error[:, k]) for k, axis in enumerate(("east", "north", "up"))
        },
    }
    for name in ("roll", "pitch", "heading"):
        values = angles[name]
        lowest, highest = float(values.min()), float(values.max())
        result["errors_deg"][name] = {
            "max_negative_deg": lowest,
            "max_positive_deg": highest,
            "rms_deg": rms(values),
            "max_negative_pass": bool(abs(lowest) <= ATTITUDE_MAX_ERROR_DEG[name]),
            "max_positive_pass": bool(abs(highest) <= ATTITUDE_MAX_ERROR_DEG[name]),
            "rms_pass": bool(rms(values) <= ATTITUDE_RMS_DEG[name]),
        }
    return result


# ---------------------------------------------------------------------------------------------
# Wind tables: common reading.


@dataclass
class WindRun:
    """The arrays of one processed wind bag."""

    start_ns: int
    aligned_ns: int
    wind_stamp_ns: np.ndarray
    wind_t_s: np.ndarray  # header stamps as the compensation takes them, s since the epoch
    measured_sensor_mps: np.ndarray
    corrected_enu_mps: np.ndarray
    truth_enu_mps: np.ndarray  # truth/wind interpolated to the anemometer stamps
    nav_t_s: np.ndarray  # nav/odometry header stamps, s since the epoch
    nav_quat_xyzw: np.ndarray


def read_wind_run(out_bag: str) -> WindRun:
    with BagReader(out_bag) as reader:
        measured = stamped_vectors(reader, WIND_RAW_TOPIC)
        corrected = stamped_vectors(reader, WIND_TRUE_TOPIC)
        truth = stamped_vectors(reader, TRUTH_WIND_TOPIC)
        nav = odometry_series(reader, NAV_ODOMETRY_TOPIC)
    if not np.array_equal(corrected.stamps_ns, measured.stamps_ns):
        raise RuntimeError(f"{out_bag}: wind/true stamps differ from anemometer/wind stamps")
    nav_t_s = seconds(nav.stamps_ns)
    return WindRun(
        start_ns=int(min(truth.stamps_ns[0], measured.stamps_ns[0])),
        aligned_ns=round(float(nav_t_s[0]) * 1e9),
        wind_stamp_ns=measured.stamps_ns,
        wind_t_s=seconds(measured.stamps_ns),
        measured_sensor_mps=measured.vectors,
        corrected_enu_mps=corrected.vectors,
        truth_enu_mps=interpolate_vectors(measured.stamps_ns, truth),
        nav_t_s=nav_t_s,
        nav_quat_xyzw=nav.quat_xyzw,
    )


def seconds(stamps_ns: np.ndarray) -> np.ndarray:
    """Header stamps (ns) as the float seconds the suite computes from (sec, nanosec)."""
    sec, nanosec = np.divmod(stamps_ns, NANOSECONDS_PER_SECOND)
    return sec + nanosec * 1e-9


def recorrected_wind(out_bag: str, config) -> CorrectedBatch:
    """The bag's ``anemometer/wind`` corrected again from its ``nav/odometry`` and ``nav/fix``,
    given to the compensation pipeline in log-time order as ``compensation_node`` receives
    them: the Miller terms of every sample."""
    pipeline = wind_pipeline(config)
    with BagReader(out_bag) as reader:
        for message in reader.messages([NAV_ODOMETRY_TOPIC, NAV_FIX_TOPIC, WIND_RAW_TOPIC]):
            topic = message.topic.lstrip("/")
            if topic == NAV_ODOMETRY_TOPIC:
                pipeline.add_odometry(*odometry_fields(reader.decode(message)))
            elif topic == NAV_FIX_TOPIC:
                pipeline.add_fix(*fix_fields(reader.decode(message)))
            else:
                pipeline.add_sample(anemometer_sample(reader.decode(message)))
    return pipeline.flush().samples


def nav_attitude_at(run: WindRun, config) -> tuple[Rotation, np.ndarray]:
    """Navigation attitude at the anemometer stamps (as the compensator interpolates it)."""
    no_motion = np.zeros((run.nav_t_s.shape[0], 3))
    track = NavTrack.from_arrays(
        run.nav_t_s, run.nav_quat_xyzw, no_motion, no_motion, max_gap_s=config.max_nav_gap_s
    )
    interpolated = track.interpolate(run.wind_t_s)
    return interpolated.attitude_nb, interpolated.valid


def heading_only_wind(measured_sensor_mps, heading_rad, config) -> np.ndarray:
    """The measured air velocity as if the platform were level and still: rotated by the
    mounting and by a heading only (no tilt, no lever-arm rotation, no platform velocity)."""
    mounted_body = mounting_rotation_from_rpy_deg(config.anemometer_rpy_deg).apply(
        measured_sensor_mps
    )
    return Rotation.from_euler("z", np.asarray(heading_rad)[:, None]).apply(mounted_body)


def mean_wind(vectors_enu: np.ndarray) -> dict:
    """Scalar mean horizontal speed, and speed and meteorological direction of the vector
    mean. The paper's table gives one mean speed; both are kept because a wind that turns
    (as an uncorrected reading on a turning platform does) has a short vector mean."""
    mean_u, mean_v = vectors_enu[:, 0].mean(), vectors_enu[:, 1].mean()
    return {
        "mean_speed_mps": float(np.mean(np.hypot(vectors_enu[:, 0], vectors_enu[:, 1]))),
        "vector_mean_speed_mps": float(np.hypot(mean_u, mean_v)),
        "direction_deg": float(meteorological_direction_deg(mean_u, mean_v)),
        "samples": len(vectors_enu),
    }


# ---------------------------------------------------------------------------------------------
# Table 2: wind tunnel.


def analyse_tunnel(out_bag: str, scenario_duration_s: float) -> dict:
    config = compensator_config_from_files(PROCESSING_PARAMS)
    run = read_wind_run(out_bag)
    after = run.wind_stamp_ns >= run.aligned_ns
    valid = after & np.all(np.isfinite(run.corrected_enu_mps), axis=1)
    attitude, nav_valid = nav_attitude_at(run, config)
    heading_rad = attitude.as_euler("ZYX")[:, 0]
    # Uncorrected, as a level and still anemometer would read: only the mounting rotation and
    # ONE heading, the circular mean of the navigation heading over the run. A plain
    # anemometer has no attitude sensor; a fixed installation heading is what it can use, so
    # this shows all the correction buys, tilt, lever arm, velocity and turning together.
    yaw = Rotation.from_quat(run.nav_quat_xyzw).as_euler("ZYX")[:, 0]
    nav_after = run.nav_t_s * 1e9 >= run.aligned_ns
    mean_heading_rad = float(
        np.arctan2(np.mean(np.sin(yaw[nav_after])), np.mean(np.cos(yaw[nav_after])))
    )
    mean_heading_wind = heading_only_wind(
        run.measured_sensor_mps[after], np.full(after.sum(), mean_heading_rad), config
    )
    # Also with the heading of each sample (a compass), to separate the turning from the rest.
    compass = after & nav_valid
    compass_wind = heading_only_wind(run.measured_sensor_mps[compass], heading_rad[compass], config)
    return {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (run.aligned_ns - run.start_ns) * 1e-9,
        "samples_after_alignment": int(after.sum()),
        "nan_samples_after_alignment": int((after & ~valid).sum()),
        "nan_samples_total": int((~np.all(np.isfinite(run.corrected_enu_mps), axis=1)).sum()),
        "corrected": mean_wind(run.corrected_enu_mps[valid]),
        "truth": mean_wind(run.truth_enu_mps[valid]),
        "uncorrected_mean_heading": {
            **mean_wind(mean_heading_wind),
            "mean_heading_enu_deg": math.degrees(mean_heading_rad),
        },
        "uncorrected_compass_heading": mean_wind(compass_wind),
    }


# ---------------------------------------------------------------------------------------------
# Table 3: vertical wind.


def analyse_vertical(out_bag: str, scenario_duration_s: float) -> dict:
    run = read_wind_run(out_bag)
    after = run.wind_stamp_ns >= run.aligned_ns
    valid = after & np.all(np.isfinite(run.corrected_enu_mps), axis=1)
    before_w = run.measured_sensor_mps[valid, 2]
    after_w = run.corrected_enu_mps[valid, 2]
    truth_w = run.truth_enu_mps[valid, 2]
    residual_rms = rms(after_w - truth_w)
    uncorrected_rms = rms(before_w - truth_w)
    corrected_speed = np.hypot(run.corrected_enu_mps[valid, 0], run.corrected_enu_mps[valid, 1])
    truth_speed = np.hypot(run.truth_enu_mps[valid, 0], run.truth_enu_mps[valid, 1])
    speed_error = float(corrected_speed.mean() / truth_speed.mean() - 1.0)
    share = residual_rms / uncorrected_rms
    return {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (run.aligned_ns - run.start_ns) * 1e-9,
        "samples": int(valid.sum()),
        "nan_samples_after_alignment": int((after & ~valid).sum()),
        "before_sensor_w": describe(before_w),
        "after_enu_w": describe(after_w),
        "truth_enu_w": describe(truth_w),
        "residual_rms_mps": residual_rms,
        "uncorrected_error_rms_mps": uncorrected_rms,
        "residual_share_of_uncorrected": share,
        "range_share_after_before": describe(after_w)["range_mps"]
        / describe(before_w)["range_mps"],
        "mean_speed_corrected_mps": float(corrected_speed.mean()),
        "mean_speed_truth_mps": float(truth_speed.mean()),
        "speed_error_fraction": speed_error,
        "residual_share_pass": bool(share <= VERTICAL_RESIDUAL_SHARE_TARGET),
        "speed_error_pass": bool(abs(speed_error) <= VERTICAL_SPEED_ERROR_TARGET),
    }


def describe(values: np.ndarray) -> dict:
    return {
        "min_mps": float(values.min()),
        "max_mps": float(values.max()),
        "range_mps": float(values.max() - values.min()),
        "std_mps": float(values.std()),
        "mean_mps": float(values.mean()),
    }


# ---------------------------------------------------------------------------------------------
# Table 4: sea.


def analyse_sea(out_bag: str, scenario_duration_s: float) -> dict:
    config = compensator_config_from_files(PROCESSING_PARAMS)
    run = read_wind_run(out_bag)
    after = run.wind_stamp_ns >= run.aligned_ns
    valid = after & np.all(np.isfinite(run.corrected_enu_mps), axis=1)
    error = run.corrected_enu_mps[valid] - run.truth_enu_mps[valid]
    windows, too_short = sea_mean_windows(run, valid)
    terms = miller_term_figures(out_bag, run, valid, config)
    return {
        "scenario_duration_s": scenario_duration_s,
        "aligned_s": (run.aligned_ns - run.start_ns) * 1e-9,
        "samples": int(valid.sum()),
        "nan_samples_after_alignment": int((after & ~valid).sum()),
        "rms_error_enu_mps": {
            axis: rms(error[:, k]) for k, axis in enumerate(("east", "north", "up"))
        },
        "rms_error_vector_mps": vector_rms(error),
        "uncorrected_error_rms_vector_mps": terms["uncorrected_rms"],
        "full_correction_error_rms_vector_mps": terms["full_rms"],
        "mean_windows": windows,
        "samples_in_windows_too_short_to_report": too_short,
        "term_share_of_uncorrected_error": terms["shares"],
        "term_rms_mps": terms["term_sizes"],
        "recomputed_vs_bag_max_abs_mps": terms["recompute_difference"],
    }


def sea_mean_windows(run, valid: np.ndarray) -> tuple[list[dict], list[int]]:
    """The mean wind's error in each window of the ``valid`` samples long enough to report,
    and the sample counts of those too short. Windows as the wind products align them:
    multiples of 600 s of the stamps."""
    window_index = run.wind_stamp_ns // int(SEA_MEAN_WINDOW_S * 1e9)
    windows, too_short = [], []
    for index in np.unique(window_index[valid]):
        in_window = valid & (window_index == index)
        stamps = run.wind_stamp_ns[in_window]
        if (stamps[-1] - stamps[0]) * 1e-9 < MIN_MEAN_WINDOW_COVERAGE_S:
            too_short.append(int(in_window.sum()))
            continue
        windows.append(sea_mean_window(run, in_window, index))
    return windows, too_short


def sea_mean_window(run, in_window: np.ndarray, index) -> dict:
    """Truth and error of the vector-mean wind speed (m/s) and meteorological direction (°)
    over the samples ``in_window`` of window ``index`` (multiples of SEA_MEAN_WINDOW_S)."""
    stamps = run.wind_stamp_ns[in_window]
    corrected = run.corrected_enu_mps[in_window].mean(axis=0)
    truth = run.truth_enu_mps[in_window].mean(axis=0)
    speed_error = float(np.hypot(*corrected[:2]) - np.hypot(*truth[:2]))
    direction_error = float(
        wrap_deg(
            meteorological_direction_deg(*corrected[:2]) - meteorological_direction_deg(*truth[:2])
        )
    )
    return {
        "start_s": (int(index) * SEA_MEAN_WINDOW_S * 1e9 - run.start_ns) * 1e-9,
        "covered_s": (stamps[-1] - stamps[0]) * 1e-9,
        "samples": int(in_window.sum()),
        "truth_speed_mps": float(np.hypot(*truth[:2])),
        "truth_direction_deg": float(meteorological_direction_deg(*truth[:2])),
        "speed_error_mps": speed_error,
        "direction_error_deg": direction_error,
        "speed_pass": bool(abs(speed_error) <= SEA_MEAN_SPEED_ERROR_MPS),
        "direction_pass": bool(abs(direction_error) <= SEA_MEAN_DIRECTION_ERROR_DEG),
    }


def miller_term_figures(out_bag: str, run, valid: np.ndarray, config) -> dict:
    """The Miller terms, recomputed from the output bag's navigation as process_bag feeds it:
    the RMS vector error (m/s) uncorrected and fully corrected, the share of the uncorrected
    error each term removes, each term's RMS size (m/s), and how far the recomputed wind is
    from the bag's (m/s)."""
    batch = recorrected_wind(out_bag, config)
    batch_valid = batch.status == SampleStatus.VALID
    recompute_difference = float(
        np.max(np.abs(batch.flow_enu_mps[valid] - run.corrected_enu_mps[valid]))
    )
    attitude, _ = nav_attitude_at(run, config)
    heading_rad = attitude.as_euler("ZYX")[:, 0]
    use = valid & batch_valid
    truth = run.truth_enu_mps[use]
    tilt = batch.tilt_term_enu_mps[use]
    rotation = batch.rotation_term_enu_mps[use]
    translation = batch.translation_term_enu_mps[use]
    # Uncorrected wind: the measured air velocity rotated by the mounting and by the
    # navigation heading of each sample (interpolated as the compensator does), nothing else:
    # what a buoy with a compass but no motion correction reports. Omitting the tilt term
    # means this heading-only rotation in place of the full attitude, so the three shares
    # measure the tilt, the lever-arm rotation and the platform velocity separately and the
    # heading, which any buoy measures, is common to all.
    levelled = heading_only_wind(run.measured_sensor_mps[use], heading_rad[use], config)
    full_rms = vector_rms(truth - (tilt + rotation + translation))
    uncorrected_rms = vector_rms(truth - levelled)
    omitted = {
        "tilt": levelled + rotation + translation,
        "rotation": tilt + translation,
        "translation": tilt + rotation,
    }
    return {
        "uncorrected_rms": uncorrected_rms,
        "full_rms": full_rms,
        "shares": {
            term: (vector_rms(truth - wind) - full_rms) / uncorrected_rms
            for term, wind in omitted.items()
        },
        "term_sizes": {
            "tilt_minus_heading_only": vector_rms(tilt - levelled),
            "rotation": vector_rms(rotation),
            "translation": vector_rms(translation),
        },
        "recompute_difference": recompute_difference,
    }


ANALYSES = {
    "attitude": analyse_attitude,
    "tunnel": analyse_tunnel,
    "vertical": analyse_vertical,
    "sea": analyse_sea,
}
