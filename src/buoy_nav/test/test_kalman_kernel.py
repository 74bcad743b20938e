"""The compiled covariance arithmetic (buoy_nav.kalman_kernel) against the algebra it stands for,
written independently with numpy, and against identities of the Kalman update."""

import numpy as np
import pytest

from buoy_nav import kalman_kernel
from buoy_nav.rotations import skew

STATES = 15
RELATIVE = 1e-12


def random_covariance(rng, size):
    factor = rng.normal(size=(size, size)) * rng.uniform(1e-3, 1.0, size)
    return factor @ factor.T + 1e-6 * np.eye(size)


def attitude_jacobian():
    jacobian = np.zeros((3, STATES))
    jacobian[:, 0:3] = np.eye(3)
    return jacobian


def dense_jacobian(rng):
    return rng.normal(size=(2, STATES))


def close(actual, expected, relative=RELATIVE):
    scale = np.max(np.abs(expected))
    return np.max(np.abs(actual - expected)) <= relative * scale


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("make_jacobian", [lambda rng: attitude_jacobian(), dense_jacobian])
def test_joseph_update_is_the_joseph_form_with_the_optimal_gain(seed, make_jacobian):
    rng = np.random.default_rng(seed)
    covariance = random_covariance(rng, STATES)
    jacobian = make_jacobian(rng)
    size = jacobian.shape[0]
    noise = random_covariance(rng, size)
    innovation = rng.normal(size=size)

    posterior, correction, positive = kalman_kernel.joseph_update(
        covariance, innovation, jacobian, noise
    )

    s = jacobian @ covariance @ jacobian.T + noise
    gain = np.linalg.solve(s, jacobian @ covariance).T
    i_kh = np.eye(STATES) - gain @ jacobian
    joseph = i_kh @ covariance @ i_kh.T + gain @ noise @ gain.T
    assert positive
    assert close(posterior, joseph)
    assert close(correction, gain @ innovation)
    # With the optimal gain the Joseph form equals the short form (I − K H) P, and the
    # posterior is symmetric and no larger than the prior.
    assert close(posterior, i_kh @ covariance, 1e-9)
    assert np.array_equal(posterior, posterior.T)
    assert np.all(np.diag(posterior) <= np.diag(covariance))


def test_a_stacked_update_equals_the_updates_one_after_the_other():
    rng = np.random.default_rng(7)
    covariance = random_covariance(rng, STATES)
    first, second = attitude_jacobian(), dense_jacobian(rng)
    r1, r2 = random_covariance(rng, 3), random_covariance(rng, 2)
    nu1, nu2 = rng.normal(size=3), rng.normal(size=2)
    stacked_noise = np.zeros((5, 5))
    stacked_noise[:3, :3], stacked_noise[3:, 3:] = r1, r2

    stacked, stacked_correction, _ = kalman_kernel.joseph_update(
        covariance, np.concatenate([nu1, nu2]), np.vstack([first, second]), stacked_noise
    )
    middle, correction1, _ = kalman_kernel.joseph_update(covariance, nu1, first, r1)
    # The second measurement's innovation is taken after the first correction.
    after, correction2, _ = kalman_kernel.joseph_update(
        middle, nu2 - second @ correction1, second, r2
    )

    assert close(stacked, after, 1e-9)
    assert close(stacked_correction, correction1 + correction2, 1e-9)


def test_innovation_test_is_the_normalised_innovation_squared():
    rng = np.random.default_rng(3)
    covariance = random_covariance(rng, STATES)
    jacobian, noise = dense_jacobian(rng), random_covariance(rng, 2)
    innovation = rng.normal(size=2)

    nis, s = kalman_kernel.innovation_test(covariance, innovation, jacobian, noise)

    expected_s = jacobian @ covariance @ jacobian.T + noise
    assert close(s, expected_s)
    assert nis == pytest.approx(innovation @ np.linalg.solve(expected_s, innovation), rel=1e-12)


def test_an_innovation_covariance_not_positive_definite_is_refused():
    rng = np.random.default_rng(4)
    covariance = random_covariance(rng, STATES)
    jacobian = attitude_jacobian()
    noise = -10.0 * np.eye(3) * np.max(covariance)
    innovation = np.ones(3)

    nis, _ = kalman_kernel.innovation_test(covariance, innovation, jacobian, noise)
    posterior, correction, positive = kalman_kernel.joseph_update(
        covariance, innovation, jacobian, noise
    )

    assert np.isnan(nis)
    assert not positive
    assert np.array_equal(posterior, covariance)
    assert not np.any(correction)


def test_attitude_reset_is_g_p_g_transposed():
    rng = np.random.default_rng(5)
    covariance = random_covariance(rng, STATES)
    correction = rng.normal(size=STATES) * 0.05

    reset, positive = kalman_kernel.attitude_reset(covariance, correction, 0)

    g = np.eye(STATES)
    g[0:3, 0:3] += skew(0.5 * correction[0:3])
    assert positive
    assert close(reset, g @ covariance @ g.T)


def test_propagated_is_phi_p_phi_transposed_plus_q():
    rng = np.random.default_rng(6)
    covariance = random_covariance(rng, STATES)
    transition = np.eye(STATES) + 0.1 * rng.normal(size=(STATES, STATES)) * (
        rng.uniform(size=(STATES, STATES)) < 0.3
    )
    noise = random_covariance(rng, STATES) * 1e-3

    propagated = kalman_kernel.propagated(covariance, transition, noise)

    assert close(propagated, transition @ covariance @ transition.T + noise)
    assert np.array_equal(propagated, propagated.T)


def test_positive_definiteness():
    rng = np.random.default_rng(8)
    covariance = random_covariance(rng, STATES)
    indefinite = covariance.copy()
    indefinite[4, 4] = -1.0

    assert kalman_kernel.is_positive_definite(covariance)
    assert not kalman_kernel.is_positive_definite(indefinite)
