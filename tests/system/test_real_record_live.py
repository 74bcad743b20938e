"""The real record through the live nodes: the first two minutes of OOI's FDCHP record
(``tests/data/ooi_fdchp/``), imported with the shipped column map, replayed over DDS to
``fusion_node`` and ``compensation_node`` with the motion-pack sensor set
(``ooi_fdchp_params.yaml``), give, recorded by ``bag_recorder``, the ``nav/odometry``,
``wind/true`` and flux windows that ``process_bag`` writes for the same messages.

A real record has no truth to hold the two runs to; the offline one is held to the motion it
removes (the vertical wind's coherence with the buoy's heave in the wave band, as
``test_real_record`` holds the whole record), so that two runs broken alike would not pass.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from live_replay import (
    differences_from_offline,
    flux_window_parameters,
    process_offline,
    replay,
    vector_arrays,
)

from buoy_common.bag_io import BagReader
from buoy_common.contract import IMU_RAW_TOPIC, wind_fluxes_topic
from buoy_common.import_records import import_records
from wind_comp.motion_residual import motion_residual, vertical_acceleration_mps2

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
RECORD = REPO / "tests" / "data" / "ooi_fdchp" / "fdchp_test_dp.dat"
RECORDS_CONFIG = REPO / "src" / "buoy_common" / "config" / "records"
COLUMN_MAP = RECORDS_CONFIG / "ooi_fdchp.yaml"
PARAMS = RECORDS_CONFIG / "ooi_fdchp_params.yaml"
RATE_HZ = 10.0
PLAYED_S = 120.0
FLUX_WINDOW_S = 30.0
# Ten times the record's pace: its three 10 Hz topics then carry about the messages a second
# that a simulated bag's 100 Hz IMU, 20 Hz anemometer and GNSS carry at the replay's usual 2x.
REPLAY_RATE = 10.0


def ungated(folder: Path) -> Path:
    """A parameter file in ``folder`` that lifts the σ limits of the wind. The motion removal
    needs the continuous stretch the shipped limits cut on this record: without GNSS its
    compass heading, and each realignment of the filter, leave many samples too uncertain."""
    path = folder / "ungated.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    compensation:\n      max_attitude_sigma_deg: 40.0\n"
        "      max_wind_sigma_horizontal_mps: 20.0\n      max_wind_sigma_vertical_mps: 20.0\n"
    )
    return path


# About 30 s on two cores (the nodes' start-up, two minutes played in 16 s): a long run.
@pytest.mark.long
def test_the_record_replayed_live_equals_process_bag(nodes, tmp_path):
    record_rows = RECORD.read_text().splitlines(keepends=True)[: int(PLAYED_S * RATE_HZ)]
    shortened = tmp_path / "fdchp_2min.dat"
    shortened.write_text("".join(record_rows))
    played = tmp_path / "played"
    import_records(shortened, COLUMN_MAP, played)
    parameter_files = [PARAMS, flux_window_parameters(tmp_path, FLUX_WINDOW_S), ungated(tmp_path)]
    offline = tmp_path / "offline"
    process_offline(played, offline, parameter_files)

    _, measured = vector_arrays(offline, "anemometer/wind")
    _, corrected = vector_arrays(offline, "wind/true")
    with BagReader(played) as reader:
        force = np.array(
            [
                (lambda a: (a.x, a.y, a.z))(reader.decode(m).linear_acceleration)
                for m in reader.messages([IMU_RAW_TOPIC])
            ]
        )
    aligned = np.isfinite(corrected).all(axis=1)
    assert aligned.mean() > 0.8
    first = int(np.argmax(aligned))
    residual = motion_residual(
        measured[first:, 2],
        corrected[first:, 2],
        vertical_acceleration_mps2(force)[first:],
        RATE_HZ,
    )
    # the offline run removes the buoy's heave from w (two minutes: a coarse spectrum)
    assert residual.coherence_after < 0.6 * residual.coherence_before, residual

    recorded = tmp_path / "live"
    flux_topic = wind_fluxes_topic(FLUX_WINDOW_S)
    figures = replay(
        nodes,
        played,
        parameter_files,
        offline,
        recorded,
        also_recorded=(flux_topic,),
        rate=REPLAY_RATE,
    )
    differences = differences_from_offline(recorded, offline)
    assert not differences, "; ".join(differences) + f"; {figures}"

    def flux_rows(bag: Path) -> list[list[float]]:
        with BagReader(bag) as reader:
            return [list(reader.decode(m).data) for m in reader.messages([flux_topic])]

    offline_fluxes, live_fluxes = flux_rows(offline), flux_rows(recorded)
    assert len(offline_fluxes) >= 3
    assert len(live_fluxes) == len(offline_fluxes), figures
    np.testing.assert_allclose(live_fluxes, offline_fluxes, rtol=0, atol=1e-9)
