"""Named quality-control tests of one flux window, IOOS QARTOD style, and the overall flag.

Each test of :data:`FLUX_FLAG_TESTS` looks at one property of a window's fluxes and answers
pass (1), suspect (3), fail (4) or not evaluated (2); a window without fluxes is missing (9) in
every test. The window's ``quality_flag`` is the worst of them (ioos_qc's aggregate: fail over
suspect over pass over not evaluated). Each test's flag is published beside the fluxes as
``<name>_flag``; a new test is one more entry of :data:`FLUX_FLAG_TESTS` (and its field of
:class:`wind_comp.flux_products.FluxProduct`).

The tests:

- ``coverage``: the share of a full window's samples the window holds valid, as for the wind
  products (:func:`wind_comp.products.quality_flag`).
- ``spikes``: suspect when the Vickers and Mahrt (1997) spikes of a component exceed a share of
  the samples.
- ``stationarity``: Foken and Wichura (1996) steady-state test of u'w': the relative difference
  between the window's covariance and the mean of its 5-min sub-windows' covariances; below
  30 % pass, 30–100 % suspect, above 100 % fail (Foken et al. 2004, classes 1–3 / 4–6 / 7–9).
- ``itc``: integral turbulence characteristics (Foken and Wichura 1996; Foken et al. 2004):
  σw/u* against the surface-layer model 1.3·(1 + 2|z/L|)^(1/3), or its neutral value 1.25 when
  z/L is unknown (no measurement height or no sonic temperature); the relative deviation below
  30 % pass, 30–100 % suspect, above 100 % fail. A stress too large for the turbulence carrying
  it (σw/u* far below the model) deviates by at most 100 %: it is suspect here, and the drag
  test tells how implausible it is.
- ``drag_coefficient``: C_D = u*²/U² against the neutral 10-m drag coefficient of COARE 3.5
  at the window's mean speed (:func:`neutral_drag_coefficient_10m`). Suspect outside a generous
  range around it (0.3× to 3×: individual 30-min values scatter by about a factor 2 around the
  bulk relation at moderate winds, Edson et al. 2013), fail above 5×: beyond that scatter, and
  low enough that a tenfold error of the stress over a sea whose drag is 0.7× the bulk
  relation's (as the simulator's surface layer, and as real windows often are) fails. Low
  values are never failed: wind-following swell takes the stress of light winds towards zero
  (Grachev and Fairall 2001). Not evaluated below a minimum speed, where u*²/U² is dominated by
  the free convection's and the sonic's noise. Measurement height: the reference is the 10-m
  value at the speed measured at the sonic's height z; below 10 m the measured C_D(z) exceeds
  C_D10N by (1 + √C_D10N/κ·ln(10/z))² (about +25 % at 4 m), well inside the range.
- ``cross_wind_stress``: |v'w'| against |u'w'| in the frame of the mean wind: suspect when the
  stress turns more than 45° off the mean wind (|v'w'| > |u'w'|), fail beyond 63° (> 2×); not
  evaluated at very low stress, where both are their sampling noise.
- ``buoyancy_flux``: the correlation r_wT = w'Ts'/(σw·σT) of the vertical wind and the sonic
  temperature (surface-layer values stay below ~0.6 in magnitude; above 0.7 suspect, above 0.9
  fail) and the temperature scale T* = −w'Ts'/u* (marine values are tenths of a kelvin at
  most), not evaluated without a sonic temperature (T* also not at very low stress).
- ``motion_left``: the share of the platform's vertical velocity the correction left in w over
  the wave band, where its coherence with w exceeds that of unrelated series
  (:mod:`wind_comp.wave_motion_left`, thresholds ``compensation.motion_left_*``).

Sources: Foken T. and Wichura B. (1996), Agric. For. Meteorol. 78, 83–105; Foken T. et al.
(2004), Handbook of Micrometeorology, ch. 9; Edson J. B. et al. (2013), J. Phys. Oceanogr. 43,
1589–1610 (COARE 3.5); Grachev A. A. and Fairall C. W. (2001), J. Phys. Oceanogr. 31,
1698–1711; Vickers D. and Mahrt L. (1997), J. Atmos. Oceanic Technol. 14, 512–526.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from buoy_common.contract import QualityFlag
from wind_comp.fluxes import FluxError, FluxWindow
from wind_comp.products import quality_flag
from wind_comp.wave_motion_left import NOT_EVALUATED as MOTION_LEFT_NOT_EVALUATED
from wind_comp.wave_motion_left import WaveMotionLeft

VON_KARMAN = 0.4
GRAVITY_MPS2 = 9.81
AIR_KINEMATIC_VISCOSITY_M2_S = 1.5e-5
"""Of air at about 20 °C; it sets the smooth-flow roughness, which matters below ~3 m/s."""
ITC_NEUTRAL_SIGMA_W_OVER_U_STAR = 1.25
CELSIUS_TO_KELVIN = 273.15


@dataclass(frozen=True)
class FluxQualityLimits:
    """The thresholds of the flux tests (the parameters ``compensation.flux_qc_*``)."""

    measurement_height_m: float = math.nan
    """Height of the sonic above the sea, m; NaN: unknown (z/L not computed)."""
    max_spike_share: float = 0.01
    stationarity_suspect_percent: float = 30.0
    stationarity_fail_percent: float = 100.0
    itc_suspect_percent: float = 30.0
    itc_fail_percent: float = 100.0
    drag_min_speed_mps: float = 2.0
    drag_suspect_below_factor: float = 0.3
    drag_suspect_above_factor: float = 3.0
    drag_fail_above_factor: float = 5.0
    min_friction_velocity_mps: float = 0.05
    cross_wind_suspect_ratio: float = 1.0
    cross_wind_fail_ratio: float = 2.0
    w_ts_correlation_suspect: float = 0.7
    w_ts_correlation_fail: float = 0.9
    temperature_scale_suspect_k: float = 0.5
    temperature_scale_fail_k: float = 2.0

    def __post_init__(self):
        pairs = (
            ("stationarity", self.stationarity_suspect_percent, self.stationarity_fail_percent),
            ("itc", self.itc_suspect_percent, self.itc_fail_percent),
            ("drag", self.drag_suspect_above_factor, self.drag_fail_above_factor),
            ("cross-wind", self.cross_wind_suspect_ratio, self.cross_wind_fail_ratio),
            ("w-Ts correlation", self.w_ts_correlation_suspect, self.w_ts_correlation_fail),
            ("T*", self.temperature_scale_suspect_k, self.temperature_scale_fail_k),
        )
        for name, suspect, fail in pairs:
            if not 0.0 < suspect <= fail:
                raise FluxError(
                    f"flux quality control: the {name} suspect threshold ({suspect}) must be "
                    f"positive and at most its fail threshold ({fail})"
                )
        if not 0.0 < self.drag_suspect_below_factor < 1.0 < self.drag_suspect_above_factor:
            raise FluxError(
                "flux quality control: the drag coefficient's range must hold its reference: "
                f"{self.drag_suspect_below_factor} < 1 < {self.drag_suspect_above_factor}"
            )


@dataclass(frozen=True)
class FluxDiagnostics:
    """What the tests judge a window by, published with its fluxes."""

    stress_along_n_m2: float
    """−ρ·u'w': the stress along the mean wind, N/m² (positive: momentum carried down)."""
    stress_cross_n_m2: float
    """−ρ·v'w': the stress across the mean wind (toward its left), N/m²."""
    sigma_w_mps: float
    """Standard deviation of the detrended vertical wind, m/s."""
    sigma_ts_k: float
    """Standard deviation of the detrended sonic temperature, K; NaN without one."""
    obukhov_stability: float
    """z/L, NaN without a measurement height or a sonic temperature."""
    itc_w_deviation_percent: float
    """|σw/u* − model| / model, %."""
    drag_coefficient: float
    """u*²/U² at the sonic's height."""
    drag_coefficient_neutral_10m: float
    """COARE 3.5 neutral 10-m drag coefficient at the window's mean speed."""
    cross_wind_stress_ratio: float
    """|v'w'| / |u'w'|."""
    w_ts_correlation: float
    """w'Ts' / (σw·σT); NaN without a sonic temperature."""
    temperature_scale_k: float
    """T* = −w'Ts'/u*, K; NaN without a sonic temperature."""


@dataclass(frozen=True)
class FluxEvidence:
    """One window as the tests see it."""

    fluxes: FluxWindow
    diagnostics: FluxDiagnostics
    coverage: float
    n_valid: int
    motion_left: WaveMotionLeft = MOTION_LEFT_NOT_EVALUATED
    """The wave motion left in the window's corrected w, judged where it is computed (it needs
    the samples, which the other tests do not)."""


@dataclass(frozen=True)
class FluxFlagTest:
    """A named test: ``evaluate(evidence, limits)`` gives its flag, published as
    ``<name>_flag``; ``meaning`` says what it judges (for the NetCDF attributes)."""

    name: str
    meaning: str
    evaluate: Callable[[FluxEvidence, FluxQualityLimits], QualityFlag]

    @property
    def field(self) -> str:
        return f"{self.name}_flag"


def neutral_drag_coefficient_10m(wind_speed_10m_mps: float) -> float:
    """COARE 3.5 neutral drag coefficient at 10 m for a 10-m neutral wind speed (m/s):
    C_D10N = (κ / ln(10/z0))², z0 = α·u*²/g + 0.11·ν/u*, Charnock α = 0.0017·U − 0.005
    (Edson et al. 2013, eq. 13; U capped at 19 m/s as COARE 3.5 does, α at 0 below 2.9 m/s,
    where the smooth-flow term rules), solved for u* by fixed-point iteration."""
    speed = max(float(wind_speed_10m_mps), 0.1)
    charnock = max(0.0017 * min(speed, 19.0) - 0.005, 0.0)
    friction_velocity = 0.035 * speed
    for _ in range(30):
        roughness_m = (
            charnock * friction_velocity**2 / GRAVITY_MPS2
            + 0.11 * AIR_KINEMATIC_VISCOSITY_M2_S / friction_velocity
        )
        friction_velocity = VON_KARMAN * speed / math.log(10.0 / roughness_m)
    return (friction_velocity / speed) ** 2


def itc_sigma_w_model(obukhov_stability: float) -> float:
    """σw/u* of the surface layer at stability z/L: 1.3·(1 + 2|z/L|)^(1/3) (Foken et al.
    2004), 1.25 when z/L is unknown (NaN)."""
    if not math.isfinite(obukhov_stability):
        return ITC_NEUTRAL_SIGMA_W_OVER_U_STAR
    return 1.3 * (1.0 + 2.0 * abs(obukhov_stability)) ** (1.0 / 3.0)


def obukhov_stability(fluxes: FluxWindow, measurement_height_m: float) -> float:
    """z/L = −z·κ·g·w'Ts' / (u*³·Ts) with the sonic temperature as virtual temperature (K);
    NaN without a height (m) or a temperature."""
    friction_velocity = fluxes.friction_velocity_mps
    temperature_k = fluxes.mean_sonic_temperature_degc + CELSIUS_TO_KELVIN
    if not (math.isfinite(measurement_height_m) and math.isfinite(fluxes.w_ts_k_mps)):
        return math.nan
    if friction_velocity <= 0.0:
        return math.nan
    return (
        -measurement_height_m
        * VON_KARMAN
        * GRAVITY_MPS2
        * fluxes.w_ts_k_mps
        / (friction_velocity**3 * temperature_k)
    )


def _ratio(numerator: float, denominator: float) -> float:
    if denominator == 0.0:
        return math.inf if numerator != 0.0 else math.nan
    return numerator / denominator


def flux_diagnostics(fluxes: FluxWindow, limits: FluxQualityLimits) -> FluxDiagnostics:
    """The values the tests judge ``fluxes`` by."""
    friction_velocity = fluxes.friction_velocity_mps
    stability = obukhov_stability(fluxes, limits.measurement_height_m)
    model = itc_sigma_w_model(stability)
    speed = fluxes.mean_speed_mps
    density = fluxes.air_density_kg_m3
    return FluxDiagnostics(
        stress_along_n_m2=-density * fluxes.u_w_m2_s2,
        stress_cross_n_m2=-density * fluxes.v_w_m2_s2,
        sigma_w_mps=fluxes.sigma_w_mps,
        sigma_ts_k=fluxes.sigma_ts_k,
        obukhov_stability=stability,
        itc_w_deviation_percent=100.0
        * abs(_ratio(fluxes.sigma_w_mps, friction_velocity) - model)
        / model,
        drag_coefficient=_ratio(friction_velocity**2, speed**2),
        drag_coefficient_neutral_10m=neutral_drag_coefficient_10m(speed),
        cross_wind_stress_ratio=_ratio(abs(fluxes.v_w_m2_s2), abs(fluxes.u_w_m2_s2)),
        w_ts_correlation=_ratio(fluxes.w_ts_k_mps, fluxes.sigma_w_mps * fluxes.sigma_ts_k),
        temperature_scale_k=_ratio(-fluxes.w_ts_k_mps, friction_velocity),
    )


def _graded(value: float, suspect_above: float, fail_above: float) -> QualityFlag:
    """Pass up to ``suspect_above``, suspect up to ``fail_above``, fail beyond; NaN is not
    evaluated."""
    if math.isnan(value):
        return QualityFlag.NOT_EVALUATED
    if value > fail_above:
        return QualityFlag.BAD
    if value > suspect_above:
        return QualityFlag.SUSPECT
    return QualityFlag.GOOD


def coverage_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    return quality_flag(evidence.coverage, evidence.n_valid)


def spikes_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    fluxes = evidence.fluxes
    share = max(fluxes.spikes) / max(fluxes.samples, 1)
    return QualityFlag.SUSPECT if share > limits.max_spike_share else QualityFlag.GOOD


def stationarity_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    return _graded(
        evidence.fluxes.stationarity_u_w_percent,
        limits.stationarity_suspect_percent,
        limits.stationarity_fail_percent,
    )


def itc_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    return _graded(
        evidence.diagnostics.itc_w_deviation_percent,
        limits.itc_suspect_percent,
        limits.itc_fail_percent,
    )


def drag_coefficient_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    diagnostics = evidence.diagnostics
    if not evidence.fluxes.mean_speed_mps >= limits.drag_min_speed_mps:
        return QualityFlag.NOT_EVALUATED
    factor = diagnostics.drag_coefficient / diagnostics.drag_coefficient_neutral_10m
    if factor < limits.drag_suspect_below_factor:
        return QualityFlag.SUSPECT
    return _graded(factor, limits.drag_suspect_above_factor, limits.drag_fail_above_factor)


def cross_wind_stress_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    if not evidence.fluxes.friction_velocity_mps >= limits.min_friction_velocity_mps:
        return QualityFlag.NOT_EVALUATED
    return _graded(
        evidence.diagnostics.cross_wind_stress_ratio,
        limits.cross_wind_suspect_ratio,
        limits.cross_wind_fail_ratio,
    )


def buoyancy_flux_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    diagnostics = evidence.diagnostics
    correlation = _graded(
        abs(diagnostics.w_ts_correlation),
        limits.w_ts_correlation_suspect,
        limits.w_ts_correlation_fail,
    )
    if not evidence.fluxes.friction_velocity_mps >= limits.min_friction_velocity_mps:
        return correlation
    scale = _graded(
        abs(diagnostics.temperature_scale_k),
        limits.temperature_scale_suspect_k,
        limits.temperature_scale_fail_k,
    )
    return worst_flag([correlation, scale])


def motion_left_test(evidence: FluxEvidence, limits: FluxQualityLimits) -> QualityFlag:
    return evidence.motion_left.flag


FLUX_FLAG_TESTS = (
    FluxFlagTest(
        "motion_left", "share of the platform's vertical velocity left in w over the wave band, "
        "where coherent beyond noise", motion_left_test,
    ),
    FluxFlagTest("coverage", "share of a full window's samples held valid", coverage_test),
    FluxFlagTest("spikes", "Vickers-Mahrt spikes per component", spikes_test),
    FluxFlagTest(
        "stationarity", "Foken-Wichura steady-state test of u'w' (5-min sub-windows)",
        stationarity_test,
    ),
    FluxFlagTest(
        "itc", "integral turbulence characteristics: sigma_w/u* against the surface-layer "
        "model", itc_test,
    ),
    FluxFlagTest(
        "drag_coefficient", "u*^2/U^2 against the COARE 3.5 neutral 10-m drag coefficient",
        drag_coefficient_test,
    ),
    FluxFlagTest(
        "cross_wind_stress", "|v'w'| against |u'w'| in the frame of the mean wind",
        cross_wind_stress_test,
    ),
    FluxFlagTest(
        "buoyancy_flux", "w'Ts' correlation and temperature scale T*", buoyancy_flux_test
    ),
)  # fmt: skip
"""The tests every flux window gets, in the order of their fields (``motion_left`` first: its
flag was published before the others')."""

_PRECEDENCE = (
    QualityFlag.MISSING,
    QualityFlag.NOT_EVALUATED,
    QualityFlag.GOOD,
    QualityFlag.SUSPECT,
    QualityFlag.BAD,
)


def worst_flag(flags) -> QualityFlag:
    """The aggregate of QARTOD flags as ioos_qc's ``qartod_compare``: fail over suspect over
    pass over not evaluated over missing."""
    return max(flags, key=_PRECEDENCE.index, default=QualityFlag.MISSING)


def flux_flags(evidence: FluxEvidence, limits: FluxQualityLimits) -> dict[str, QualityFlag]:
    """{``<name>_flag``: flag} of every test of :data:`FLUX_FLAG_TESTS`; every one missing for
    a window without fluxes."""
    if not math.isfinite(evidence.fluxes.friction_velocity_mps) or evidence.n_valid == 0:
        return {test.field: QualityFlag.MISSING for test in FLUX_FLAG_TESTS}
    return {test.field: test.evaluate(evidence, limits) for test in FLUX_FLAG_TESTS}
