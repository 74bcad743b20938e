"""How much each mounting error costs the corrected wind, computed on a processed bag.

    python -m tools.mounting_sensitivity PROCESSED_BAG

The Miller correction W = R_nb·(R_bw·u + ω×B) + V is linear in the mounting R_bw and the lever
arm B, so an error of the mounting (δR) or of the lever arm (δB) changes every corrected sample
by exactly R_nb·δR·u or R_nb·(ω×δB). This script applies 1° about each sonic axis and 1 cm along
each body axis to the bag's own measured wind, attitude and body rate, and prints, per error,
the bias of the mean vertical wind, the error of the record's mean speed and direction, and the
RMS of the per-sample change (what enters turbulent fluxes). The table of docs/mounting.md comes
from here.
"""

from __future__ import annotations

import sys

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from buoy_common.bag_io import BagReader
from buoy_common.contract import NAV_ODOMETRY_TOPIC, WIND_RAW_TOPIC, WIND_TRUE_TOPIC
from buoy_processing.report.data import odometry_series, stamped_vectors, vectors_at_stamps
from wind_comp.products import meteorological_direction_deg


def main(bag: str) -> None:
    with BagReader(bag) as reader:
        measured = stamped_vectors(reader, WIND_RAW_TOPIC)
        corrected = vectors_at_stamps(measured.stamps_ns, stamped_vectors(reader, WIND_TRUE_TOPIC))
        odometry = odometry_series(reader, NAV_ODOMETRY_TOPIC)
    nav_t_s = (odometry.stamps_ns - odometry.stamps_ns[0]) * 1e-9
    t_s = (measured.stamps_ns - odometry.stamps_ns[0]) * 1e-9
    usable = np.isfinite(corrected).all(1) & (t_s >= nav_t_s[0]) & (t_s <= nav_t_s[-1])
    t_s, u, wind = t_s[usable], measured.vectors[usable], corrected[usable]
    attitude = Slerp(nav_t_s, Rotation.from_quat(odometry.quat_xyzw))(t_s).as_matrix()
    rate = np.column_stack(
        [np.interp(t_s, nav_t_s, odometry.angular_rate_body_rad_s[:, k]) for k in range(3)]
    )
    mean = wind.mean(axis=0)
    speed = np.hypot(mean[0], mean[1])
    print(
        f"{bag}: {t_s.size} samples, mean wind {speed:.2f} m/s, "
        f"RMS body rate {np.sqrt((rate**2).sum(1).mean()):.3f} rad/s"
    )
    print(
        "| error | mean w bias (m/s) | mean speed error (m/s) | mean direction error (deg) "
        "| RMS per-sample change (m/s) |"
    )
    print("|---|---|---|---|---|")
    for name, change in _changes(attitude, u, rate).items():
        perturbed = (wind + change).mean(axis=0)
        direction_error = (
            meteorological_direction_deg(perturbed[0], perturbed[1])
            - meteorological_direction_deg(mean[0], mean[1])
            + 180.0
        ) % 360.0 - 180.0
        fluctuation = change - change.mean(axis=0)
        print(
            f"| {name} | {perturbed[2] - mean[2]:+.4f} | "
            f"{np.hypot(perturbed[0], perturbed[1]) - speed:+.4f} | {direction_error:+.3f} | "
            f"{np.sqrt((fluctuation**2).sum(1).mean()):.4f} |"
        )


def _changes(attitude: np.ndarray, u: np.ndarray, rate: np.ndarray) -> dict[str, np.ndarray]:
    """The change of every corrected sample (ENU, m/s) under each error."""
    changes = {}
    for axis, name in enumerate(("roll", "pitch", "yaw")):
        rotation_vector = np.zeros(3)
        rotation_vector[axis] = np.radians(1.0)
        delta = Rotation.from_rotvec(rotation_vector).as_matrix() - np.eye(3)
        changes[f"mounting {name} 1°"] = np.einsum("nij,jk,nk->ni", attitude, delta, u)
    for axis, name in enumerate(("x (forward)", "y (left)", "z (up)")):
        lever = np.zeros(3)
        lever[axis] = 0.01
        changes[f"lever arm {name} 1 cm"] = np.einsum("nij,nj->ni", attitude, np.cross(rate, lever))
    return changes


if __name__ == "__main__":
    main(sys.argv[1])
