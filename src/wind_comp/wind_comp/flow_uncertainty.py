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

from wind_comp.flow_covariance_kernel import TRACE_FLOOR, flow_covariances_enu


def bound_of_correlated_sum(terms) -> np.ndarray:
    """A covariance no smaller than that of a sum of errors whose covariances are ``terms``
    (K of them along the first axis, (K, ..., 3, 3), or a list of K (..., 3, 3)), whatever
    their cross-covariances: Σ A_i / w_i with w_i ∝ √tr(A_i)."""
    terms = np.asarray(terms, dtype=float)
    roots = np.sqrt(np.maximum(np.trace(terms, axis1=-2, axis2=-1), 0.0))
    total_root = np.sum(roots, axis=0)
    # A_i / w_i = A_i · Σ√tr / √tr_i; a term of zero trace is the zero matrix.
    scale = np.where(roots > TRACE_FLOOR, total_root / np.maximum(roots, TRACE_FLOOR), 0.0)
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
        sensor_noise_covariance_m2s2: (3, 3) the sensor's noise in its own axes, or (N, 3, 3)
            each sample's, m²/s².

    Compiled (:mod:`wind_comp.flow_covariance_kernel`): one sample costs microseconds, and
    each sample's covariance is the same alone or in a batch.
    """
    rotation_nb = np.ascontiguousarray(rotation_nb, dtype=float)
    n_samples = rotation_nb.shape[0]
    navigation = np.empty((n_samples, 3, 3))
    sensor = np.empty((n_samples, 3, 3))
    noise = np.asarray(sensor_noise_covariance_m2s2, dtype=float)
    flow_covariances_enu(
        rotation_nb,
        np.asarray(mounting_rotation_bs, dtype=float),
        np.asarray(lever_arm_body_m, dtype=float),
        np.asarray(flow_sensor_mps, dtype=float),
        np.asarray(angular_rate_body_rad_s, dtype=float),
        np.asarray(attitude_covariance_enu_rad2, dtype=float),
        np.asarray(velocity_covariance_enu_m2s2, dtype=float),
        np.asarray(angular_rate_covariance_body_rad2s2, dtype=float),
        np.broadcast_to(noise, (n_samples, 3, 3)),
        navigation,
        sensor,
    )
    return FlowCovariance(navigation, sensor)


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
