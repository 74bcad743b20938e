"""The outputs of ``process_bag`` kept in memory for its NetCDF file
(:mod:`buoy_processing.netcdf_output`), in plain arrays while the bag is processed: the corrected
series of each flow sensor and the navigation solutions handed to the corrections. Apart from
the NetCDF code so that a run without NetCDF output does not import xarray.
"""

from __future__ import annotations

from array import array
from collections.abc import Callable, Iterable

import numpy as np

from buoy_processing.nav_output_rate import NavOutputRate
from buoy_processing.solution_columns import SolutionColumns
from wind_comp.compensator import CorrectedBatch, SampleStatus

NANOSECONDS = 1_000_000_000
_NAV_FIELDS = 10  # latitude, longitude, altitude, quaternion (4), ENU velocity (3)


class FlowSeries:
    """The corrected samples of one flow sensor, in output order: what ``wind/true`` or
    ``current/velocity`` carry, each sample's standard errors (the square roots of the
    diagonal of its covariance, ``*_with_covariance``) and its :class:`SampleStatus`."""

    def __init__(self, reason: Callable[[SampleStatus], str]):
        """reason: the contract's name of an invalid sample's status (the sensor's
        :meth:`~wind_comp.compensator.FlowSensor.reason`, as ``diagnostics`` counts it)."""
        self.reason = reason
        self.stamps_ns = array("q")
        self.flows_enu_mps = array("d")
        self.standard_errors_enu_mps = array("d")
        self.status = array("b")

    def add(self, secs: np.ndarray, nanosecs: np.ndarray, batch: CorrectedBatch) -> None:
        """The header stamps (s, ns) of a batch's sensor messages and the batch."""
        self.stamps_ns.extend((secs * NANOSECONDS + nanosecs).astype(np.int64).tolist())
        self.flows_enu_mps.extend(np.asarray(batch.flow_enu_mps, dtype=float).ravel().tolist())
        variances = np.diagonal(batch.covariance.total, axis1=1, axis2=2)
        self.standard_errors_enu_mps.extend(np.sqrt(variances).ravel().tolist())
        self.status.extend(np.asarray(batch.status, dtype=np.int8).tolist())

    def __len__(self) -> int:
        return len(self.status)

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N,) stamps ns, (N, 3) ENU vectors m/s, (N,) status codes."""
        return (
            np.frombuffer(self.stamps_ns, dtype=np.int64),
            np.frombuffer(self.flows_enu_mps, dtype=float).reshape(-1, 3),
            np.frombuffer(self.status, dtype=np.int8),
        )

    def standard_errors(self) -> np.ndarray:
        """(N, 3) 1σ of the ENU components of each sample, m/s (NaN where invalid)."""
        return np.frombuffer(self.standard_errors_enu_mps, dtype=float).reshape(-1, 3)


class NavigationSeries:
    """The navigation solutions handed to the corrections (``nav/odometry`` and ``nav/fix``),
    every one or those the bag's ``nav/*`` carry at a lower rate."""

    def __init__(self, nav_rate_hz: float = 0.0):
        """nav_rate_hz: keep the solutions at this rate, Hz, as the bag's ``nav/*`` are
        written (:mod:`buoy_processing.nav_output_rate`); 0: every solution."""
        self._stamps_ns = array("q")
        self._values = array("d")
        self._output = NavOutputRate(nav_rate_hz)

    def add_columns(self, columns: SolutionColumns) -> None:
        """Solutions handed over as columns, in stamp order (a run that makes no ``nav/*``
        values)."""
        secs, nanosecs = columns.secs, columns.nanosecs
        kept = slice(None)
        if not self._output.every_solution:
            due = self._output.due_at
            kept = np.array(
                [due(*stamp) for stamp in zip(secs.tolist(), nanosecs.tolist(), strict=True)],
                dtype=bool,
            )
        values = np.column_stack(
            (columns.geodetic, columns.navigation.attitude_xyzw, columns.velocity_enu_mps)
        )[kept]
        self._stamps_ns.frombytes((secs * NANOSECONDS + nanosecs)[kept].tobytes())
        self._values.frombytes(values.tobytes())

    def add(self, solutions: Iterable) -> None:
        """Solutions as :class:`buoy_nav.fusion_messages.NavValues`, in stamp order."""
        values = self._values
        for solution in solutions:
            if not self._output.due(solution):
                continue
            self._stamps_ns.append(solution.sec * NANOSECONDS + solution.nanosec)
            values.extend((solution.latitude_deg, solution.longitude_deg, solution.altitude_m))
            values.extend(solution.attitude_xyzw)
            values.extend(solution.velocity_enu_mps)

    def __len__(self) -> int:
        return len(self._stamps_ns)

    def columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(M,) stamps ns and (M, 10): latitude, longitude, altitude, quaternion x y z w,
        velocity E N U."""
        return (
            np.frombuffer(self._stamps_ns, dtype=np.int64),
            np.frombuffer(self._values, dtype=float).reshape(-1, _NAV_FIELDS),
        )
