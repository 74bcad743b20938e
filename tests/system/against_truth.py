"""The simulator's truth a bag carries, and the errors of wind and navigation against it, judged
by the budgets of :mod:`error_budget`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from buoy_common import cdr_bulk
from buoy_common.bag_io import BagReader
from error_budget import AXES, IMU_RATE_HZ, NavigationLimits, wind_budget
from ros_messages import stamp_ns

# Wind samples are compared where truth/wind has a sample of the same stamp: between its
# samples the turbulence is not linear, and interpolating it would add an error of the size
# of the anemometer noise.
STAMP_MATCH_NS = 1000
NANOSECONDS_PER_SECOND = 1_000_000_000


def vector(v) -> list[float]:
    return [v.x, v.y, v.z]


def quaternion_xyzw(odometry) -> list[float]:
    q = odometry.pose.pose.orientation
    return [q.x, q.y, q.z, q.w]


def topic_columns(reader: BagReader, topic: str, msgtype: str) -> cdr_bulk.MessageColumns:
    """Every message of ``topic`` as columns, all of them decoded (the suite's column codec,
    held equal to rosbags' message by message in its own tests)."""
    columns = cdr_bulk.decode(msgtype, [record.raw for record in reader.messages([topic])])
    assert columns.valid.all(), f"{topic}: undecodable messages {columns.rejected}"
    return columns


@dataclass(frozen=True)
class NavigationErrors:
    """Errors estimate − truth of N solutions: attitude as the rotation vector φ with
    R_true = Exp(φ) R_estimate (ENU, rad), roll, pitch and heading (deg; the heading error is
    the yaw error, wrapped) and ENU velocity (m/s), (N, 3) each."""

    attitude_enu_rad: np.ndarray
    roll_pitch_heading_deg: np.ndarray
    velocity_enu_mps: np.ndarray

    def __len__(self) -> int:
        return self.velocity_enu_mps.shape[0]

    def largest(self) -> tuple[np.ndarray, np.ndarray]:
        """Largest |error|: (roll, pitch, heading) deg and velocity E, N, U m/s."""
        return (
            np.abs(self.roll_pitch_heading_deg).max(axis=0),
            np.abs(self.velocity_enu_mps).max(axis=0),
        )


class Truth:
    """``truth/odometry`` and ``truth/wind`` of a bag, as arrays."""

    def __init__(self, bag: Path):
        with BagReader(bag) as reader:
            odometry = topic_columns(reader, "truth/odometry", "nav_msgs/msg/Odometry")
            wind = topic_columns(reader, "truth/wind", "geometry_msgs/msg/Vector3Stamped")
        self.odometry_ns = odometry.stamp_ns
        self.attitude = Rotation.from_quat(odometry["orientation"])
        self.velocity_enu_mps = self.attitude.apply(odometry["linear"])
        self.wind_ns = wind.stamp_ns
        self.wind_enu_mps = wind["vector"]

    def wind_errors(self, stamps_ns, wind_enu_mps) -> np.ndarray:
        """Corrected − true wind (M, 3) at the valid samples whose stamp truth/wind shares."""
        stamps = np.asarray(stamps_ns)
        wind = np.asarray(wind_enu_mps, dtype=float)
        after = np.clip(np.searchsorted(self.wind_ns, stamps), 1, self.wind_ns.size - 1)
        nearest = np.where(
            np.abs(self.wind_ns[after] - stamps) < np.abs(self.wind_ns[after - 1] - stamps),
            after,
            after - 1,
        )
        matched = (np.abs(self.wind_ns[nearest] - stamps) < STAMP_MATCH_NS) & np.all(
            np.isfinite(wind), axis=1
        )
        return wind[matched] - self.wind_enu_mps[nearest[matched]]

    def covers(self, stamps_ns) -> np.ndarray:
        """Which stamps lie within the truth's odometry (bool array)."""
        stamps = np.asarray(stamps_ns)
        return (stamps >= self.odometry_ns[0]) & (stamps <= self.odometry_ns[-1])

    def navigation_errors(self, stamps_ns, attitude_xyzw, velocity_enu_mps) -> NavigationErrors:
        """Errors of solutions at ``stamps_ns`` (all covered by the truth) against the truth
        interpolated to their stamps: attitude by slerp, velocity linearly (both smooth to far
        below the errors judged over the 20 ms between truth samples)."""
        stamps = np.asarray(stamps_ns)
        assert np.all(self.covers(stamps)), "solutions outside the truth's time span"
        seconds = (stamps - self.odometry_ns[0]) * 1e-9
        truth_seconds = (self.odometry_ns - self.odometry_ns[0]) * 1e-9
        true_attitude = Slerp(truth_seconds, self.attitude)(seconds)
        estimate = Rotation.from_quat(np.asarray(attitude_xyzw, dtype=float))
        euler = estimate.as_euler("ZYX") - true_attitude.as_euler("ZYX")
        yaw_pitch_roll_deg = np.degrees((euler + np.pi) % (2 * np.pi) - np.pi)
        true_velocity = np.column_stack(
            [np.interp(seconds, truth_seconds, self.velocity_enu_mps[:, k]) for k in range(3)]
        )
        return NavigationErrors(
            (true_attitude * estimate.inv()).as_rotvec(),
            yaw_pitch_roll_deg[:, ::-1],
            np.asarray(velocity_enu_mps, dtype=float) - true_velocity,
        )


def odometry_errors(truth: Truth, odometry, settling_s: float) -> NavigationErrors:
    """Errors of decoded ``nav/odometry`` messages (rosbags' or rclpy's) stamped from
    ``settling_s`` after the first one on, within the truth's time span."""
    stamps = np.array([stamp_ns(m) for m in odometry])
    judged = (stamps >= stamps[0] + settling_s * NANOSECONDS_PER_SECOND) & truth.covers(stamps)
    chosen = [m for m, keep in zip(odometry, judged, strict=True) if keep]
    attitude_xyzw = np.array([quaternion_xyzw(m) for m in chosen])
    velocity_enu_mps = Rotation.from_quat(attitude_xyzw).apply(
        [vector(m.twist.twist.linear) for m in chosen]
    )
    return truth.navigation_errors(stamps[judged], attitude_xyzw, velocity_enu_mps)


def assert_wind_within_budget(
    errors_mps, measured_wind_mps, anemometer_position_body_m, what, imu_rate_hz=IMU_RATE_HZ
):
    """The RMS per ENU axis of ``errors_mps`` (M, 3) is inside the budget for M samples of a
    run whose anemometer measured ``measured_wind_mps`` (sensor axes, any number of samples)
    and whose IMU sampled at ``imu_rate_hz``."""
    errors = np.asarray(errors_mps)
    assert errors.shape[0] >= 300, f"{what}: only {errors.shape[0]} samples to judge"
    speeds = np.linalg.norm(np.asarray(measured_wind_mps, dtype=float), axis=1)
    speed_rms = float(np.sqrt(np.nanmean(speeds**2)))
    budget = wind_budget(errors.shape[0], speed_rms, anemometer_position_body_m, imu_rate_hz)
    rms = np.sqrt(np.mean(errors**2, axis=0))
    figures = (
        f"{what}: RMS error E, N, U {np.round(rms, 4)} m/s over {errors.shape[0]} samples, "
        f"air speed RMS {speed_rms:.2f} m/s; {budget}"
    )
    assert np.all(rms <= budget.total_mps), figures
    return figures


def assert_navigation_within_limits(errors: NavigationErrors, limits: NavigationLimits, what):
    """The largest roll, pitch, heading and velocity errors are inside ``limits``."""
    assert len(errors) > 100, f"{what}: only {len(errors)} solutions to judge"
    attitude, velocity = errors.largest()
    figures = (
        f"{what}: largest |error| roll {attitude[0]:.3f}, pitch {attitude[1]:.3f}, heading "
        f"{attitude[2]:.3f} deg, velocity "
        + ", ".join(f"{a} {v:.4f}" for a, v in zip(AXES, velocity, strict=True))
        + f" m/s over {len(errors)} solutions; {limits}"
    )
    assert attitude[0] <= limits.roll_deg, figures
    assert attitude[1] <= limits.pitch_deg, figures
    assert attitude[2] <= limits.heading_deg, figures
    assert np.all(velocity <= limits.velocity_mps), figures
    return figures
