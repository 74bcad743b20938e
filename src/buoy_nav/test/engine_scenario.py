"""The rocking buoy the fusion engine's tests run on: its motion, the IMU and GNSS events it
gives, and helpers to run an engine on them and compare runs."""

import math

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_nav import earth
from buoy_nav.aiding import GnssFix, GnssHeading, GnssVelocity
from buoy_nav.config import FusionConfig
from buoy_nav.engine import FusionEngine

LATITUDE_DEG, LONGITUDE_DEG, ALTITUDE_M = 38.9, 117.7, 0.0
LATITUDE = math.radians(LATITUDE_DEG)
GRAVITY = earth.normal_gravity_mps2(LATITUDE, ALTITUDE_M)
EARTH_RATE = earth.earth_rate_enu_rad_s(LATITUDE)
PRIMARY = np.array((0.2, -0.5, 1.1))
SECONDARY = np.array((-1.1, 0.4, 0.8))
POSITION_COV = np.diag((4e-4, 4e-4, 16e-4))
VELOCITY_COV = np.diag((4e-4, 4e-4, 16e-4))
HEADING_VAR = (0.003 / 1.6) ** 2


class RockingBuoy:
    """A buoy rocking about its IMU at a fixed position, with exact sensor data.

    Euler angles (ZYX) are sums of sinusoids; the body rate comes from their analytic rates.
    """

    def __init__(self, roll_deg=8.0, pitch_deg=5.0, yaw_deg=30.0, yaw_swing_deg=3.0):
        self.amplitudes = np.radians((roll_deg, pitch_deg, yaw_swing_deg))
        self.yaw0 = math.radians(yaw_deg)
        self.omegas = 2 * math.pi / np.array((9.0, 6.0, 11.0))
        self.phases = np.array((0.0, 1.0, 2.0))

    def euler(self, t):
        t = np.atleast_1d(t)[:, None]
        angles = self.amplitudes * np.sin(self.omegas * t + self.phases)
        angles[:, 2] += self.yaw0
        rates = self.amplitudes * self.omegas * np.cos(self.omegas * t + self.phases)
        return angles, rates

    def rotation(self, t):
        angles, _ = self.euler(t)
        return Rotation.from_euler("ZYX", angles[:, ::-1])

    def body_rate(self, t):
        angles, rates = self.euler(t)
        roll, pitch = angles[:, 0], angles[:, 1]
        droll, dpitch, dyaw = rates.T
        return np.column_stack(
            (
                droll - dyaw * np.sin(pitch),
                dpitch * np.cos(roll) + dyaw * np.sin(roll) * np.cos(pitch),
                -dpitch * np.sin(roll) + dyaw * np.cos(roll) * np.cos(pitch),
            )
        )

    def imu(self, t):
        rotation = self.rotation(t)
        gyro = self.body_rate(t) + rotation.inv().apply(EARTH_RATE)
        force = rotation.inv().apply(np.array((0.0, 0.0, GRAVITY)))
        return gyro, force

    def gnss(self, t):
        """Per stamp: antenna fix (deg, deg, m), antenna velocity ENU, baseline azimuth."""
        rotation = self.rotation(t)
        lever = rotation.apply(PRIMARY)
        plane = earth.LocalTangentPlane(LATITUDE, math.radians(LONGITUDE_DEG), ALTITUDE_M)
        lat, lon, alt = plane.geodetic_from_enu(lever)
        velocity = rotation.apply(np.cross(self.body_rate(t), PRIMARY))
        baseline = rotation.apply(SECONDARY - PRIMARY)
        heading = np.arctan2(baseline[:, 1], baseline[:, 0])
        return np.degrees(lat), np.degrees(lon), alt, velocity, heading


def make_events(buoy, duration, imu_rate=100.0, gnss_rate=10.0, gnss_offset_s=0.0):
    """Events (t, arrival order key, kind, args) of a run, in stamp order."""
    t_imu = np.arange(0.0, duration, 1.0 / imu_rate)
    t_gnss = np.arange(gnss_offset_s, duration, 1.0 / gnss_rate)
    gyro, force = buoy.imu(t_imu)
    lat, lon, alt, velocity, heading = buoy.gnss(t_gnss)
    events = [(t, 1, "imu", (gyro[k], force[k])) for k, t in enumerate(t_imu)]
    for k, t in enumerate(t_gnss):
        events.append((t, 0, "fix", (lat[k], lon[k], alt[k], POSITION_COV)))
        events.append((t, 0, "vel", (velocity[k], VELOCITY_COV)))
        events.append((t, 0, "heading", (heading[k], HEADING_VAR)))
    events.sort(key=lambda e: (e[0], e[1]))
    return events


MEASUREMENT_TYPES = {"fix": GnssFix, "vel": GnssVelocity, "heading": GnssHeading}


def deliver(engine, event):
    t, _, kind, args = event
    if kind == "imu":
        return engine.add_imu(t, *args)
    engine.add_measurement(t, MEASUREMENT_TYPES[kind](*args))
    return []


def run(events, config=None):
    engine = FusionEngine(config or engine_config())
    solutions = []
    for event in events:
        solutions += deliver(engine, event)
    solutions += engine.flush()
    return engine, solutions


def engine_config(**overrides):
    values = dict(primary_antenna_body_m=tuple(PRIMARY), secondary_antenna_body_m=tuple(SECONDARY))
    values.update(overrides)
    return FusionConfig(**values)


def attitude_errors_rad(buoy, solutions):
    t = np.array([s.t_s for s in solutions])
    estimate = Rotation.from_quat(np.array([s.attitude_xyzw for s in solutions]))
    return np.linalg.norm((buoy.rotation(t) * estimate.inv()).as_rotvec(), axis=1)


def solution_matrix(solutions):
    """Every number of every solution, for exact comparisons of whole runs."""
    rows = []
    for s in solutions:
        rows.append(
            np.concatenate(
                (
                    [s.t_s, s.latitude_deg, s.longitude_deg, s.altitude_m],
                    s.attitude_xyzw,
                    s.velocity_enu_mps,
                    s.position_map_m,
                    s.gyro_bias_rad_s,
                    s.accel_bias_mps2,
                    s.attitude_covariance_rad2.ravel(),
                    s.velocity_covariance_m2s2.ravel(),
                    s.position_covariance_m2.ravel(),
                    [s.coasting_fix, s.coasting_velocity, s.coasting_heading],
                )
            )
        )
    return np.array(rows)
