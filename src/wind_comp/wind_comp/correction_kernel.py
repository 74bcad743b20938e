"""The compiled correction of the samples the navigation brackets: each one's Miller terms
(:func:`wind_comp.miller.miller_components`, the one routine, compiled) and its covariance
(:func:`wind_comp.flow_covariance_kernel.sample_covariance`), from the interpolated navigation.

One compiled loop over the samples (numba, cached on disk): the live node corrects one sample
per message, where numpy's cost per call on a row of three values, not the arithmetic, was the
cost. The arithmetic is the same operations on the same floats as the component-wise numpy
code, so one sample alone, a batch, and that code agree to the bit.
"""

import numba
import numpy as np
from numba.extending import register_jitable

from buoy_nav.rotations import cross_components, rotation_matrix_elements
from wind_comp.flow_covariance_kernel import sample_covariance
from wind_comp.miller import miller_components, rotate_components

# The component-wise routines, callable from compiled code as they are; registered here so that
# only what imports this module imports numba. numba's cache of a compiled function follows its
# own file only: a change of a routine it calls from another file needs the cache (*.nbi, *.nbc
# in __pycache__) removed.
for _routine in (rotation_matrix_elements, cross_components, rotate_components, miller_components):
    register_jitable(_routine)

FLOW, TILT, ROTATION, TRANSLATION = range(4)
"""Rows of the terms array: the corrected flow and its three Miller terms."""
NAVIGATION, SENSOR = range(2)
"""Rows of the covariances array: the navigation's part and the sensor noise's."""


@numba.njit(cache=True)
def correct_samples(
    quats_xyzw,
    rates_body_rad_s,
    velocities_enu_mps,
    attitude_covariances_enu_rad2,
    velocity_covariances_enu_m2s2,
    rate_covariances_body_rad2s2,
    flows_sensor_mps,
    noise_covariances_m2s2,
    mounting_bs,
    mounting_elements,
    lever_arm_elements_body_m,
    terms_out,
    covariances_out,
):
    """Correct M samples into ``terms_out`` (4, M, 3: the flow over ground and the tilt,
    rotation and translation terms, ENU m/s) and ``covariances_out`` (2, M, 3, 3: the
    navigation's and the sensor noise's parts, ENU m²/s²).

    Per sample (M rows each): the interpolated navigation (unit body→ENU quaternion xyzw, body
    rate rad/s, ENU velocity m/s and the covariances of the attitude (ENU, rad²), the ENU
    velocity (m²/s²) and the body rate (body, rad²/s²)), the flow relative to the sensor
    (sensor axes, m/s) and its noise covariance (sensor axes, m²/s²). The sensor's mounting
    R_bs as a 3×3 array and as its nine row-major elements, its lever arm as three floats (body
    axes, m)."""
    lever_arm = np.array(lever_arm_elements_body_m)
    rotation = np.empty((3, 3))
    scratch = np.empty((6, 3, 3))
    for n in range(quats_xyzw.shape[0]):
        quat, rate, velocity, flow = (
            quats_xyzw[n],
            rates_body_rad_s[n],
            velocities_enu_mps[n],
            flows_sensor_mps[n],
        )
        elements = rotation_matrix_elements(quat[0], quat[1], quat[2], quat[3])
        for k in range(9):
            rotation[k // 3, k % 3] = elements[k]
        terms = miller_components(
            (flow[0], flow[1], flow[2]),
            elements,
            (rate[0], rate[1], rate[2]),
            (velocity[0], velocity[1], velocity[2]),
            mounting_elements,
            lever_arm_elements_body_m,
        )
        for row in range(4):
            for axis in range(3):
                terms_out[row, n, axis] = terms[row][axis]
        sample_covariance(
            rotation,
            mounting_bs,
            lever_arm,
            flow,
            rate,
            attitude_covariances_enu_rad2[n],
            velocity_covariances_enu_m2s2[n],
            rate_covariances_body_rad2s2[n],
            noise_covariances_m2s2[n],
            scratch,
            covariances_out[NAVIGATION, n],
            covariances_out[SENSOR, n],
        )
