"""Irregular, directionally spread deep-water waves (JONSWAP spectrum) as a sum of components.

The sea surface is elevation(x, t) = sum_k a_k cos(k_k . x - omega_k t + phase_k), with one
frequency and one direction per component (the single-direction-per-frequency method, which
keeps the field Gaussian without the phase locking of a frequency-direction grid). Each
component's frequency is drawn inside its own frequency bin, so the sum never repeats within a
run. The field is evaluated at the buoy's mean position (the horizontal origin of ``map``):
orbital excursions of a few metres are small next to the wavelengths kept here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

STANDARD_GRAVITY_MPS2 = 9.80665
# Frequencies kept, as multiples of the peak frequency: below 0.6 fp the JONSWAP energy is
# negligible, and a buoy a few metres across does not follow waves shorter than about 3 fp.
LOWEST_FREQUENCY_RATIO = 0.6
HIGHEST_FREQUENCY_RATIO = 3.0
_CHUNK = 4096


def depth_decay(angular_frequency_rad_s: ArrayLike, depth_m: ArrayLike) -> np.ndarray:
    """exp(−k d) of linear deep-water waves, k = ω²/g: the ratio of the orbital velocity at
    depth d below the surface to the surface's. (N, K) for (K,) angular frequencies (rad/s) and
    (N,) depths (m); a point above the surface counts as at the surface (ratio 1)."""
    wavenumber = np.asarray(angular_frequency_rad_s, dtype=float) ** 2 / STANDARD_GRAVITY_MPS2
    depth = np.maximum(np.atleast_1d(np.asarray(depth_m, dtype=float)), 0.0)
    return np.exp(-np.outer(depth, wavenumber))


def jonswap_spectral_shape(
    frequency_hz: ArrayLike, peak_frequency_hz: float, peak_enhancement: float
) -> np.ndarray:
    """Unnormalised JONSWAP variance density S(f) (shape only; scale it to the wave height)."""
    f = np.asarray(frequency_hz, dtype=float)
    width = np.where(f <= peak_frequency_hz, 0.07, 0.09)
    peak_shape = np.exp(-((f - peak_frequency_hz) ** 2) / (2.0 * width**2 * peak_frequency_hz**2))
    pierson_moskowitz = f**-5 * np.exp(-1.25 * (peak_frequency_hz / f) ** 4)
    return pierson_moskowitz * peak_enhancement**peak_shape


def sample_cos2s_directions_rad(
    rng: np.random.Generator, count: int, mean_rad: float, spreading_exponent: float
) -> np.ndarray:
    """Directions drawn from D(theta) proportional to cos^(2s)((theta - mean)/2), radians."""
    grid = np.linspace(-np.pi, np.pi, 4001)
    density = np.cos(grid / 2.0) ** (2.0 * spreading_exponent)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(grid))])
    cdf /= cdf[-1]
    return mean_rad + np.interp(rng.uniform(size=count), cdf, grid)


@dataclass(frozen=True)
class WaveSample:
    """Surface quantities at the buoy's mean position; each tuple is (value, d/dt, d²/dt²).

    elevation_m: (N,) surface elevation, m. slope_en: (N,2) surface gradient
    (d elevation/d east, d elevation/d north), dimensionless. orbital_displacement_en_m: (N,2)
    horizontal displacement of a surface particle from its mean position, east/north, m.
    """

    elevation_m: tuple[np.ndarray, np.ndarray, np.ndarray]
    slope_en: tuple[np.ndarray, np.ndarray, np.ndarray]
    orbital_displacement_en_m: tuple[np.ndarray, np.ndarray, np.ndarray]


class WaveField:
    """JONSWAP wave field with cos-2s directional spreading, random phases from an RNG."""

    def __init__(
        self,
        significant_height_m: float,
        peak_period_s: float,
        peak_enhancement: float,
        spreading_exponent: float,
        from_direction_deg: float,
        component_count: int,
        rng: np.random.Generator,
    ):
        """Build the components.

        significant_height_m: Hs = 4 sqrt(m0), m. peak_period_s: Tp, s. peak_enhancement:
        JONSWAP gamma. spreading_exponent: s of cos^(2s). from_direction_deg: mean direction the
        waves come FROM, degrees clockwise from true North. component_count: number of
        sinusoids.
        """
        peak_frequency = 1.0 / peak_period_s
        edges = np.linspace(
            LOWEST_FREQUENCY_RATIO * peak_frequency,
            HIGHEST_FREQUENCY_RATIO * peak_frequency,
            component_count + 1,
        )
        bin_width = np.diff(edges)
        frequencies = edges[:-1] + rng.uniform(size=component_count) * bin_width
        variances = jonswap_spectral_shape(frequencies, peak_frequency, peak_enhancement)
        variances *= bin_width
        variances *= (significant_height_m / 4.0) ** 2 / variances.sum()
        self.amplitudes_m = np.sqrt(2.0 * variances)
        self.angular_frequencies_rad_s = 2.0 * np.pi * frequencies
        toward_azimuth = np.deg2rad(from_direction_deg + 180.0)
        # Azimuths are clockwise from North; ENU east = sin(azimuth), north = cos(azimuth).
        azimuths = sample_cos2s_directions_rad(
            rng, component_count, toward_azimuth, spreading_exponent
        )
        self.propagation_unit_en = np.stack([np.sin(azimuths), np.cos(azimuths)], axis=-1)
        self.wavenumbers_rad_m = self.angular_frequencies_rad_s**2 / STANDARD_GRAVITY_MPS2
        self.phases_rad = rng.uniform(0.0, 2.0 * np.pi, size=component_count)

        a = self.amplitudes_m
        w = self.angular_frequencies_rad_s
        kx, ky = (self.wavenumbers_rad_m[:, None] * self.propagation_unit_en).T
        ux, uy = self.propagation_unit_en.T
        # Columns multiplied by cos(theta) and sin(theta), theta = phase - omega t (at x = 0).
        self._cos_weights = np.stack(
            [a, -a * w**2, a * kx * w, a * ky * w, a * ux * w, a * uy * w], axis=-1
        )
        self._sin_weights = np.stack(
            [
                a * w,
                -a * kx,
                -a * ky,
                a * kx * w**2,
                a * ky * w**2,
                -a * ux,
                -a * uy,
                a * ux * w**2,
                a * uy * w**2,
            ],
            axis=-1,
        )

    def slope_variance(self) -> float:
        """Variance of the surface-slope vector, sigma_east² + sigma_north² (dimensionless)."""
        return float(np.sum(self.amplitudes_m**2 * self.wavenumbers_rad_m**2) / 2.0)

    def evaluate(self, t_s: ArrayLike) -> WaveSample:
        """Surface elevation, slope and orbital displacement (with derivatives) at times t_s."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
        by_cos = np.empty((t.size, self._cos_weights.shape[1]))
        by_sin = np.empty((t.size, self._sin_weights.shape[1]))
        for start in range(0, t.size, _CHUNK):
            theta = self.phases_rad - np.outer(
                t[start : start + _CHUNK], self.angular_frequencies_rad_s
            )
            by_cos[start : start + _CHUNK] = np.cos(theta) @ self._cos_weights
            by_sin[start : start + _CHUNK] = np.sin(theta) @ self._sin_weights
        elevation = (by_cos[:, 0], by_sin[:, 0], by_cos[:, 1])
        slope = (by_sin[:, 1:3], by_cos[:, 2:4], by_sin[:, 3:5])
        displacement = (by_sin[:, 5:7], by_cos[:, 4:6], by_sin[:, 7:9])
        return WaveSample(elevation, slope, displacement)

    def orbital_velocity_enu_mps(self, t_s: ArrayLike, depth_m: ArrayLike) -> np.ndarray:
        """Water velocity of the waves (east, north, up), m/s, (N, 3), at times t_s (s) and
        depths depth_m (m, below the instantaneous surface, one per time) under the buoy's mean
        position: each component's surface orbital velocity times exp(−k d). At depth 0 it is
        the rate of the surface particle's displacement and elevation of :meth:`evaluate`."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
        depth = np.broadcast_to(np.asarray(depth_m, dtype=float), t.shape)
        # Surface particle velocity of component k: a ω (cos θ u_k, sin θ), θ = phase − ω t.
        speed = self.amplitudes_m * self.angular_frequencies_rad_s
        velocity = np.empty((t.size, 3))
        for start in range(0, t.size, _CHUNK):
            rows = slice(start, start + _CHUNK)
            theta = self.phases_rad - np.outer(t[rows], self.angular_frequencies_rad_s)
            at_depth = speed * depth_decay(self.angular_frequencies_rad_s, depth[rows])
            velocity[rows, :2] = (at_depth * np.cos(theta)) @ self.propagation_unit_en
            velocity[rows, 2] = np.sum(at_depth * np.sin(theta), axis=1)
        return velocity
