"""The IMU screening's steady course in a compiled stretch (:mod:`buoy_nav.imu_stretch`): a raw
sample screened as :meth:`~buoy_nav.imu_input.ImuInput.accept` screens it when nothing is held,
refused, restarted or learnt (:func:`screened`), and the screening's state following an accepted
one (:func:`accepted`), over the arrays laid out below
(:meth:`~buoy_nav.imu_input.ImuInput.steady_screening` fills them).
"""

import math

import numba

from buoy_nav.sequence_kernels import RING_SIZE, ring_add, ring_interval
from buoy_nav.stream_sequence import SEQUENCE_INTERVALS

SAMPLE_SIZE = 7
"""A sample's numbers: stamp (s), ω_ib (body rad/s, 3), specific force (body m/s², 3)."""

# The screening's limits and state (:func:`~buoy_nav.imu_stretch.imu_stretch`'s ``screening`` and
# ``screened_state``,
# :meth:`~buoy_nav.imu_input.ImuInput.steady_screening`): the clock's offset (s), the largest
# squared rate and force, the largest gap (s), the calibration's gyro biases, accelerometer
# biases and scales (none when CALIBRATED is 0.0), the largest angular acceleration and jerk,
# the rate's and force's noise allowances, the learnt sample interval (s) and the exponent of
# the squares (2.0, handed in so that they are the C library's, as the interpreter's ``** 2``);
# the latest accepted stamp, the sequence's latest stamp, the clock's sample interval (s), the
# last accepted sample (stamp s, gyro, force) and, last, the ring of the clock's recent
# intervals the sample interval is taken from (:mod:`buoy_nav.sequence_kernels`).
(CLOCK_OFFSET, MAX_RATE_SQ, MAX_FORCE_SQ, SCREENING_MAX_GAP, CALIBRATED) = range(5)
GYRO_BIAS, ACCEL_BIAS, ACCEL_SCALE = 5, 8, 11
(MAX_ANGULAR_ACCELERATION, MAX_JERK, RATE_NOISE, FORCE_NOISE, SAMPLE_INTERVAL) = range(14, 19)
SQUARE = 19
SCREENING_SIZE = 20
LATEST, SEQUENCE_LAST, CLOCK_INTERVAL, LAST_SAMPLE, CLOCK_RING = 0, 1, 2, 3, 10
SCREENED_STATE_SIZE = CLOCK_RING + RING_SIZE


@numba.njit(cache=True)
def screened(raw_sample, screening, screened_state, sample) -> bool:
    """Whether :meth:`~buoy_nav.imu_input.ImuInput.accept` would accept ``raw_sample`` as the
    next sample of the sequence with nothing else to do (nothing held, refused, restarted or
    learnt); ``sample`` then holds it re-stamped and calibrated. Nothing else is changed."""
    t = raw_sample[0]
    stamp = t + screening[CLOCK_OFFSET]
    latest = screened_state[LATEST]
    sequence_last = screened_state[SEQUENCE_LAST]
    if not (
        stamp > latest
        and (
            stamp == sequence_last
            or (
                stamp > sequence_last
                and not stamp - sequence_last > SEQUENCE_INTERVALS * screened_state[CLOCK_INTERVAL]
            )
        )
    ):
        return False
    gx, gy, gz, fx, fy, fz = raw_sample[1:7]
    if not (math.isfinite(t) and math.isfinite(gx + gy + gz) and math.isfinite(fx + fy + fz)):
        return False
    if screening[CALIBRATED] != 0.0:
        gx = gx - screening[GYRO_BIAS]
        gy = gy - screening[GYRO_BIAS + 1]
        gz = gz - screening[GYRO_BIAS + 2]
        fx = (fx - screening[ACCEL_BIAS]) / screening[ACCEL_SCALE]
        fy = (fy - screening[ACCEL_BIAS + 1]) / screening[ACCEL_SCALE + 1]
        fz = (fz - screening[ACCEL_BIAS + 2]) / screening[ACCEL_SCALE + 2]
    if (
        gx * gx + gy * gy + gz * gz > screening[MAX_RATE_SQ]
        or fx * fx + fy * fy + fz * fz > screening[MAX_FORCE_SQ]
    ):
        return False
    if stamp - latest > screening[SCREENING_MAX_GAP]:
        return False
    last = screened_state[LAST_SAMPLE : LAST_SAMPLE + SAMPLE_SIZE]
    dt = stamp - last[0]
    if dt > 0.0 and dt < screening[SAMPLE_INTERVAL]:
        return False
    square = screening[SQUARE]
    rate_bound = screening[MAX_ANGULAR_ACCELERATION] * dt + screening[RATE_NOISE]
    force_bound = screening[MAX_JERK] * dt + screening[FORCE_NOISE]
    if (
        math.pow(gx - last[1], square)
        + math.pow(gy - last[2], square)
        + math.pow(gz - last[3], square)
        > rate_bound * rate_bound
        or math.pow(fx - last[4], square)
        + math.pow(fy - last[5], square)
        + math.pow(fz - last[6], square)
        > force_bound * force_bound
    ):
        return False
    sample[0] = stamp
    sample[1] = gx
    sample[2] = gy
    sample[3] = gz
    sample[4] = fx
    sample[5] = fy
    sample[6] = fz
    return True


@numba.njit(cache=True)
def accepted(screening, screened_state, sample) -> None:
    """The screened ``sample`` accepted: the screening's state follows it (the sequence, the
    clock's sample interval, the last accepted sample)."""
    stamp = sample[0]
    dt = stamp - screened_state[LATEST]
    if dt <= screening[SCREENING_MAX_GAP] and not dt > (
        SEQUENCE_INTERVALS * screened_state[CLOCK_INTERVAL]
    ):
        ring = screened_state[CLOCK_RING:]
        ring_add(ring, dt)
        screened_state[CLOCK_INTERVAL] = ring_interval(ring)
    screened_state[LATEST] = stamp
    screened_state[SEQUENCE_LAST] = stamp
    screened_state[LAST_SAMPLE : LAST_SAMPLE + SAMPLE_SIZE] = sample
