"""The named flux tests on synthetic surface layers of known covariances: each test passes a
window built to the surface layer's similarity relations and flags one built to break the one
relation it judges; the overall flag is the worst of them."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from buoy_common.contract import QualityFlag
from wind_comp.flux_products import DEFAULT_QUALITY_LIMITS, FluxAverager, FluxProduct
from wind_comp.flux_quality import (
    AIR_KINEMATIC_VISCOSITY_M2_S,
    FLUX_FLAG_TESTS,
    GRAVITY_MPS2,
    VON_KARMAN,
    FluxQualityLimits,
    itc_sigma_w_model,
    neutral_drag_coefficient_10m,
    worst_flag,
)
from wind_comp.fluxes import FluxError

RATE_HZ = 10.0
WINDOW_S = 1800.0
START_S = 1_767_225_600.0


@dataclasses.dataclass(frozen=True)
class SurfaceLayer:
    """Streamwise turbulence of a marine surface layer: mean speed U, friction velocity u*,
    the stress's angle off the mean wind, σu, σv, σw as multiples of u*, and the sonic
    temperature's σT and correlation with w."""

    speed_mps: float = 10.0
    friction_velocity_mps: float = 0.36
    stress_angle_deg: float = 0.0
    sigma_ratios: tuple[float, float, float] = (2.4, 1.9, 1.25)
    sigma_t_k: float = 0.1
    w_t_correlation: float = 0.3

    def covariance(self) -> np.ndarray:
        sigma_u, sigma_v, sigma_w = np.multiply(self.sigma_ratios, self.friction_velocity_mps)
        stress = self.friction_velocity_mps**2
        angle = math.radians(self.stress_angle_deg)
        u_w, v_w = -stress * math.cos(angle), -stress * math.sin(angle)
        w_t = self.w_t_correlation * sigma_w * self.sigma_t_k
        return np.array(
            [
                [sigma_u**2, 0.0, u_w, 0.0],
                [0.0, sigma_v**2, v_w, 0.0],
                [u_w, v_w, sigma_w**2, w_t],
                [0.0, 0.0, w_t, self.sigma_t_k**2],
            ]
        )


def window_of(
    layer: SurfaceLayer,
    seed: int = 1,
    temperature: bool = True,
    limits: FluxQualityLimits = DEFAULT_QUALITY_LIMITS,
) -> FluxProduct:
    """The flux product of one 30-min window of ``layer``, the mean wind from 300°."""
    rng = np.random.default_rng(seed)
    samples = int(WINDOW_S * RATE_HZ)
    fluctuations = rng.multivariate_normal(np.zeros(4), layer.covariance(), size=samples)
    streamwise = fluctuations[:, :3] + [layer.speed_mps, 0.0, 0.0]
    wind = Rotation.from_euler("Z", 150.0, degrees=True).apply(streamwise)
    t = START_S + np.arange(samples) / RATE_HZ
    averager = FluxAverager(WINDOW_S, quality_limits=limits)
    if temperature:
        for stamp, value in zip(t, 18.0 + fluctuations[:, 3], strict=True):
            averager.add_temperature(stamp, value)
    (product,) = averager.add_batch(t, wind) + averager.flush()
    return product


def flags(product: FluxProduct) -> dict[str, int]:
    return {test.name: getattr(product, test.field) for test in FLUX_FLAG_TESTS}


def neutral(speed_mps: float) -> SurfaceLayer:
    """A neutral surface layer carrying the COARE 3.5 stress at ``speed_mps``."""
    u_star = speed_mps * math.sqrt(neutral_drag_coefficient_10m(speed_mps))
    return SurfaceLayer(speed_mps=speed_mps, friction_velocity_mps=u_star)


def test_every_test_has_its_field_and_every_flag_field_its_test():
    flag_fields = [f.name for f in dataclasses.fields(FluxProduct) if f.name.endswith("_flag")]
    assert flag_fields == ["quality_flag", *(test.field for test in FLUX_FLAG_TESTS)]


def test_coare_drag_coefficient_follows_the_log_law_of_its_own_roughness():
    for speed in (3.0, 8.0, 15.0, 25.0):
        drag = neutral_drag_coefficient_10m(speed)
        u_star = speed * math.sqrt(drag)
        charnock = max(0.0017 * min(speed, 19.0) - 0.005, 0.0)
        roughness = (
            charnock * u_star**2 / GRAVITY_MPS2 + 0.11 * AIR_KINEMATIC_VISCOSITY_M2_S / u_star
        )
        assert math.isclose(speed, u_star / VON_KARMAN * math.log(10.0 / roughness), rel_tol=1e-9)
    # rougher seas in stronger winds: C_D rises with the wind above the smooth-flow regime
    drags = [neutral_drag_coefficient_10m(speed) for speed in (6.0, 10.0, 15.0, 20.0)]
    assert drags == sorted(drags) and 0.8e-3 < drags[0] < drags[-1] < 3e-3


def test_a_neutral_surface_layer_passes_every_test():
    # without a platform velocity (a buoy that does not move) there is no motion to leave
    for seed, speed in ((2, 6.0), (3, 10.0), (4, 16.0)):
        product = window_of(neutral(speed), seed)
        result = flags(product)
        assert result.pop("motion_left") == QualityFlag.NOT_EVALUATED
        assert set(result.values()) == {QualityFlag.GOOD}, result
        assert product.quality_flag == QualityFlag.GOOD
        assert math.isclose(product.drag_coefficient / product.drag_coefficient_neutral_10m, 1.0,
                            abs_tol=0.15)  # fmt: skip
        assert product.itc_w_deviation_percent < 10.0


def test_a_stress_beyond_ten_times_the_bulk_relation_fails_the_drag_coefficient():
    # twelve times COARE's stress at 10 m/s, carried by turbulence whose σw/u* stays near the
    # surface layer's (σu/u* 1.2, r_uw = -0.88): only the drag coefficient can tell
    bulk = neutral(10.0)
    layer = dataclasses.replace(
        bulk,
        friction_velocity_mps=math.sqrt(12.0) * bulk.friction_velocity_mps,
        sigma_ratios=(1.2, 1.9, 0.95),
    )
    product = window_of(layer, seed=5)
    result = flags(product)
    assert math.isclose(
        product.drag_coefficient / product.drag_coefficient_neutral_10m, 12.0, rel_tol=0.1
    )
    assert result["drag_coefficient"] == QualityFlag.BAD
    assert result["itc"] == QualityFlag.GOOD  # 0.95 against 1.25: within 30 %
    assert product.quality_flag == QualityFlag.BAD
    # four times the bulk stress: suspect
    layer = dataclasses.replace(
        layer, friction_velocity_mps=math.sqrt(4.0) * bulk.friction_velocity_mps
    )
    assert flags(window_of(layer, seed=5))["drag_coefficient"] == QualityFlag.SUSPECT


def test_too_little_stress_for_the_turbulence_fails_the_itc_test():
    # σw three times the surface layer's for its u*: a deviation of 200 %
    layer = dataclasses.replace(neutral(10.0), sigma_ratios=(2.4, 1.9, 3 * 1.25))
    product = window_of(layer, seed=6)
    assert math.isclose(product.itc_w_deviation_percent, 200.0, abs_tol=15.0)
    assert flags(product)["itc"] == QualityFlag.BAD
    assert product.quality_flag == QualityFlag.BAD


@pytest.mark.parametrize(
    ("angle_deg", "expected"),
    [(20.0, QualityFlag.GOOD), (55.0, QualityFlag.SUSPECT), (70.0, QualityFlag.BAD)],
)
def test_a_stress_turned_off_the_mean_wind_is_suspect_then_failed(angle_deg, expected):
    product = window_of(dataclasses.replace(neutral(10.0), stress_angle_deg=angle_deg), seed=7)
    assert math.isclose(
        product.cross_wind_stress_ratio, math.tan(math.radians(angle_deg)), rel_tol=0.15
    )
    assert math.isclose(
        math.hypot(product.stress_along_n_m2, product.stress_cross_n_m2),
        product.stress_n_m2,
        rel_tol=1e-9,
    )
    assert flags(product)["cross_wind_stress"] == expected


def test_no_stress_leaves_the_cross_wind_test_not_evaluated():
    calm = SurfaceLayer(speed_mps=1.5, friction_velocity_mps=0.02, stress_angle_deg=80.0)
    result = flags(window_of(calm, seed=8))
    assert result["cross_wind_stress"] == QualityFlag.NOT_EVALUATED
    assert result["drag_coefficient"] == QualityFlag.NOT_EVALUATED


@pytest.mark.parametrize(
    ("correlation", "expected"),
    [(0.4, QualityFlag.GOOD), (0.8, QualityFlag.SUSPECT), (0.93, QualityFlag.BAD)],
)
def test_a_buoyancy_flux_too_well_correlated_with_w_is_flagged(correlation, expected):
    layer = dataclasses.replace(neutral(10.0), w_t_correlation=correlation, sigma_t_k=0.05)
    product = window_of(layer, seed=9)
    assert math.isclose(product.w_ts_correlation, correlation, abs_tol=0.02)
    assert flags(product)["buoyancy_flux"] == expected


def test_an_implausible_temperature_scale_fails_the_buoyancy_flux():
    # σT 3 K correlated at 0.5 with w: T* = 0.5·σw·σT/u* = 0.5·1.25·3 = 1.9 K, suspect
    layer = dataclasses.replace(neutral(10.0), w_t_correlation=-0.5, sigma_t_k=3.0)
    product = window_of(layer, seed=10)
    assert math.isclose(product.temperature_scale_k, 0.5 * 1.25 * 3.0, rel_tol=0.1)
    assert flags(product)["buoyancy_flux"] == QualityFlag.SUSPECT


def test_without_a_sonic_temperature_the_buoyancy_flux_is_not_evaluated():
    product = window_of(neutral(10.0), seed=11, temperature=False)
    assert flags(product)["buoyancy_flux"] == QualityFlag.NOT_EVALUATED
    assert math.isnan(product.obukhov_stability)
    assert product.quality_flag == QualityFlag.GOOD


def test_stability_enters_the_itc_model_when_the_height_is_known():
    # an unstable layer, w'T' > 0: z/L = -z κ g w'T' / (u*³ T) < 0
    layer = dataclasses.replace(neutral(6.0), w_t_correlation=0.5, sigma_t_k=0.3)
    product = window_of(layer, seed=12, limits=FluxQualityLimits(measurement_height_m=5.0))
    expected = (
        -5.0 * VON_KARMAN * GRAVITY_MPS2 * product.w_ts_k_mps
        / (product.friction_velocity_mps**3 * (18.0 + 273.15))
    )  # fmt: skip
    assert product.obukhov_stability < 0.0
    assert math.isclose(product.obukhov_stability, expected, rel_tol=1e-3)
    model = itc_sigma_w_model(product.obukhov_stability)
    assert model > itc_sigma_w_model(math.nan)
    measured = product.sigma_w_mps / product.friction_velocity_mps
    assert math.isclose(
        product.itc_w_deviation_percent, 100 * abs(measured - model) / model, rel_tol=1e-9
    )


def test_an_empty_window_is_missing_in_every_test():
    averager = FluxAverager(WINDOW_S)
    t = START_S + np.arange(100) / RATE_HZ
    (product,) = averager.add_batch(t, np.full((100, 3), np.nan)) + averager.flush()
    assert set(flags(product).values()) == {QualityFlag.MISSING}
    assert product.quality_flag == QualityFlag.MISSING


def test_the_overall_flag_is_the_worst_in_qartod_precedence():
    good, unknown, suspect, bad = (QualityFlag.GOOD, QualityFlag.NOT_EVALUATED,
                                   QualityFlag.SUSPECT, QualityFlag.BAD)  # fmt: skip
    assert worst_flag([good, unknown]) == good
    assert worst_flag([unknown, unknown]) == unknown
    assert worst_flag([good, suspect, unknown]) == suspect
    assert worst_flag([suspect, bad, good]) == bad


def test_thresholds_out_of_order_are_refused():
    with pytest.raises(FluxError, match="stationarity suspect threshold"):
        FluxQualityLimits(stationarity_suspect_percent=120.0)
    with pytest.raises(FluxError, match="must hold its reference"):
        FluxQualityLimits(drag_suspect_below_factor=1.5)
