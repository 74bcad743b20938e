"""The fixed-interval smoother on the independent simulator: consistent and more accurate.

Over independent seeds, the smoothed attitude and velocity errors normalised by the
smoothed covariance (NEES) are chi-square with 3 degrees of freedom per run at fixed times
inside the recording; and the smoothed solution is closer to the truth than the forward one.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_nav_simulated import (
    attitude_nees,
    chi_square_mean_bounds,
    euler_errors_deg,
    simulate_smoothed,
    velocity_nees,
)

SEEDS = range(300, 308)
DURATION_S = 80.0
# Inside the recording: at its end the smoothed solution is the forward one.
CHECKPOINTS_S = (20.0, 40.0, 60.0)


@pytest.fixture(scope="module")
def runs():
    return [simulate_smoothed("sea_state", duration_s=DURATION_S, seed=seed) for seed in SEEDS]


@pytest.mark.parametrize("nees_of", [attitude_nees, velocity_nees], ids=["attitude", "velocity"])
def test_smoothed_nees_is_chi_square_over_seeds(runs, nees_of):
    low, high = chi_square_mean_bounds(3, len(runs))
    for checkpoint in CHECKPOINTS_S:
        nees = []
        for _, forward, smoothed, truth in runs:
            stamps = np.array([s.t_s for s in forward])
            index = int(np.argmin(np.abs(stamps - checkpoint)))
            nees.append(nees_of(smoothed, truth)[index])
        assert low <= np.mean(nees) <= high, (checkpoint, nees)


def test_smoothed_attitude_and_velocity_are_closer_to_the_truth(runs):
    """Pooled over the seeds, after 20 s of convergence: the smoothed attitude and velocity
    RMS errors are below the forward filter's on every axis."""
    forward_attitude, smoothed_attitude, forward_velocity, smoothed_velocity = [], [], [], []
    for _, forward, smoothed, truth in runs:
        stamps = np.array([s.t_s for s in forward])
        converged = stamps >= 20.0
        forward_attitude.append(euler_errors_deg(forward, truth)[converged])
        smoothed_attitude.append(euler_errors_deg(smoothed, truth)[converged])
        truth_velocity = truth.velocity_enu_mps[converged]
        forward_velocity.append(
            np.array([s.velocity_enu_mps for s in forward])[converged] - truth_velocity
        )
        smoothed_velocity.append(
            np.array([s.velocity_enu_mps for s in smoothed])[converged] - truth_velocity
        )

    def rms(errors):
        return np.sqrt(np.mean(np.concatenate(errors) ** 2, axis=0))

    assert np.all(rms(smoothed_attitude) < rms(forward_attitude))
    assert np.all(rms(smoothed_velocity) < rms(forward_velocity))


def test_smoothed_solution_is_the_forward_one_at_the_end(runs):
    """No measurement follows the last epoch: there the smoothed state is the filtered one."""
    _, forward, smoothed, _ = runs[0]
    last_forward, last_smoothed = forward[-1], smoothed[-1]
    rotation = Rotation.from_quat(last_forward.attitude_xyzw)
    difference = Rotation.from_quat(last_smoothed.attitude_xyzw) * rotation.inv()
    assert difference.magnitude() < 1e-6
    np.testing.assert_allclose(
        last_smoothed.velocity_enu_mps, last_forward.velocity_enu_mps, atol=1e-5
    )
