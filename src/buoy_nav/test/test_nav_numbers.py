"""The compiled numbers of a solution's ``nav/*`` messages: to the bit what the interpreter makes
of the same formulae (numpy's products included), in the layout of the messages' 6×6
covariances, and physically what they say: a rotation keeps a vector's length and a
covariance's trace."""

import numpy as np
import pytest

from buoy_nav import nav_numbers as layout
from buoy_nav.nav_numbers import body_numbers, covariance_numbers, load_compiled_nav_numbers
from buoy_nav.rotations import rotation_matrix_elements

RNG = np.random.default_rng(52)
CASES = 2000


def random_case(writable: bool):
    """A unit quaternion, an ENU velocity (m/s) and four covariances (attitude, velocity,
    position, gyro bias) of the magnitudes a solution carries."""
    quaternion = RNG.normal(size=4)
    quaternion /= np.linalg.norm(quaternion)
    velocity = RNG.normal(scale=2.0, size=3)
    blocks = []
    for scale in (1e-5, 1e-2, 1.0, 1e-9):
        root = RNG.normal(scale=np.sqrt(scale), size=(3, 3))
        blocks.append(root @ root.T)
    blocks = np.array(blocks)
    blocks.setflags(write=writable)
    return quaternion, velocity, tuple(blocks)


def interpreted(quaternion, velocity, blocks):
    """The same numbers as the interpreter forms them: those that turn with the attitude,
    then those of the covariance blocks alone."""
    elements = rotation_matrix_elements(*quaternion.tolist())
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = elements
    rotation = np.array(elements).reshape(3, 3)
    ve, vn, vu = velocity.tolist()
    attitude, velocity_cov, position, gyro_bias = blocks
    body = np.zeros((6, 6))
    body[:3, :3] = rotation.T @ velocity_cov @ rotation
    body[3:, 3:] = gyro_bias
    pose = np.zeros((6, 6))
    pose[:3, :3], pose[3:, 3:] = position, attitude
    enu = np.zeros((6, 6))
    enu[:3, :3] = velocity_cov
    turning = [
        r00 * ve + r10 * vn + r20 * vu,
        r01 * ve + r11 * vn + r21 * vu,
        r02 * ve + r12 * vn + r22 * vu,
        *body.ravel().tolist(),
    ]
    alone = [
        *pose.ravel().tolist(),
        *enu.ravel().tolist(),
        *attitude.ravel().tolist(),
        *position.ravel().tolist(),
        *gyro_bias.ravel().tolist(),
    ]
    return turning, alone


def bits(values) -> list[int]:
    """The values' bit patterns: equal only when equal to the bit, the sign of a zero too."""
    return np.array(values, dtype=float).view(np.int64).tolist()


@pytest.mark.parametrize("writable", [False, True])
def test_every_number_is_the_interpreters_to_the_bit(writable):
    load_compiled_nav_numbers()
    for _ in range(CASES):
        quaternion, velocity, blocks = random_case(writable)
        turning, alone = interpreted(quaternion, velocity, blocks)
        ours = body_numbers(quaternion, velocity, blocks[1], blocks[3])
        assert len(ours) == layout.BODY_NUMBERS
        assert bits(ours) == bits(turning)
        ours = covariance_numbers(*blocks)
        assert len(ours) == layout.COVARIANCE_NUMBERS
        assert bits(ours) == bits(alone)


def test_a_rotation_keeps_the_velocitys_length_and_the_covariances_trace():
    for _ in range(200):
        quaternion, velocity, blocks = random_case(writable=False)
        numbers = np.array(body_numbers(quaternion, velocity, blocks[1], blocks[3]))
        body_velocity = numbers[layout.VELOCITY_BODY : layout.VELOCITY_BODY + 3]
        np.testing.assert_allclose(np.linalg.norm(body_velocity), np.linalg.norm(velocity))
        twist = numbers[layout.BODY_TWIST_COVARIANCE : layout.BODY_TWIST_COVARIANCE + 36]
        body_velocity_cov = twist.reshape(6, 6)[:3, :3]
        np.testing.assert_allclose(np.trace(body_velocity_cov), np.trace(blocks[1]), rtol=1e-12)
        np.testing.assert_allclose(body_velocity_cov, body_velocity_cov.T, rtol=1e-12, atol=0)
        assert np.linalg.eigvalsh(body_velocity_cov).min() > -1e-12 * np.trace(blocks[1])


def test_a_quaternion_of_the_identity_leaves_the_body_frame_the_enu_frame():
    _, velocity, blocks = random_case(writable=False)
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    numbers = np.array(body_numbers(identity, velocity, blocks[1], blocks[3]))
    np.testing.assert_array_equal(numbers[:3], velocity)
    twist = numbers[layout.BODY_TWIST_COVARIANCE : layout.BODY_TWIST_COVARIANCE + 36]
    np.testing.assert_array_equal(twist.reshape(6, 6)[:3, :3], blocks[1])
    np.testing.assert_array_equal(twist.reshape(6, 6)[3:, 3:], blocks[3])
    np.testing.assert_array_equal(twist.reshape(6, 6)[:3, 3:], 0.0)


def test_the_numbers_of_many_solutions_are_each_ones_own():
    """A run without a bag makes the body numbers of a stretch of solutions at once: each row
    is the one solution's, to the bit."""
    cases = [random_case(writable=False) for _ in range(300)]
    quaternions = np.array([quaternion for quaternion, _, _ in cases])
    velocities = np.array([velocity for _, velocity, _ in cases])
    velocity_covariances = np.array([blocks[1] for _, _, blocks in cases])
    gyro_bias_covariances = np.array([blocks[3] for _, _, blocks in cases])
    rows = layout.body_numbers_of_solutions(
        quaternions, velocities, velocity_covariances, gyro_bias_covariances
    )
    assert rows.shape == (len(cases), layout.BODY_NUMBERS)
    for row, (quaternion, velocity, blocks) in zip(rows, cases, strict=True):
        alone = body_numbers(quaternion, velocity, blocks[1], blocks[3])
        assert row.tobytes() == np.array(alone).tobytes()
