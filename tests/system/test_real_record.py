"""A real record: OOI's FDCHP flux-buoy test record (sonic anemometer and motion pack, 10 Hz, no
GNSS), imported with the shipped column map and processed with the motion-pack sensor set,
against Edson's published processing of the same record (``tests/data/ooi_fdchp/README.md``).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
from pathlib import Path

import numpy as np
import pytest
from scipy import signal
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.contract import IMU_RAW_TOPIC, WIND_RAW_TOPIC, WIND_TRUE_TOPIC, QualityFlag
from buoy_common.import_records import import_records
from buoy_common.records.column_map import load_column_map
from buoy_common.records.decoding import decode, plausibility_warnings, read_table
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import WIND_FLUXES_CSV_SUFFIX as FLUXES_CSV
from buoy_processing.bag_processing import process_bag, products_csv_path
from buoy_processing.report.data import stamped_vectors
from wind_comp.config import compensator_config_from_files
from wind_comp.flux_quality import FLUX_FLAG_TESTS, worst_flag
from wind_comp.fluxes import window_fluxes
from wind_comp.motion_residual import motion_residual, vertical_acceleration_mps2

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data" / "ooi_fdchp"
RECORD = DATA / "fdchp_test_dp.dat"
CONFIG = REPO / "src" / "buoy_common" / "config" / "records"
COLUMN_MAP = CONFIG / "ooi_fdchp.yaml"
PARAMS = CONFIG / "ooi_fdchp_params.yaml"
RATE_HZ = 10.0
EDGE = 300
"""Edson keeps rows 300 to 11 700 (30 s trimmed at each end of the first 12 000)."""
# ion-functions' test: Edson's fluxes of the record (u'w', v'w' m²/s²; w'Ts' K m/s)
PUBLISHED_U_W, PUBLISHED_V_W, PUBLISHED_W_TS = -0.350371566926, 0.115496951668, -0.008274161328
ENU_FROM_NWU = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
PROCESSED_ROWS = 6000
UNGATED_ATTITUDE_SIGMA_DEG = 40.0
UNGATED_WIND_SIGMA_MPS = 20.0
"""The first 10 min of the record: enough spectral segments for the wave band, in test time."""


@pytest.fixture(scope="module")
def decoded_record():
    column_map = load_column_map(COLUMN_MAP)
    return decode(read_table(RECORD, column_map), column_map), column_map


def edson_corrected_wind_enu() -> np.ndarray:
    """Edson's motion-corrected wind of rows 300..11 699 (tools/edson_fdchp.py --save-wind)."""
    return np.load(DATA / "edson_corrected_wind_nwu.npy") @ ENU_FROM_NWU.T


def test_the_shipped_map_reads_the_record_as_physics_expects(decoded_record):
    samples, column_map = decoded_record
    assert len(samples) == 12009
    assert plausibility_warnings(samples, column_map) == []
    # the pack reads gravity up in forward-left-up axes (its own z reads about −1 g)
    mean_force = samples.specific_force_mps2.mean(axis=0)
    assert 9.5 < mean_force[2] < 10.1
    # its attitude and its accelerometer tilt the same way: the slow (< 0.02 Hz) tilt from the
    # pack's Euler angles and from the direction of the specific force move together on both
    # horizontal axes (a sign or axis error in the map would make one of them move opposite)
    up_body = Rotation.from_quat(samples.orientation_xyzw).inv().apply([0.0, 0.0, 1.0])
    force_direction = samples.specific_force_mps2 / np.linalg.norm(
        samples.specific_force_mps2, axis=1, keepdims=True
    )
    slow = signal.butter(2, 0.02, fs=RATE_HZ, output="sos")
    for axis in (0, 1):
        from_attitude = signal.sosfiltfilt(slow, up_body[:, axis])
        from_force = signal.sosfiltfilt(slow, force_direction[:, axis])
        assert np.corrcoef(from_attitude, from_force)[0, 1] > 0.5
    # sonic temperature c²/403 − 273.15 from a 345 m/s speed of sound: a mild day
    assert 10.0 < np.nanmean(samples.sonic_temperature_degc) < 30.0


def test_our_flux_core_gives_edsons_fluxes_from_his_corrected_wind(decoded_record):
    # His rotation into the mean wind, linear detrending and covariances are the textbook
    # ones; ours, on his wind and his samples, must give his published numbers.
    samples, _ = decoded_record
    kept = slice(EDGE, 12000 - EDGE)
    window = window_fluxes(
        samples.time_ns[kept] * 1e-9,
        edson_corrected_wind_enu(),
        samples.sonic_temperature_degc[kept],
    )
    # his Python port holds his MATLAB at 1e-4 (ion-functions' test)
    assert window.u_w_m2_s2 == pytest.approx(PUBLISHED_U_W, rel=1e-4)
    assert window.v_w_m2_s2 == pytest.approx(PUBLISHED_V_W, rel=1e-4)
    assert window.w_ts_k_mps == pytest.approx(PUBLISHED_W_TS, abs=1e-5)


@pytest.fixture(scope="module")
def processed_record(tmp_path_factory):
    directory = tmp_path_factory.mktemp("fdchp")
    shortened = directory / "fdchp_10min.dat"
    shortened.write_text("".join(RECORD.read_text().splitlines(keepends=True)[:PROCESSED_ROWS]))
    imported, processed = directory / "fdchp", directory / "fdchp_processed"
    import_records(shortened, COLUMN_MAP, imported)
    # The motion correction itself is held against Edson's here, over the continuous stretch
    # the spectra need. Without GNSS the heading rests on the pack's compass and the filter
    # realigns now and then: the shipped limits rightly refuse many samples as too uncertain
    # (horizontally for the heading, vertically in the seconds after a realignment), which
    # would cut the stretch, so this comparison lifts them.
    ungated = dataclasses.replace(
        compensator_config_from_files([str(PARAMS)]),
        max_attitude_sigma_deg=UNGATED_ATTITUDE_SIGMA_DEG,
        max_wind_sigma_horizontal_mps=UNGATED_WIND_SIGMA_MPS,
        max_wind_sigma_vertical_mps=UNGATED_WIND_SIGMA_MPS,
    )
    with contextlib.redirect_stdout(io.StringIO()):
        process_bag(imported, processed, fusion_config_from_files([str(PARAMS)]), ungated)
    with BagReader(processed) as reader:
        measured = stamped_vectors(reader, WIND_RAW_TOPIC)
        corrected = stamped_vectors(reader, WIND_TRUE_TOPIC)
    with BagReader(imported) as reader:
        force = np.array(
            [
                (lambda a: (a.x, a.y, a.z))(reader.decode(m).linear_acceleration)
                for m in reader.messages([IMU_RAW_TOPIC])
            ]
        )
    return measured.vectors, corrected.vectors, force, products_csv_path(processed, FLUXES_CSV)


def test_the_motion_pack_correction_removes_the_buoys_motion_as_edsons_does(processed_record):
    measured, corrected, force, _ = processed_record
    kept = slice(EDGE, PROCESSED_ROWS - EDGE)
    assert np.isfinite(corrected[kept]).all(axis=1).mean() > 0.98
    heave = vertical_acceleration_mps2(force)[kept]
    ours = motion_residual(measured[kept, 2], corrected[kept, 2], heave, RATE_HZ)
    edson = motion_residual(
        measured[kept, 2],
        edson_corrected_wind_enu()[: PROCESSED_ROWS - 2 * EDGE, 2],
        heave,
        RATE_HZ,
        ours.band_hz,
    )
    # the uncorrected w is the buoy's heave: coherent with its acceleration in the wave band
    assert ours.coherence_before > 0.5
    # the correction removes most of that coherence and most of the band's variance ...
    assert ours.coherence_after < 0.5 * ours.coherence_before
    assert ours.variance_share < 0.5
    # ... as far as Edson's processing does, within what 10 min of spectra resolve
    assert ours.coherence_after < edson.coherence_after + 0.05
    assert ours.variance_share < edson.variance_share + 0.05


def test_the_records_stress_is_plausible_for_its_wind(processed_record):
    # With the motion pack's gyro and the record's sea stated as measured, no slow platform
    # velocity is left in the wind: C_D = u*²/U² lies within the scatter of real windows about
    # COARE 3.5's neutral value (0.3-3x), where the slow velocity of a mooring held to 3 m and a
    # gyro taken for 5 deg/h made it about ten times that. The drag test passes it.
    *_, fluxes_csv = processed_record
    with open(fluxes_csv, newline="") as stream:
        (window,) = list(csv.DictReader(stream))
    values = {name: float(value) for name, value in window.items() if not name.endswith("_utc")}
    drag = values["friction_velocity_mps"] ** 2 / values["mean_speed_mps"] ** 2
    # the CSV gives each figure to its printed digits
    assert values["drag_coefficient"] == pytest.approx(drag, rel=1e-3)
    ratio = values["drag_coefficient"] / values["drag_coefficient_neutral_10m"]
    assert 0.3 < ratio < 3.0
    assert values["drag_coefficient_flag"] == QualityFlag.GOOD
    flags = [QualityFlag(int(values[test.field])) for test in FLUX_FLAG_TESTS]
    assert values["quality_flag"] == worst_flag(flags)
