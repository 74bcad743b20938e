"""GNSS measurement models of the error-state filter.

Each model returns a :class:`MeasurementModel`: the predicted measurement, the innovation
(measured − predicted), the Jacobian H of the measurement with respect to the 15 error states
under the error-injection convention of :func:`buoy_nav.error_state_filter.inject_error_state`,
and the measurement covariance R.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MeasurementModel:
    """Linearised measurement.

    predicted: measurement predicted from the nominal state (m,).
    innovation: measured − predicted (m,), angles wrapped to (−π, π].
    jacobian: ∂(measurement)/∂(error state), m × 15.
    covariance: measurement noise covariance R, m × m.
    """

    predicted: np.ndarray
    innovation: np.ndarray
    jacobian: np.ndarray
    covariance: np.ndarray


def floored_covariance(covariance, variance_floor: float) -> np.ndarray:
    """Symmetrised covariance whose diagonal is raised to at least ``variance_floor``."""
    matrix = np.array(covariance, dtype=float, ndmin=2)
    matrix = 0.5 * (matrix + matrix.T)
    diagonal = matrix.reshape(-1)[:: matrix.shape[0] + 1]
    np.maximum(diagonal, variance_floor, out=diagonal)
    return matrix
