"""The compiled correction runs the component-wise routines on the same floats: its Miller terms
and covariances equal, to the bit, those of :func:`miller_components` on numpy columns and of
:func:`corrected_flow_covariance_enu`, whether a sample comes alone or in a batch."""

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_nav.rotations import rotation_matrix_elements
from wind_comp.correction_kernel import correct_samples
from wind_comp.flow_uncertainty import corrected_flow_covariance_enu
from wind_comp.miller import miller_components, mounting_rotation_from_rpy_deg

N = 400
MOUNTING = mounting_rotation_from_rpy_deg((2.0, -3.0, 150.0)).as_matrix()
LEVER_ARM_M = (0.2, -0.15, 2.7)


def _inputs(seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)

    def covariances(scale):
        factor = rng.normal(size=(N, 3, 3)) * scale
        return factor @ np.swapaxes(factor, -1, -2)

    return {
        "quats": Rotation.random(N, random_state=seed).as_quat(),
        "rates": rng.normal(size=(N, 3)) * 0.2,
        "velocities": rng.normal(size=(N, 3)),
        "attitude": covariances(1e-3),
        "velocity": covariances(0.05),
        "rate": covariances(1e-3),
        "flows": rng.normal(size=(N, 3)) * 8.0,
        "noises": covariances(0.05),
    }


def _compiled(inputs: dict[str, np.ndarray], rows) -> tuple[np.ndarray, np.ndarray]:
    n = len(range(N)[rows])
    terms, covariances = np.empty((4, n, 3)), np.empty((2, n, 3, 3))
    correct_samples(
        *(np.ascontiguousarray(values[rows]) for values in inputs.values()),
        MOUNTING,
        tuple(MOUNTING.ravel().tolist()),
        LEVER_ARM_M,
        terms,
        covariances,
    )
    return terms, covariances


def test_the_compiled_correction_is_the_component_wise_routines_to_the_bit():
    inputs = _inputs(11)
    terms, covariances = _compiled(inputs, slice(None))
    elements = rotation_matrix_elements(*inputs["quats"].T)
    expected_terms = miller_components(
        tuple(inputs["flows"].T),
        elements,
        tuple(inputs["rates"].T),
        tuple(inputs["velocities"].T),
        tuple(MOUNTING.ravel().tolist()),
        LEVER_ARM_M,
    )
    np.testing.assert_array_equal(terms, np.stack(expected_terms).transpose(0, 2, 1))
    expected = corrected_flow_covariance_enu(
        np.stack(elements, axis=-1).reshape(-1, 3, 3),
        MOUNTING,
        np.array(LEVER_ARM_M),
        inputs["flows"],
        inputs["rates"],
        inputs["attitude"],
        inputs["velocity"],
        inputs["rate"],
        inputs["noises"],
    )
    np.testing.assert_array_equal(covariances[0], expected.navigation)
    np.testing.assert_array_equal(covariances[1], expected.sensor)


def test_a_sample_alone_is_corrected_as_in_a_batch():
    inputs = _inputs(12)
    terms, covariances = _compiled(inputs, slice(None))
    for i in range(0, N, 37):
        alone_terms, alone_covariances = _compiled(inputs, slice(i, i + 1))
        np.testing.assert_array_equal(alone_terms[:, 0], terms[:, i])
        np.testing.assert_array_equal(alone_covariances[:, 0], covariances[:, i])
