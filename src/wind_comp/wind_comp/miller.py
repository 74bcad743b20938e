"""Miller et al. (2008) motion correction of a sonic anemometer on a moving platform.

The anemometer measures the air velocity relative to itself, in its own axes. Removing the
platform's tilt, its rotation about the body origin (lever arm) and its translation gives the
true wind in the world frame:

    V_true = R_nb · R_bw · V_w  +  R_nb · (ω × B)  +  V_b

- R_nb: attitude, rotates body (``base_link``, forward-left-up) vectors into ENU (``map``).
- R_bw: mounting rotation, rotates anemometer-axis vectors into the body frame.
- V_w: measured air velocity relative to the sensor, anemometer axes, m/s (direction the air
  moves toward).
- ω: body angular rate relative to the local-level frame, body axes, rad/s.
- B: anemometer measurement centre in the body frame, m.
- V_b: ENU velocity of the body origin, m/s.

The same correction gives the ocean current from a DVL in water track (paper 003): the DVL
measures its own velocity through the water, v_DVL, in its own axes, so the water moves past it
at V_w = −v_DVL, and with the DVL's mounting R_bd and position l in place of R_bw and B

    current = R_nb · R_bd · (−v_DVL)  +  R_nb · (ω × l)  +  V_b.

One component-wise routine, :func:`miller_components`, corrects one sample (floats, live) or a
whole recording (arrays, offline), with bit-identical results; the compensator runs it compiled
(numba, :mod:`wind_comp.correction_kernel`), sample by sample, on the same floats.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_nav.rotations import cross_components


class MillerInputError(ValueError):
    """An input of the Miller correction has the wrong shape or type."""


@dataclass(frozen=True, eq=False)
class MillerTerms:
    """Corrected wind and the three terms of the Miller correction, ENU, m/s.

    Arrays are (N, 3) when any input was a batch, (3,) when every input was a single sample.
    ``true_wind_enu_mps = tilt_term_enu_mps + rotation_term_enu_mps + translation_term_enu_mps``.
    """

    true_wind_enu_mps: np.ndarray
    tilt_term_enu_mps: np.ndarray
    rotation_term_enu_mps: np.ndarray
    translation_term_enu_mps: np.ndarray

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(true wind, tilt term, rotation term, translation term)."""
        return (
            self.true_wind_enu_mps,
            self.tilt_term_enu_mps,
            self.rotation_term_enu_mps,
            self.translation_term_enu_mps,
        )


def mounting_rotation_from_rpy_deg(rpy_deg) -> Rotation:
    """Sensor→body rotation (R_bw of the anemometer, R_bd of the DVL) from roll, pitch, yaw in
    degrees.

    Applied as R = Rz(yaw)·Ry(pitch)·Rx(roll), the convention of parameters
    ``anemometer.rpy_deg`` and ``dvl.rpy_deg``.
    """
    angles_deg = np.asarray(rpy_deg, dtype=float)
    if angles_deg.shape != (3,):
        raise MillerInputError(
            f"mounting rpy_deg must be three angles (roll, pitch, yaw) in degrees, "
            f"got shape {angles_deg.shape}"
        )
    if not np.all(np.isfinite(angles_deg)):
        raise MillerInputError(f"mounting rpy_deg must be finite, got {angles_deg.tolist()}")
    roll_deg, pitch_deg, yaw_deg = angles_deg
    return Rotation.from_euler("ZYX", [yaw_deg, pitch_deg, roll_deg], degrees=True)


def _as_vectors(name: str, values) -> np.ndarray:
    """Return ``values`` as an (N, 3) or (3,) float array, or raise naming the input."""
    array = np.asarray(values, dtype=float)
    if array.ndim not in (1, 2) or array.shape[-1] != 3:
        raise MillerInputError(f"{name} must have shape (3,) or (N, 3), got {array.shape}")
    return array


def _attitude_matrices(attitude_nb) -> np.ndarray:
    """Body→ENU rotation matrices as (N, 3, 3) or (3, 3)."""
    if not isinstance(attitude_nb, Rotation):
        raise MillerInputError(
            f"attitude_nb must be a scipy Rotation (body→ENU), got {type(attitude_nb).__name__}"
        )
    return attitude_nb.as_matrix()


def _mounting_matrix(mounting_rotation_bw) -> np.ndarray:
    """Anemometer→body rotation as one 3x3 matrix."""
    if isinstance(mounting_rotation_bw, Rotation):
        if not mounting_rotation_bw.single:
            raise MillerInputError("mounting_rotation_bw must be a single rotation")
        return mounting_rotation_bw.as_matrix()
    matrix = np.asarray(mounting_rotation_bw, dtype=float)
    if matrix.shape != (3, 3):
        raise MillerInputError(
            f"mounting_rotation_bw must be a scipy Rotation or a 3x3 matrix, got {matrix.shape}"
        )
    if not np.allclose(matrix @ matrix.T, np.eye(3), atol=1e-9) or np.linalg.det(matrix) < 0:
        raise MillerInputError("mounting_rotation_bw matrix is not a proper rotation")
    return matrix


def rotate_components(matrix_elements, vector) -> tuple:
    """Matrix × vector written out: ``matrix_elements`` are the nine row-major elements,
    ``vector`` the three components; each a float or an array, all of one shape (or floats).

    Elementwise, so a sample gives bit-identical results alone (floats, the live case) or inside
    a batch (arrays, offline): streaming and offline must agree.
    """
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = matrix_elements
    x, y, z = vector
    return (
        m00 * x + m01 * y + m02 * z,
        m10 * x + m11 * y + m12 * z,
        m20 * x + m21 * y + m22 * z,
    )


def miller_correction(
    wind_sensor_mps,
    attitude_nb: Rotation,
    angular_rate_body_rad_s,
    velocity_enu_mps,
    mounting_rotation_bw,
    anemometer_position_body_m,
) -> MillerTerms:
    """Remove the platform motion from anemometer samples (Miller et al. 2008).

    Args:
        wind_sensor_mps: measured air velocity relative to the sensor, anemometer axes, m/s,
            shape (3,) or (N, 3).
        attitude_nb: body→ENU attitude, one rotation or N rotations.
        angular_rate_body_rad_s: body rate relative to the local-level frame, body axes, rad/s,
            (3,) or (N, 3).
        velocity_enu_mps: ENU velocity of the body origin, m/s, (3,) or (N, 3).
        mounting_rotation_bw: anemometer→body rotation (scipy Rotation or 3x3 matrix).
        anemometer_position_body_m: anemometer measurement centre in the body frame, m, (3,).

    Every per-sample input is either a single value or a batch of the same length N.
    Non-finite values propagate to the output; screening them is the caller's job.
    """
    wind = _as_vectors("wind_sensor_mps", wind_sensor_mps)
    rate = _as_vectors("angular_rate_body_rad_s", angular_rate_body_rad_s)
    velocity = _as_vectors("velocity_enu_mps", velocity_enu_mps)
    attitude = _attitude_matrices(attitude_nb)
    mounting = _mounting_matrix(mounting_rotation_bw)
    lever_arm = np.asarray(anemometer_position_body_m, dtype=float)
    if lever_arm.shape != (3,):
        raise MillerInputError(
            f"anemometer_position_body_m must have shape (3,), got {lever_arm.shape}"
        )

    batch_lengths = {
        name: array.shape[0]
        for name, array, single_ndim in (
            ("wind_sensor_mps", wind, 1),
            ("attitude_nb", attitude, 2),
            ("angular_rate_body_rad_s", rate, 1),
            ("velocity_enu_mps", velocity, 1),
        )
        if array.ndim > single_ndim
    }
    distinct_lengths = {n for n in batch_lengths.values() if n != 1}
    if len(distinct_lengths) > 1:
        raise MillerInputError(f"inputs have different batch lengths: {batch_lengths}")
    single_sample = not batch_lengths
    n_samples = distinct_lengths.pop() if distinct_lengths else 1

    terms = miller_terms(
        np.broadcast_to(wind.reshape(-1, 3), (n_samples, 3)),
        np.broadcast_to(attitude.reshape(-1, 3, 3), (n_samples, 3, 3)),
        np.broadcast_to(rate.reshape(-1, 3), (n_samples, 3)),
        np.broadcast_to(velocity.reshape(-1, 3), (n_samples, 3)),
        mounting,
        lever_arm,
    )
    if single_sample:
        return MillerTerms(*(term[0] for term in terms.arrays()))
    return terms


def miller_terms(
    wind_sensor_mps: np.ndarray,
    attitude_matrix_nb: np.ndarray,
    angular_rate_body_rad_s: np.ndarray,
    velocity_enu_mps: np.ndarray,
    mounting_matrix_bw: np.ndarray,
    anemometer_position_body_m: np.ndarray,
) -> MillerTerms:
    """The arithmetic of :func:`miller_correction` on checked (N, ...) float arrays: wind
    (N, 3) anemometer axes m/s, body→ENU matrices (N, 3, 3), body rate (N, 3) rad/s, ENU
    velocity (N, 3) m/s, anemometer→body matrix (3, 3), anemometer position (3,) body m.

    Runs :func:`miller_components` on the columns.
    """
    terms = miller_components(
        tuple(wind_sensor_mps.T),
        tuple(attitude_matrix_nb.reshape(-1, 9).T),
        tuple(angular_rate_body_rad_s.T),
        tuple(velocity_enu_mps.T),
        tuple(np.asarray(mounting_matrix_bw, dtype=float).ravel().tolist()),
        tuple(np.asarray(anemometer_position_body_m, dtype=float).tolist()),
    )
    return MillerTerms(*(np.stack(term, axis=-1) for term in terms))


def miller_components(
    flow_sensor_mps,
    attitude_elements_nb,
    angular_rate_body_rad_s,
    velocity_enu_mps,
    mounting_elements,
    sensor_position_body_m,
) -> tuple[tuple, tuple, tuple, tuple]:
    """The Miller correction written out by components: the one routine every path runs, live
    on one sample's floats, offline on a recording's columns.

    Args:
        flow_sensor_mps: the fluid's velocity relative to the sensor in the sensor's axes, m/s
            (the anemometer's (u, v, w); the negative of a DVL's water-track velocity).
        attitude_elements_nb: the nine row-major elements of the body→ENU matrix R_nb.
        angular_rate_body_rad_s: body rate relative to the local-level frame, body axes, rad/s.
        velocity_enu_mps: ENU velocity of the body origin, m/s.
        mounting_elements: the nine row-major elements of the sensor→body rotation (R_bw of
            the anemometer, R_bd of the DVL; floats).
        sensor_position_body_m: the lever arm (Miller's B), body axes, m (floats).

    Each per-sample component is a float or an array, all of one shape. Returns the fluid's
    velocity over ground (the true wind, the current) and the tilt, rotation and translation
    terms, ENU m/s, as component triples.
    """
    flow_body = rotate_components(mounting_elements, flow_sensor_mps)
    tilt_term = rotate_components(attitude_elements_nb, flow_body)
    lever_arm_velocity_body = cross_components(angular_rate_body_rad_s, sensor_position_body_m)
    rotation_term = rotate_components(attitude_elements_nb, lever_arm_velocity_body)
    east, north, up = velocity_enu_mps
    translation_term = (east, north, up)
    flow = (
        tilt_term[0] + rotation_term[0] + translation_term[0],
        tilt_term[1] + rotation_term[1] + translation_term[1],
        tilt_term[2] + rotation_term[2] + translation_term[2],
    )
    return flow, tilt_term, rotation_term, translation_term
