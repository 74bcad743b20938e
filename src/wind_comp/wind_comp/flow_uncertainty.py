"""Uncertainty of a motion-corrected flow sample (the true wind, or the current).

With the Miller correction V = R_nb·(R_bw·V_w + ω×B) + V_b (:mod:`wind_comp.miller`) and the
navigation's errors defined as R_nb = (I + [δθ×])·R̂_nb (δθ a small rotation about the ENU
axes), δV_b (ENU velocity) and δω (body rate), the first-order error of a corrected sample is

    δV = −[a×]·δθ  +  δV_b  −  R̂_nb·[B×]·δω  +  R̂_nb·R_bw·δV_w,      a = R̂_nb·(R_bw·V_w + ω̂×B)

The sensor's own noise δV_w is independent of the navigation, so its covariance adds. The three
navigation terms are correlated through the filter (a tilt error and a velocity error grow
together from the same specific force), and the navigation messages carry each block on its own
(``nav/odometry``: the attitude block of the pose covariance, the body velocity and rate blocks
of the twist covariance) but not their cross-covariances. Their sum is therefore bounded by the
rule that holds for every correlation: for terms of covariance A_i and any weights w_i > 0 with
Σ w_i = 1, Cov(Σ e_i) ≼ Σ A_i / w_i. The weights w_i ∝ √tr(A_i) make the bound's trace the
smallest, (Σ √tr A_i)². When one term dominates, as on most sensor sets, the bound is that term;
when k terms are equal it is at most k times their sum of variances, never less than the truth.
"""

from typing import NamedTuple

import numpy as np

_TRACE_FLOOR = 1e-300
"""Below this a term's trace counts as zero (it gets no weight and adds nothing)."""


def skew_matrices(vectors: np.ndarray) -> np.ndarray:
    """(N, 3, 3) cross-product matrices [v×] of (N, 3) vectors (so that [v×]·u = v × u)."""
    # Element by element: a few microseconds for the one sample the live node corrects.
    v = np.asarray(vectors, dtype=float)
    skew = np.zeros((*v.shape[:-1], 3, 3))
    skew[..., 0, 1], skew[..., 0, 2] = -v[..., 2], v[..., 1]
    skew[..., 1, 0], skew[..., 1, 2] = v[..., 2], -v[..., 0]
    skew[..., 2, 0], skew[..., 2, 1] = -v[..., 1], v[..., 0]
    return skew


def sandwich(jacobians: np.ndarray, covariances: np.ndarray) -> np.ndarray:
    """J·P·Jᵀ for (N, 3, 3) Jacobians and (N, 3, 3) or (3, 3) covariances."""
    return jacobians @ covariances @ np.swapaxes(jacobians, -1, -2)


def bound_of_correlated_sum(terms) -> np.ndarray:
    """A covariance no smaller than that of a sum of errors whose covariances are ``terms``
    (K of them along the first axis, (K, ..., 3, 3), or a list of K (..., 3, 3)), whatever
    their cross-covariances: Σ A_i / w_i with w_i ∝ √tr(A_i)."""
    terms = np.asarray(terms, dtype=float)
    roots = np.sqrt(np.maximum(np.trace(terms, axis1=-2, axis2=-1), 0.0))
    total_root = np.sum(roots, axis=0)
    # A_i / w_i = A_i · Σ√tr / √tr_i; a term of zero trace is the zero matrix.
    scale = np.where(roots > _TRACE_FLOOR, total_root / np.maximum(roots, _TRACE_FLOOR), 0.0)
    return np.sum(terms * scale[..., None, None], axis=0)


class FlowCovariance(NamedTuple):
    """Covariance of corrected flow samples, ENU, m²/s², (N, 3, 3) each: the navigation's part
    (correlated from sample to sample over the filter's time constants) and the sensor's
    noise (independent from sample to sample)."""

    navigation: np.ndarray
    sensor: np.ndarray

    @property
    def total(self) -> np.ndarray:
        return self.navigation + self.sensor


def corrected_flow_covariance_enu(
    rotation_nb: np.ndarray,
    mounting_rotation_bs: np.ndarray,
    lever_arm_body_m: np.ndarray,
    flow_sensor_mps: np.ndarray,
    angular_rate_body_rad_s: np.ndarray,
    attitude_covariance_enu_rad2: np.ndarray,
    velocity_covariance_enu_m2s2: np.ndarray,
    angular_rate_covariance_body_rad2s2: np.ndarray,
    sensor_noise_covariance_m2s2: np.ndarray,
) -> FlowCovariance:
    """Covariance (m²/s², ENU) of N motion-corrected flow samples.

    Args:
        rotation_nb: (N, 3, 3) estimated body→ENU rotations.
        mounting_rotation_bs: (3, 3) sensor-axes→body rotation (R_bw, R_bd).
        lever_arm_body_m: (3,) the sensor's measurement centre in ``base_link``, m.
        flow_sensor_mps: (N, 3) the fluid's velocity relative to the sensor, its axes, m/s.
        angular_rate_body_rad_s: (N, 3) estimated body rate, body axes, rad/s.
        attitude_covariance_enu_rad2: (N, 3, 3) attitude error as a rotation about the ENU
            axes, rad².
        velocity_covariance_enu_m2s2: (N, 3, 3) ENU velocity error of the body origin, m²/s².
        angular_rate_covariance_body_rad2s2: (N, 3, 3) body rate error, body axes, rad²/s².
        sensor_noise_covariance_m2s2: (3, 3) the sensor's noise in its own axes, m²/s².
    """
    rotation_nb = np.asarray(rotation_nb, dtype=float)
    mounting = np.asarray(mounting_rotation_bs, dtype=float)
    lever_arm = np.asarray(lever_arm_body_m, dtype=float)
    # Not flows @ mountingᵀ: a matrix product of (N, 3) rows may sum in another order for
    # N = 1 than for a batch, and the live node corrects one sample at a time.
    flow_body = np.einsum("ij,nj->ni", mounting, np.asarray(flow_sensor_mps, dtype=float))
    rotation_velocity_body = np.einsum(
        "nij,j->ni", skew_matrices(angular_rate_body_rad_s), lever_arm
    )  # ω × B
    relative_enu = np.einsum("nij,nj->ni", rotation_nb, flow_body + rotation_velocity_body)
    attitude_term = sandwich(skew_matrices(relative_enu), attitude_covariance_enu_rad2)
    rate_jacobian = rotation_nb @ skew_matrices(np.broadcast_to(lever_arm, relative_enu.shape))
    rate_term = sandwich(rate_jacobian, angular_rate_covariance_body_rad2s2)
    navigation = bound_of_correlated_sum(
        [attitude_term, np.asarray(velocity_covariance_enu_m2s2, dtype=float), rate_term]
    )
    sensor_jacobian = rotation_nb @ mounting
    return FlowCovariance(navigation, sandwich(sensor_jacobian, sensor_noise_covariance_m2s2))


def window_mean_covariance_enu(covariance: FlowCovariance) -> np.ndarray:
    """(3, 3) covariance (m²/s², ENU) of the mean of the N samples of ``covariance``.

    Not the samples' covariance over N: the navigation's errors stay alike over the filter's
    time constants (a heading error of minutes, a velocity error through a GNSS outage), so
    its part is bounded as a sum of errors of unknown correlation; the sensor's noise averages
    down as independent noise does.
    """
    n = covariance.navigation.shape[0]
    if n == 0:
        return np.full((3, 3), np.nan)
    navigation = bound_of_correlated_sum(covariance.navigation) / n**2
    return navigation + np.sum(covariance.sensor, axis=0) / n**2


def horizontal_and_vertical_sigma(covariance_enu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) 1σ of the horizontal vector error (√(σ_E² + σ_N²)) and of the vertical component,
    from (N, 3, 3) ENU covariances in m²/s²: m/s."""
    covariance_enu = np.asarray(covariance_enu, dtype=float)
    horizontal = np.sqrt(covariance_enu[..., 0, 0] + covariance_enu[..., 1, 1])
    return horizontal, np.sqrt(covariance_enu[..., 2, 2])
