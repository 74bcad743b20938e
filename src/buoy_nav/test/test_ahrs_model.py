"""The motion pack's measurement covariance, computed element by element in compiled code,
is the numpy formula it replaces to the last bit: symmetrised, floored, widened by the lag's
variance and weighted by the samples that share one error."""

import numpy as np

from buoy_nav.aiding.ahrs_attitude import _model_covariance


def _numpy_floored(covariance, floor):
    symmetric = 0.5 * (covariance + covariance.T)
    np.fill_diagonal(symmetric, np.maximum(np.diag(symmetric), floor))
    return symmetric


def test_model_covariance_is_the_numpy_formula_bit_for_bit():
    generator = np.random.default_rng(7)
    for _ in range(2000):
        covariance = generator.normal(0.0, 1e-4, (3, 3)) * generator.choice([1e-6, 1.0, 1e3])
        np.fill_diagonal(covariance, np.abs(np.diag(covariance)))
        floor = float(generator.choice([0.0, 1e-8, 1e-4, 3e-4]))
        lag_variance = float(generator.choice([0.0, generator.uniform(0.0, 1e-3)]))
        weight = float(generator.choice([1.0, generator.uniform(1.0, 600.0)]))
        expected = (_numpy_floored(covariance, floor) + np.eye(3) * lag_variance) * weight
        computed = _model_covariance(covariance, floor, lag_variance, weight)
        assert computed.tobytes() == expected.tobytes()


def test_variances_below_the_floor_are_raised_to_it():
    covariance = np.diag([1e-9, 2e-4, 5e-5])
    computed = _model_covariance(covariance, 1e-4, 0.0, 1.0)
    assert np.array_equal(np.diag(computed), [1e-4, 2e-4, 1e-4])
