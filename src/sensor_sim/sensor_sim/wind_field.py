"""True wind: a mean vector plus Kaimal turbulence built from seeded sinusoids.

The wind is spatially uniform: the buoy's excursions (metres) are small next to the
turbulent length scales over the sea, so every sensor sees the same vector at a given time.
Turbulence is a sum of sinusoids per axis (longitudinal u along the mean wind, lateral v to
its left, vertical w up) whose amplitudes follow the Kaimal spectrum in the IEC 61400-1 form

    f S_k(f) / sigma_k^2 = 4 f L_k / U / (1 + 6 f L_k / U)^(5/3),
    L_u = 8.1 Lambda, L_v = 2.7 Lambda, L_w = 0.66 Lambda, Lambda = 0.7 z (z < 60 m),

so it is evaluable at any time and identical for every node. Frequencies are log-spaced
between 1/record length and the highest frequency asked for, each drawn inside its own bin;
the components are scaled so that each axis carries exactly its variance sigma_k^2.

Fluxes: the along-wind turbulence is mixed with the vertical one, u = sqrt(1 - r^2) u_0 +
r (sigma_u / sigma_w) w, so that u'w' = r sigma_u sigma_w (expected; a record of finite length
holds that within its sampling error) while u keeps its variance. A sonic temperature follows
the same construction with its own sinusoids of the vertical's spectrum shape: T' =
r_T (sigma_T / sigma_w) w + sqrt(1 - r_T^2) T_0, w'T' = r_T sigma_w sigma_T.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

_LENGTH_SCALE_FACTORS = np.array([8.1, 2.7, 0.66])
_CHUNK = 4096


def kaimal_spectrum(
    frequency_hz: ArrayLike, variance: float, length_scale_m: float, mean_speed_mps: float
) -> np.ndarray:
    """One-sided Kaimal variance density S(f), (m/s)²/Hz, IEC 61400-1 form."""
    f = np.asarray(frequency_hz, dtype=float)
    reduced = f * length_scale_m / mean_speed_mps
    return variance * 4.0 * length_scale_m / mean_speed_mps / (1.0 + 6.0 * reduced) ** (5.0 / 3.0)


def kaimal_length_scales_m(height_m: float) -> np.ndarray:
    """Integral length scales (L_u, L_v, L_w), m, at height_m above the sea (IEC 61400-1)."""
    turbulence_scale = 0.7 * min(height_m, 60.0)
    return _LENGTH_SCALE_FACTORS * turbulence_scale


def meteorological_to_enu_unit(from_direction_deg: float) -> np.ndarray:
    """ENU unit vector (east, north, 0) of the direction air moves toward.

    from_direction_deg is meteorological: where the wind blows FROM, clockwise from North.
    """
    from_rad = np.deg2rad(from_direction_deg)
    return np.array([-np.sin(from_rad), -np.cos(from_rad), 0.0])


@dataclass(frozen=True)
class SonicTemperatureConfig:
    """The sonic temperature of a wind field: mean °C, fluctuation 1σ K, its correlation with
    the vertical wind, and the random stream of its own fluctuations."""

    mean_degc: float
    sigma_k: float
    heat_flux_correlation: float
    rng: np.random.Generator


class WindField:
    """Mean wind plus optional Kaimal turbulence, evaluable at arbitrary times."""

    def __init__(
        self,
        speed_mps: float,
        from_direction_deg: float,
        turbulence_intensity: float,
        lateral_intensity_ratio: float,
        vertical_intensity_ratio: float,
        height_m: float,
        component_count: int,
        lowest_frequency_hz: float,
        highest_frequency_hz: float,
        rng: np.random.Generator,
        momentum_flux_correlation: float = 0.0,
        temperature: SonicTemperatureConfig | None = None,
    ):
        """Build the field.

        speed_mps: mean horizontal speed. from_direction_deg: meteorological direction.
        turbulence_intensity: sigma_u / speed (0 disables turbulence). lateral/vertical
        intensity ratios: sigma_v / sigma_u and sigma_w / sigma_u. height_m: anemometer height
        above the sea (sets the length scales). component_count: sinusoids per axis.
        lowest/highest_frequency_hz: band represented. momentum_flux_correlation: of u and w.
        temperature: the sonic temperature, None for none.
        """
        self.momentum_flux_correlation = float(momentum_flux_correlation)
        self.temperature = temperature
        self._temperature_sinusoids = None
        self.mean_enu_mps = speed_mps * meteorological_to_enu_unit(from_direction_deg)
        along = meteorological_to_enu_unit(from_direction_deg)
        left = np.array([-along[1], along[0], 0.0])
        self._axes_enu = np.stack([along, left, np.array([0.0, 0.0, 1.0])])
        sigma_u = turbulence_intensity * speed_mps
        self.sigmas_mps = sigma_u * np.array(
            [1.0, lateral_intensity_ratio, vertical_intensity_ratio]
        )
        if component_count == 0 or not np.any(self.sigmas_mps > 0.0):
            self._angular_frequencies = np.zeros((3, 0))
            self._amplitudes = np.zeros((3, 0))
            self._phases = np.zeros((3, 0))
            return
        edges = np.geomspace(lowest_frequency_hz, highest_frequency_hz, component_count + 1)
        length_scales = kaimal_length_scales_m(height_m)
        frequencies = np.empty((3, component_count))
        amplitudes = np.empty((3, component_count))
        for axis in range(3):
            frequencies[axis] = edges[:-1] + rng.uniform(size=component_count) * np.diff(edges)
            variances = kaimal_spectrum(
                frequencies[axis], 1.0, length_scales[axis], speed_mps
            ) * np.diff(edges)
            variances *= self.sigmas_mps[axis] ** 2 / variances.sum()
            amplitudes[axis] = np.sqrt(2.0 * variances)
        self._angular_frequencies = 2.0 * np.pi * frequencies
        self._amplitudes = amplitudes
        self._phases = rng.uniform(0.0, 2.0 * np.pi, size=(3, component_count))
        if temperature is not None:
            # The temperature's own fluctuations: the vertical's spectrum shape, unit variance.
            temperature_frequencies = edges[:-1] + temperature.rng.uniform(
                size=component_count
            ) * np.diff(edges)
            variances = kaimal_spectrum(
                temperature_frequencies, 1.0, length_scales[2], speed_mps
            ) * np.diff(edges)
            variances /= variances.sum()
            self._temperature_sinusoids = (
                2.0 * np.pi * temperature_frequencies,
                np.sqrt(2.0 * variances),
                temperature.rng.uniform(0.0, 2.0 * np.pi, size=component_count),
            )

    def turbulence_uvw_mps(self, t_s: ArrayLike) -> np.ndarray:
        """Turbulent fluctuations (N,3): longitudinal, lateral (left), vertical, m/s."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
        result = np.zeros((t.size, 3))
        if self._amplitudes.shape[1] == 0:
            return result
        for start in range(0, t.size, _CHUNK):
            block = t[start : start + _CHUNK]
            for axis in range(3):
                phase = np.outer(block, self._angular_frequencies[axis]) + self._phases[axis]
                result[start : start + _CHUNK, axis] = np.cos(phase) @ self._amplitudes[axis]
        correlation = self.momentum_flux_correlation
        if correlation and self.sigmas_mps[2] > 0.0:
            result[:, 0] = (
                math.sqrt(1.0 - correlation**2) * result[:, 0]
                + correlation * self.sigmas_mps[0] / self.sigmas_mps[2] * result[:, 2]
            )
        return result

    def sonic_temperature_degc(self, t_s: ArrayLike) -> np.ndarray | None:
        """The air's sonic temperature (N,), °C, at times t_s; None without one."""
        temperature = self.temperature
        if temperature is None:
            return None
        t = np.atleast_1d(np.asarray(t_s, dtype=float)).ravel()
        own = np.zeros(t.size)
        if self._temperature_sinusoids is not None:
            frequencies, amplitudes, phases = self._temperature_sinusoids
            for start in range(0, t.size, _CHUNK):
                block = t[start : start + _CHUNK]
                own[start : start + _CHUNK] = (
                    np.cos(np.outer(block, frequencies) + phases) @ amplitudes
                )
        correlation = temperature.heat_flux_correlation
        fluctuation = math.sqrt(1.0 - correlation**2) * temperature.sigma_k * own
        if correlation and self.sigmas_mps[2] > 0.0:
            vertical = self.turbulence_uvw_mps(t)[:, 2]
            fluctuation += correlation * temperature.sigma_k / self.sigmas_mps[2] * vertical
        return temperature.mean_degc + fluctuation

    def evaluate_enu_mps(self, t_s: ArrayLike) -> np.ndarray:
        """True wind (N,3), ENU, m/s: air velocity over ground (the direction it moves toward)."""
        return self.mean_enu_mps + self.turbulence_uvw_mps(t_s) @ self._axes_enu
