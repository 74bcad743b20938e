"""Report figures, tables and the saved report data; the report of a processed bag."""

import contextlib
import dataclasses
import io
import json
import math
import re
import shutil
from pathlib import Path

import bag_faults
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.image import imread
from mcap.reader import make_reader
from PIL import Image
from scipy.signal import welch
from scipy.spatial.transform import Rotation

from against_truth import assert_wind_within_budget
from buoy_common.bag_io import BagReader, BagWriter
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from buoy_processing.report import figures
from buoy_processing.report.attitude import (
    attitude_errors_deg,
    rpy_rad_from_quaternions,
    rpy_sigma_rad,
)
from buoy_processing.report.data import (
    ReportData,
    ReportDataError,
    load_report_data,
    report_data_from_bag,
    save_report_data,
)
from buoy_processing.report.folder import write_report
from buoy_processing.wind_report import main
from sensor_sim.simulate_bag import parse_arguments, simulate
from wind_comp.config import compensator_config_from_files
from wind_comp.flow_uncertainty import FlowCovariance
from wind_comp.flux_products import FluxAverager
from wind_comp.products import WindAverager

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
REPO = Path(__file__).resolve().parents[2]
BUOY_PARAMS = str(REPO / "src/buoy_common/config/buoy.yaml")
FIGURES = ("wind_time_series.png", "attitude_error.png", "vertical_wind_spectrum.png")


MIN_COLOURED_SHARE = 0.001
"""Share of a figure's pixels in colour below which it shows no data: matplotlib draws the axes,
ticks, text and grid in greys and the data in the colour cycle. Three panels with titles and
grids: 0.000 %; the same with three legend entries each and every value NaN: 0.05 %; one line
across each panel: 0.5 %; the report's figures: 0.18 to 1.7 %."""


def coloured_share(png: Path) -> float:
    """Share of the pixels of the image ``png`` that are in colour (red, green and blue apart by
    more than a third of their range): what the data are drawn with."""
    with Image.open(png) as image:
        pixels = np.asarray(image.convert("RGB"), dtype=np.int16)
    return float(np.mean(np.ptp(pixels, axis=2) > 85))


def sample_data(with_truth: bool) -> ReportData:
    rng = np.random.default_rng(51)
    t_s = np.arange(0.0, 130.0, 0.1)
    true_wind = np.column_stack(
        (np.full_like(t_s, 6.0), np.full_like(t_s, -2.0), 0.1 * np.sin(0.5 * t_s))
    )
    sway = 0.5 * np.sin(2 * np.pi * t_s / 6.0)
    measured = true_wind + np.column_stack((np.zeros_like(t_s), sway, sway))
    corrected = true_wind + rng.normal(scale=0.05, size=true_wind.shape)
    corrected[100:110] = np.nan
    covariance = FlowCovariance(
        np.broadcast_to(np.diag([0.03, 0.03, 0.01]) ** 2, (t_s.size, 3, 3)),
        np.broadcast_to(np.diag([0.05, 0.05, 0.05]) ** 2, (t_s.size, 3, 3)),
    )
    averager = WindAverager(window_s=60.0)
    products = averager.add_batch(t_s, corrected, covariance) + averager.flush()
    truth_rpy = np.column_stack((sway * 0.2, sway * 0.1, np.full_like(t_s, np.radians(179.9))))
    nav_rpy = truth_rpy + np.radians([0.1, -0.2, 0.3])
    nav_rpy[:, 2] = (nav_rpy[:, 2] + np.pi) % (2 * np.pi) - np.pi  # yaw wraps past 180°
    return ReportData(
        t_s=t_s,
        measured_wind_sensor_mps=measured,
        corrected_wind_enu_mps=corrected,
        true_wind_enu_mps=true_wind if with_truth else None,
        attitude_t_s=t_s,
        nav_rpy_rad=nav_rpy,
        truth_rpy_rad=truth_rpy if with_truth else None,
        nav_rpy_sigma_rad=np.full_like(nav_rpy, np.radians(0.2)),
        nav_up_velocity_mps=0.4 * np.cos(2 * np.pi * t_s / 6.0),
        products=products,
        title="test run",
    )


@pytest.fixture(scope="module")
def sample_report_with_truth(tmp_path_factory) -> tuple[list[Path], Path]:
    """(paths written, folder) of the report of ``sample_data(with_truth=True)``, rendered once:
    the tests that only read it share it."""
    folder = tmp_path_factory.mktemp("sample_with_truth") / "report"
    return write_report(sample_data(with_truth=True), folder), folder


def test_report_with_truth_writes_all_figures_and_tables(sample_report_with_truth):
    paths, folder = sample_report_with_truth
    names = sorted(path.name for path in paths)
    assert names == [
        "attitude_error.png",
        "summary.md",
        "vertical_wind_spectrum.png",
        "wind_products.md",
        "wind_time_series.png",
    ]
    for path in paths:
        if path.suffix == ".png":
            assert path.read_bytes()[:8] == PNG_SIGNATURE
            assert path.stat().st_size > 10_000
    table = (folder / "wind_products.md").read_text()
    assert "Error against truth" in table
    assert table.count("| 60 |") == 3  # three 60 s windows in 130 s
    # Mean wind (6, -2) m/s toward ESE comes from 288.4°.
    assert "| 288.4 |" in table
    # The first minute lacks 10 of its 600 samples: good; the last holds 100: bad, in bold.
    assert table.count("| 0.9833 | 1 good |") == 1
    assert table.count("| 0.1667 | **4 bad** |") == 1


def test_report_without_truth_skips_the_attitude_error(tmp_path):
    paths = write_report(sample_data(with_truth=False), tmp_path)
    assert sorted(path.name for path in paths) == [
        "summary.md",
        "vertical_wind_spectrum.png",
        "wind_products.md",
        "wind_time_series.png",
    ]
    assert "Error against truth" not in (tmp_path / "wind_products.md").read_text()


def test_report_data_round_trip_and_command_line(tmp_path, capsys):
    data = sample_data(with_truth=True)
    saved = save_report_data(data, tmp_path / "run.npz")
    loaded = load_report_data(saved)
    np.testing.assert_array_equal(loaded.corrected_wind_enu_mps, data.corrected_wind_enu_mps)
    np.testing.assert_array_equal(loaded.truth_rpy_rad, data.truth_rpy_rad)
    np.testing.assert_array_equal(loaded.nav_rpy_sigma_rad, data.nav_rpy_sigma_rad)
    np.testing.assert_array_equal(loaded.nav_up_velocity_mps, data.nav_up_velocity_mps)
    assert loaded.products == data.products
    assert loaded.title == "test run"
    assert main([str(saved), "--out", str(tmp_path / "out")]) == 0
    assert "wind_time_series.png" in capsys.readouterr().out
    assert (tmp_path / "out" / "attitude_error.png").exists()


def test_heading_error_is_wrapped_and_clockwise():
    truth = np.radians([[0.0, 0.0, 179.0], [0.0, 0.0, 10.0]])
    estimate = np.radians([[1.0, -2.0, -179.0], [0.0, 0.0, 12.0]])
    errors = attitude_errors_deg(estimate, truth)
    # Yaw grows counter-clockwise, heading clockwise: +2° of yaw is -2° of heading.
    np.testing.assert_allclose(errors, [[1.0, -2.0, -2.0], [0.0, 0.0, -2.0]], atol=1e-12)


def test_euler_angles_from_quaternions_follow_the_zyx_convention():
    roll, pitch, yaw = 0.1, -0.2, 2.5
    quat = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
    np.testing.assert_allclose(rpy_rad_from_quaternions([quat]), [[roll, pitch, yaw]])


@pytest.mark.parametrize("seed", range(5))
def test_euler_sigma_follows_the_euler_change_of_a_small_enu_rotation(seed):
    # A rotation error along ENU axis k alone (covariance e_k e_kᵀ) moves the Euler angles by
    # column k of their Jacobian: its 1σ must be that column's magnitude, found here by turning
    # the attitude by a small angle about that axis.
    rng = np.random.default_rng(seed)
    attitude = Rotation.from_euler("ZYX", rng.uniform([-np.pi, -1.2, -np.pi], [np.pi, 1.2, np.pi]))
    rpy = rpy_rad_from_quaternions([attitude.as_quat()])
    step_rad = 1e-7
    for k in range(3):
        turned = Rotation.from_rotvec(step_rad * np.eye(3)[k]) * attitude
        change = rpy_rad_from_quaternions([turned.as_quat()]) - rpy
        change = (change + np.pi) % (2 * np.pi) - np.pi
        covariance = np.outer(np.eye(3)[k], np.eye(3)[k])[None]
        np.testing.assert_allclose(
            rpy_sigma_rad(rpy, covariance), np.abs(change) / step_rad, rtol=1e-5, atol=1e-6
        )


def test_euler_sigma_of_a_full_covariance_matches_sampled_errors():
    rng = np.random.default_rng(7)
    attitude = Rotation.from_euler("ZYX", [2.0, 0.4, -0.3])
    rpy = rpy_rad_from_quaternions([attitude.as_quat()])
    factor = rng.normal(scale=1e-3, size=(3, 3))
    covariance = factor @ factor.T
    samples = rng.multivariate_normal(np.zeros(3), covariance, size=20_000)
    turned = Rotation.from_rotvec(samples) * attitude
    errors = rpy_rad_from_quaternions(turned.as_quat()) - rpy
    errors = (errors + np.pi) % (2 * np.pi) - np.pi
    # 20 000 samples estimate a standard deviation to about 0.5 % (1σ).
    np.testing.assert_allclose(
        rpy_sigma_rad(rpy, covariance[None])[0], errors.std(axis=0), rtol=0.03
    )


def test_inconsistent_report_data_raises():
    t_s = np.arange(5.0)
    with pytest.raises(ReportDataError, match="corrected_wind_enu_mps"):
        ReportData(t_s, np.zeros((5, 3)), np.zeros((4, 3)))
    with pytest.raises(ReportDataError, match="truth_rpy_rad"):
        ReportData(t_s, np.zeros((5, 3)), np.zeros((5, 3)), truth_rpy_rad=np.zeros((5, 3)))


def test_unreadable_data_file_is_reported(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_text("not numpy")
    with pytest.raises(SystemExit) as exit_info:
        main([str(bad)])
    assert exit_info.value.code == 2


# The truth at the anemometer's rate (the offsets agree in both geometries), so that the
# report's errors against the truth need no interpolation of the turbulence between samples.
TRUTH_WITH_THE_ANEMOMETER = "/**/truth_node:\n  ros__parameters:\n    rate_hz: 20.0\n"
GEOMETRIES = {
    "default": (BUOY_PARAMS,),
    "off_axis": (BUOY_PARAMS, str(REPO / "bags" / "off_axis.yaml")),
}
# Flux windows of 10 s over the 40 s of sea_state, with a sonic temperature added: several
# windows, before and after the alignment, to show with their flags. Neither changes the
# corrected wind, so one run serves the tests of the wind and those of the fluxes.
FLUX_WINDOW_S = 10.0
FLUX_WINDOW_PARAMETERS = (
    f"/**:\n  ros__parameters:\n    compensation:\n      flux_window_s: {FLUX_WINDOW_S}\n"
)
_RUNS = {}
_REPORTS = {}


def sea_state_run(tmp_path_factory, geometry: str):
    """(sensor bag, processed bag, process summary, buoy parameter files) of 40 s of the
    sea_state scenario simulated with the buoy parameters of ``geometry``, given a sonic
    temperature and processed with those parameters and flux windows of :data:`FLUX_WINDOW_S`,
    made once."""
    if geometry not in _RUNS:
        folder = tmp_path_factory.mktemp(f"sea_state_{geometry}")
        simulated = folder / "simulated"
        sensors, processed = folder / "sensors", folder / "processed"
        truth_rate = folder / "truth_with_the_anemometer.yaml"
        truth_rate.write_text(TRUTH_WITH_THE_ANEMOMETER)
        files = GEOMETRIES[geometry]
        simulate(
            parse_arguments(
                ["sea_state", str(simulated), "--set", "duration_s=40"]
                + [a for path in (*files, truth_rate) for a in ("--params-file", str(path))]
            )
        )
        records = bag_faults.read_records(simulated, None, seconds=3600.0)
        bag_faults.write_records(bag_faults.with_sonic_temperature(records), sensors)
        flux_window = folder / "flux_window.yaml"
        flux_window.write_text(FLUX_WINDOW_PARAMETERS)
        processing_files = [*files, flux_window]
        summary = process_bag(
            sensors,
            processed,
            fusion_config_from_files(processing_files),
            compensator_config_from_files(processing_files),
        )
        _RUNS[geometry] = sensors, processed, summary, files
    return _RUNS[geometry]


def sea_state_report(tmp_path_factory, geometry: str) -> tuple[Path, int, str]:
    """(report folder, exit code, printed text) of ``wind_report`` on the processed bag of
    :func:`sea_state_run`, rendered once: the tests here only read it."""
    if geometry not in _REPORTS:
        _, processed, _, _ = sea_state_run(tmp_path_factory, geometry)
        folder = tmp_path_factory.mktemp(f"sea_state_{geometry}_report")
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            exit_code = main([str(processed), "--out", str(folder)])
        _REPORTS[geometry] = folder, exit_code, printed.getvalue()
    return _REPORTS[geometry]


@pytest.fixture(scope="module")
def sea_state_bags(tmp_path_factory):
    """(sensor bag, processed bag, process summary) of the default buoy's run."""
    return sea_state_run(tmp_path_factory, "default")[:3]


def independent_errors(bag) -> tuple[np.ndarray, np.ndarray]:
    """Corrected wind matched to each anemometer stamp and its error against the truth
    interpolated there, straight from the bag's messages; (N, 3) each, NaN where unknown."""
    with BagReader(bag) as reader:

        def stamped(topic):
            for message in reader.messages([topic]):
                decoded = reader.decode(message)
                stamp = decoded.header.stamp
                yield (
                    (stamp.sec, stamp.nanosec),
                    (
                        decoded.vector.x,
                        decoded.vector.y,
                        decoded.vector.z,
                    ),
                )

        measured_stamps = [stamp for stamp, _ in stamped("anemometer/wind")]
        corrected_by_stamp = dict(stamped("wind/true"))
        truth = list(stamped("truth/wind"))
    # The contract: one wind/true per anemometer sample, with its stamp.
    assert len(corrected_by_stamp) == len(measured_stamps)
    corrected = np.array([corrected_by_stamp[stamp] for stamp in measured_stamps])
    truth_sec0 = truth[0][0][0]
    truth_t_s = np.array([(sec - truth_sec0) + nanosec * 1e-9 for (sec, nanosec), _ in truth])
    truth_wind = np.array([vector for _, vector in truth])
    t_s = np.array([(sec - truth_sec0) + nanosec * 1e-9 for sec, nanosec in measured_stamps])
    true_at_samples = np.column_stack(
        [
            np.interp(t_s, truth_t_s, truth_wind[:, axis], left=np.nan, right=np.nan)
            for axis in range(3)
        ]
    )
    return corrected, corrected - true_at_samples


def table_row(markdown: str, series: str, quantity: str) -> tuple[float, float, int]:
    """(bias, RMS, samples) of one row of the error table."""
    match = re.search(
        rf"^\| {re.escape(series)} \| {re.escape(quantity)} \| (\S+) \| (\S+) \| (\d+) \|$",
        markdown,
        flags=re.MULTILINE,
    )
    assert match, f"no row {series} / {quantity}"
    return float(match[1]), float(match[2]), int(match[3])


# The off-axis buoy's report is a long run: its wind is held to the budget by test_process_bag.
@pytest.mark.parametrize(
    "geometry",
    [pytest.param(name, marks=[pytest.mark.long] * (name != "default")) for name in GEOMETRIES],
)
def test_report_of_a_processed_bag(tmp_path_factory, geometry):
    sensors, processed, summary, parameter_files = sea_state_run(tmp_path_factory, geometry)
    report, exit_code, printed = sea_state_report(tmp_path_factory, geometry)
    assert exit_code == 0
    assert "wind_products.md" in printed
    for name in FIGURES:
        path = report / name
        assert path.read_bytes()[:8] == PNG_SIGNATURE
        image = imread(path)
        assert image.shape[0] > 400 and image.shape[1] > 600
        assert coloured_share(path) > MIN_COLOURED_SHARE, f"{name} shows no data"

    corrected, errors = independent_errors(processed)
    data = report_data_from_bag(processed)
    np.testing.assert_array_equal(data.corrected_wind_enu_mps, corrected)
    np.testing.assert_allclose(
        data.corrected_wind_enu_mps - data.true_wind_enu_mps, errors, rtol=0, atol=1e-9
    )

    markdown = (report / "wind_products.md").read_text()
    usable = np.all(np.isfinite(errors), axis=1)
    rms = np.sqrt(np.mean(errors[usable] ** 2, axis=0))
    for axis, quantity in enumerate(("u (m/s)", "v (m/s)", "w (m/s)")):
        _, table_rms, samples = table_row(markdown, "corrected", quantity)
        assert samples == np.count_nonzero(usable)
        # The table prints 4 decimals: it must be the recomputed value rounded.
        assert abs(table_rms - rms[axis]) <= 0.5e-4 + 1e-9
    # The motion correction removes most of the buoy's motion from w, and what the table
    # reports is inside the error budget of the sensors.
    _, measured_w_rms, _ = table_row(markdown, "measured (sensor axes)", "w (m/s)")
    assert rms[2] < 0.2 * measured_w_rms
    with BagReader(sensors) as reader:
        measured = [reader.decode(m).vector for m in reader.messages(["anemometer/wind"])]
    print(
        assert_wind_within_budget(
            errors[usable],
            [(v.x, v.y, v.z) for v in measured],
            compensator_config_from_files(parameter_files).anemometer_position_body_m,
            f"report of the {geometry} buoy",
        )
    )

    # The attitude errors stay inside the filter's own ±3σ but for rare moments once the
    # filter has converged (a consistent filter: ~0.3 % outside for Gaussian errors).
    errors_deg = np.abs(attitude_errors_deg(data.nav_rpy_rad, data.truth_rpy_rad))
    bound_deg = 3.0 * np.degrees(data.nav_rpy_sigma_rad)
    settled = data.attitude_t_s >= data.attitude_t_s[0] + 20.0
    outside = np.mean(errors_deg[settled] > bound_deg[settled], axis=0)
    assert np.all(outside < 0.05), f"share outside ±3σ (roll, pitch, heading): {outside}"

    # The published products are read back as process_bag computed them (the gust window is
    # not published).
    published = [dataclasses.replace(p, gust_window_s=3.0) for p in data.products]
    assert published == sorted(summary.wind.products, key=lambda p: (p.window_s, p.window_start_s))
    assert "published on wind/stats_1min, wind/stats_10min" in markdown
    # The simulated buoy's heading is its GNSS antennas': the process_bag run says true north
    # beside the bag, and the report takes it from there.
    assert summary.facts.north == "true north"
    assert data.north == "true_north"
    assert (
        "Wind directions in degrees clockwise from true north."
        in (report / "summary.md").read_text()
    )


def copy_of(bag: Path, destination: Path) -> Path:
    """The messages of ``bag`` in a new bag without its metadata records: a bag processed
    before process_bag stored its outputs' facts."""
    with BagReader(bag) as reader, BagWriter(destination) as writer:
        for message in reader.messages(list(reader.topics)):
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
    return destination


def test_the_processed_bag_states_its_north_and_sensors_and_the_report_reads_them(
    sea_state_bags, tmp_path
):
    _, processed, summary = sea_state_bags
    # read with the mcap library alone, not the suite's own reader
    with open(next(Path(processed).glob("*.mcap")), "rb") as stream:
        records = {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}
    stored = records["buoy_outputs"]
    assert stored["north"] == summary.facts.north == "true north"
    assert json.loads(stored["sensors"]) == list(summary.facts.sensors)
    assert json.loads(stored["position_from_gnss"]) is True
    assert "buoy_record" not in records  # a simulated bag, not an imported record

    # the bag alone, without the products CSV beside it, still says its north and sensors
    alone = tmp_path / "alone" / "processed"
    shutil.copytree(processed, alone)
    data = report_data_from_bag(alone)
    assert (data.north, data.sensors) == ("true_north", summary.facts.sensor_text())
    assert "Sensors used: IMU, GNSS receiver" in data.sensors_sentence


def test_a_bag_without_its_outputs_facts_falls_back_to_the_csv_or_says_it_does_not_know(
    sea_state_bags, tmp_path
):
    _, processed, _ = sea_state_bags
    earlier = copy_of(processed, tmp_path / "earlier")
    csv_name = "_wind_products.csv"
    shutil.copy(str(processed) + csv_name, str(earlier) + csv_name)
    data = report_data_from_bag(earlier)
    assert (data.north, data.sensors) == ("true_north", "")
    assert "not recorded with these data" in data.sensors_sentence
    # recorded from the nodes: no facts, no CSV (the same messages, the CSV taken away)
    Path(str(earlier) + csv_name).unlink()
    write_report(report_data_from_bag(earlier), tmp_path / "report")
    page = (tmp_path / "report" / "summary.md").read_text()
    assert "which north is not recorded with these data" in page
    assert "The sensors used are not recorded with these data" in page


def test_products_are_recomputed_when_the_bag_has_none(sea_state_bags, tmp_path):
    _, processed, _ = sea_state_bags
    without_products = tmp_path / "without_products"
    with BagReader(processed) as reader, BagWriter(without_products) as writer:
        kept = [name for name in reader.topics if not name.startswith("/wind/stats_")]
        for message in reader.messages(kept):
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
    data = report_data_from_bag(without_products)
    expected = []
    for window_s in (60.0, 600.0):
        averager = WindAverager(window_s, 3.0)
        expected += averager.add_batch(data.t_s, data.corrected_wind_enu_mps) + averager.flush()
    assert data.products == expected
    assert data.products_source.startswith("recomputed from wind/true")


def test_missing_bag_or_wind_topics_exit_with_one_line(sea_state_bags, tmp_path, capsys):
    sensors, _, _ = sea_state_bags
    for source, expected in ((tmp_path / "no_such_bag", "does not exist"), (sensors, "wind/true")):
        with pytest.raises(SystemExit) as exit_info:
            main([str(source), "--out", str(tmp_path / "report")])
        assert exit_info.value.code == 2
        error = capsys.readouterr().err
        assert error.startswith("wind_report: ") and expected in error
        assert error.count("\n") == 1
    assert not (tmp_path / "report").exists()


def test_summary_page_shows_every_figure_the_quality_and_the_filter_health(
    sample_report_with_truth,
):
    paths, folder = sample_report_with_truth
    summary = (folder / "summary.md").read_text()
    for path in paths:
        if path.suffix == ".png":
            assert f"]({path.name})" in summary
    # 10 of the 1300 samples have no corrected wind.
    assert "| corrected | 1290 | 99.2 % |" in summary
    assert "| not corrected (NaN: before alignment, gaps, rejected) | 10 | 0.8 % |" in summary
    # Errors of 0.1°, 0.2°, 0.3° against a 1σ of 0.2°: all inside ±3σ, RMS the offset itself.
    assert "| roll | 0.200 | 0.200 | 0.100 | 100.0 % |" in summary
    assert "| heading | 0.200 | 0.200 | 0.300 | 100.0 % |" in summary
    assert "| 288.4 |" in summary


def test_wave_band_holds_the_period_of_the_heave():
    # The sample's buoy heaves with a 6 s period.
    low_hz, high_hz = figures._wave_band_hz(sample_data(with_truth=True))
    assert low_hz <= 1 / 6.0 <= high_hz
    assert high_hz - low_hz < 0.1


def test_log_band_averaging_keeps_the_level_of_white_noise():
    rate_hz, sigma = 10.0, 0.3
    noise = np.random.default_rng(3).normal(scale=sigma, size=36_000)
    segment = figures._segment_samples(noise.size, rate_hz)
    frequency_hz, density = welch(noise, fs=rate_hz, nperseg=segment)
    frequency_hz, density = figures._log_band_average(frequency_hz[1:], density[1:])
    assert segment == 60 * rate_hz  # an hour of data: 60 s segments, 119 of them
    assert np.all(np.diff(np.log10(frequency_hz)) > 0)
    # One-sided density of white noise: 2σ²/f_s.
    assert np.allclose(density, 2 * sigma**2 / rate_hz, rtol=0.35)


def test_directions_across_north_are_drawn_without_jumps():
    direction = np.array([350.0, 356.0, np.nan, 3.0, 10.0, 359.0])
    unwrapped = figures._unwrapped_deg(direction)
    assert np.isnan(unwrapped[2])
    steps = np.diff(unwrapped[np.isfinite(unwrapped)])
    assert np.all(np.abs(steps) < 20.0)
    assert np.allclose(unwrapped[np.isfinite(unwrapped)] % 360.0, direction[np.isfinite(direction)])
    assert np.allclose(figures._near_deg([5.0, 355.0], 0.0), [5.0, -5.0])


def published_windows(bag, prefix: str) -> list[dict[str, float]]:
    """Every message of the ``prefix*`` topics as {label: value}, read straight from the bag,
    ordered by window length and start."""
    with BagReader(bag) as reader:
        topics = [name for name in reader.topics if name.lstrip("/").startswith(prefix)]
        rows = []
        for message in reader.messages(topics):
            decoded = reader.decode(message)
            labels = [dimension.label for dimension in decoded.layout.dim]
            rows.append(dict(zip(labels, decoded.data, strict=True)))
    return sorted(
        rows, key=lambda row: (row["window_end_s"] - row["window_start_s"], row["window_start_s"])
    )


def markdown_table(markdown: str, heading: str) -> list[dict[str, str]]:
    """The rows of the table under ``## heading``, as {column header: cell}."""
    section = markdown.split(f"## {heading}\n", 1)[1].split("\n## ", 1)[0]
    lines = [line for line in section.splitlines() if line.startswith("|")]

    def cells(line: str) -> list[str]:
        return [cell.strip() for cell in line.strip().strip("|").split("|")]

    header = cells(lines[0])
    return [dict(zip(header, cells(line), strict=True)) for line in lines[2:]]


def assert_printed(cell: str, value: float, *, decimals: int | None = None) -> None:
    """``cell`` is ``value`` as printed: to ``decimals`` decimals, or to four significant
    digits."""
    if math.isnan(value):
        assert cell == "nan", (cell, value)
        return
    tolerance = 0.5 * 10.0**-decimals if decimals is not None else 5e-4 * abs(value)
    assert abs(float(cell) - value) <= tolerance * (1 + 1e-9), (cell, value)


def assert_flag(cell: str, flag: float) -> None:
    """A flag cell carries the window's flag, in bold unless good."""
    assert int(cell.strip("*").split()[0]) == int(flag), (cell, flag)
    assert cell.startswith("**") == (int(flag) != 1), cell


def test_report_tables_are_the_bags_products_and_fluxes(sea_state_bags, tmp_path_factory, tmp_path):
    _, processed, _ = sea_state_bags
    report, exit_code, _ = sea_state_report(tmp_path_factory, "default")
    assert exit_code == 0
    markdown = (report / "wind_products.md").read_text()

    stats = published_windows(processed, "wind/stats_")
    products = markdown_table(markdown, "Averaged wind")
    assert len(products) == len(stats) > 0
    for row, published in zip(products, stats, strict=True):
        assert float(row["length (s)"]) == published["window_end_s"] - published["window_start_s"]
        assert int(row["valid"]) == published["n_valid"]
        assert_printed(row["coverage"], published["coverage"], decimals=4)
        assert_flag(row["flag"], published["quality_flag"])

    published_fluxes = published_windows(processed, "wind/fluxes_")
    fluxes = markdown_table(markdown, "Eddy-covariance fluxes")
    # 40 s in 10 s windows; those before the alignment have no corrected wind
    assert len(fluxes) == len(published_fluxes) >= 4
    for row, published in zip(fluxes, published_fluxes, strict=True):
        assert float(row["length (s)"]) == FLUX_WINDOW_S
        assert int(row["valid"]) == published["n_valid"]
        for column, label in (
            ("u* (m/s)", "friction_velocity_mps"),
            ("u'w' (m²/s²)", "u_w_m2_s2"),
            ("v'w' (m²/s²)", "v_w_m2_s2"),
            ("w'Ts' (K m/s)", "w_ts_k_mps"),
        ):
            assert_printed(row[column], published[label])
        assert_printed(row["tilt (deg)"], published["tilt_deg"], decimals=2)
        assert row["spikes u/v/w/Ts"] == "/".join(
            str(int(published[f"spikes_{c}"])) for c in ("u", "v", "w", "ts")
        )
        for column, label in (
            ("non-stationarity u'w' (%)", "stationarity_u_w_percent"),
            ("non-stationarity w'Ts' (%)", "stationarity_w_ts_percent"),
        ):
            assert_printed(row[column], published[label], decimals=1)
        assert_printed(row["coverage"], published["coverage"], decimals=4)
        assert_flag(row["flag"], published["quality_flag"])
    # 10 s windows of a simulated minute: before the alignment missing, then non-stationary
    assert {int(published["quality_flag"]) for published in published_fluxes} - {1}

    summary = (report / "summary.md").read_text()
    assert "](wind_fluxes.png)" in summary and "## Eddy-covariance fluxes" in summary
    assert coloured_share(report / "wind_fluxes.png") > MIN_COLOURED_SHARE
    flagged = sum(1 for published in published_fluxes if published["quality_flag"] != 1)
    assert f"| {FLUX_WINDOW_S:g} s flux windows flagged other than good | {flagged} of " in summary

    # the fluxes survive a saved report data file
    data = report_data_from_bag(processed)
    loaded = load_report_data(save_report_data(data, tmp_path / "run.npz")).fluxes
    # NaN fluxes of the missing windows included
    np.testing.assert_equal(
        [dataclasses.astuple(flux) for flux in loaded],
        [dataclasses.astuple(flux) for flux in data.fluxes],
    )


def test_a_bag_without_fluxes_gets_no_flux_table(sea_state_bags, tmp_path):
    _, processed, _ = sea_state_bags
    without_fluxes = tmp_path / "without_fluxes"
    with BagReader(processed) as reader, BagWriter(without_fluxes) as writer:
        assert any(name.startswith("/wind/fluxes_") for name in reader.topics)
        kept = [name for name in reader.topics if not name.startswith("/wind/fluxes_")]
        for message in reader.messages(kept):
            writer.write_raw(message.topic, message.msgtype, message.log_time_ns, message.raw)
    out = tmp_path / "report"
    assert main([str(without_fluxes), "--out", str(out)]) == 0
    for name in ("wind_products.md", "summary.md"):
        text = (out / name).read_text()
        assert "Eddy-covariance fluxes" not in text and "flux windows" not in text
        assert "| coverage | flag |" in text
    assert not (out / "wind_fluxes.png").exists()


def _turning_wind_data(north: str = "") -> ReportData:
    """20 minutes at 10 Hz of a 6 m/s wind whose direction turns from 300° through north to
    120° and back, the sensor axes turning with a buoy that swings about its mooring."""
    t_s = np.arange(0.0, 1201.0, 0.1)
    from_deg = 300.0 + 180.0 * np.sin(np.pi * t_s / t_s[-1])
    toward_rad = np.radians(from_deg + 180.0)
    corrected = np.column_stack(
        (6.0 * np.sin(toward_rad), 6.0 * np.cos(toward_rad), np.zeros_like(t_s))
    )
    corrected[3000:3100] = np.nan
    swing_rad = np.radians(200.0 * np.sin(2 * np.pi * t_s / 700.0))
    measured = np.column_stack(
        (6.0 * np.sin(toward_rad), 6.0 * np.cos(toward_rad), np.zeros_like(t_s))
    )
    measured[:, 0] = np.cos(swing_rad) * corrected[:, 0] - np.sin(swing_rad) * corrected[:, 1]
    measured[:, 1] = np.sin(swing_rad) * corrected[:, 0] + np.cos(swing_rad) * corrected[:, 1]
    return ReportData(
        t_s=t_s,
        measured_wind_sensor_mps=measured,
        corrected_wind_enu_mps=corrected,
        title="turning wind",
        north=north,
    )


def _direction_lines(figure) -> dict[str, np.ndarray]:
    direction_axis = figure.axes[1]
    return {line.get_label(): np.asarray(line.get_ydata()) for line in direction_axis.get_lines()}


def test_directions_are_drawn_continuous_and_true_to_the_wind_modulo_a_turn():
    data = _turning_wind_data()
    figure = figures.wind_time_series_figure(data)
    lines = _direction_lines(figure)
    for label, wind in (
        ("corrected", data.corrected_wind_enu_mps),
        ("measured (sensor axes)", data.measured_wind_sensor_mps),
    ):
        drawn = lines[label]
        finite = np.isfinite(drawn)
        # No step of a turn between neighbouring samples: the directions turn by less than a
        # degree from one to the next.
        assert np.nanmax(np.abs(np.diff(drawn))) < 1.0, label
        expected = np.degrees(np.arctan2(-wind[:, 0], -wind[:, 1])) % 360.0
        wrapped_error = (drawn[finite] - expected[finite] + 180.0) % 360.0 - 180.0
        assert np.abs(wrapped_error).max() < 1e-9, label
    # The corrected wind's 180° turn through north is one continuous line.
    corrected = lines["corrected"][np.isfinite(lines["corrected"])]
    assert 179.0 < np.ptp(corrected) < 181.0


def test_direction_ticks_are_quarters_labelled_within_a_turn():
    figure = figures.wind_time_series_figure(_turning_wind_data())
    direction_axis = figure.axes[1]
    FigureCanvasAgg(figure).draw()
    low, high = direction_axis.get_ylim()
    ticks = [t for t in direction_axis.get_yticks() if low <= t <= high]
    assert len(ticks) >= 3
    assert all(t % 90.0 == 0.0 for t in ticks), ticks
    labels = [label.get_text() for label in direction_axis.get_yticklabels() if label.get_text()]
    assert set(labels) <= {"0", "90", "180", "270", "360"}, labels
    assert [figures._direction_label(v) for v in (-90, 0, 90, 360, 450, 720)] == [
        "270",
        "0",
        "90",
        "360",
        "90",
        "360",
    ]


def test_the_direction_panel_names_the_north_of_the_data():
    for north, words in (
        ("magnetic_north", "clockwise from magnetic north (no declination applied)"),
        ("true_north", "clockwise from true north"),
        ("", "which north is not recorded"),
    ):
        figure = figures.wind_time_series_figure(_turning_wind_data(north))
        assert words in figure.axes[1].get_title(loc="left")


def test_the_five_thirds_line_lies_on_an_inertial_spectrum():
    # Vertical wind with a −5/3 spectrum: white noise shaped in frequency.
    rate_hz, n = 10.0, 12_000
    rng = np.random.default_rng(11)
    frequency_hz = np.fft.rfftfreq(n, 1.0 / rate_hz)
    shape = np.zeros_like(frequency_hz)
    shape[1:] = frequency_hz[1:] ** (-5.0 / 6.0)
    w = np.fft.irfft(np.fft.rfft(rng.normal(size=n)) * shape, n)
    w *= 0.5 / w.std()
    t_s = np.arange(n) / rate_hz
    wind = np.column_stack((np.full(n, 5.0), np.zeros(n), w))
    data = ReportData(t_s=t_s, measured_wind_sensor_mps=wind, corrected_wind_enu_mps=wind)
    figure = figures.vertical_wind_spectrum_figure(data)
    density_axis = figure.axes[0]
    lines = {line.get_label(): line for line in density_axis.get_lines()}
    reference = lines["f^(−5/3)"]
    spectrum_f, spectrum_s = (np.asarray(v) for v in lines["corrected"].get_data())
    line_f, line_s = (np.asarray(v) for v in reference.get_data())
    # Drawn over the spectrum's upper decade, and on it there: within 30 % at every band.
    assert line_f[0] >= spectrum_f[-1] / 10.0 - 1e-12 and line_f[-1] == spectrum_f[-1]
    on_line = np.isin(spectrum_f, line_f)
    ratio = line_s / spectrum_s[on_line]
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio
    np.testing.assert_allclose(line_s * line_f ** (5.0 / 3.0), line_s[0] * line_f[0] ** (5 / 3))


def test_a_flux_window_longer_than_the_record_is_drawn_over_the_data():
    data = _turning_wind_data()
    averager = FluxAverager(1800.0)
    fluxes = averager.add_batch(data.t_s, data.corrected_wind_enu_mps) + averager.flush()
    data = dataclasses.replace(data, fluxes=fluxes, time_origin_s=0.0)
    assert fluxes[0].window_end_s - fluxes[0].window_start_s == 1800.0
    figure = figures.fluxes_figure(data)
    segments = np.concatenate([c.get_segments() for c in figure.axes[0].collections])
    drawn_s = segments[:, :, 0]
    assert drawn_s.min() >= data.t_s[0] and drawn_s.max() <= data.t_s[-1]
    assert drawn_s.max() - drawn_s.min() > 0.99 * (data.t_s[-1] - data.t_s[0])
