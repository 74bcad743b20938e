"""Report figures, tables and the saved report data."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wind_comp.products import WindAverager
from wind_comp.report import (
    ReportData,
    ReportDataError,
    load_report_data,
    main,
    rpy_rad_from_quaternions,
    save_report_data,
    write_report,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


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
    averager = WindAverager(window_s=60.0)
    products = averager.add_batch(t_s, corrected) + averager.flush()
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
        products=products,
        title="test run",
    )


def test_report_with_truth_writes_all_figures_and_tables(tmp_path):
    paths = write_report(sample_data(with_truth=True), tmp_path / "report")
    names = sorted(path.name for path in paths)
    assert names == [
        "attitude_error.png",
        "vertical_wind_spectrum.png",
        "wind_products.md",
        "wind_time_series.png",
    ]
    for path in paths:
        if path.suffix == ".png":
            assert path.read_bytes()[:8] == PNG_SIGNATURE
            assert path.stat().st_size > 10_000
    table = (tmp_path / "report" / "wind_products.md").read_text()
    assert "Error against truth" in table
    assert table.count("| 60 |") == 3  # three 60 s windows in 130 s
    # Mean wind (6, -2) m/s toward ESE comes from 288.4°.
    assert "| 288.4 |" in table


def test_report_without_truth_skips_the_attitude_error(tmp_path):
    paths = write_report(sample_data(with_truth=False), tmp_path)
    assert sorted(path.name for path in paths) == [
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
    assert loaded.products == data.products
    assert loaded.title == "test run"
    assert main([str(saved), "--out", str(tmp_path / "out")]) == 0
    assert "wind_time_series.png" in capsys.readouterr().out
    assert (tmp_path / "out" / "attitude_error.png").exists()


def test_heading_error_is_wrapped_and_clockwise():
    from wind_comp.report import _attitude_errors_deg

    truth = np.radians([[0.0, 0.0, 179.0], [0.0, 0.0, 10.0]])
    estimate = np.radians([[1.0, -2.0, -179.0], [0.0, 0.0, 12.0]])
    errors = _attitude_errors_deg(estimate, truth)
    # Yaw grows counter-clockwise, heading clockwise: +2° of yaw is -2° of heading.
    np.testing.assert_allclose(errors, [[1.0, -2.0, -2.0], [0.0, 0.0, -2.0]], atol=1e-12)


def test_euler_angles_from_quaternions_follow_the_zyx_convention():
    roll, pitch, yaw = 0.1, -0.2, 2.5
    quat = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
    np.testing.assert_allclose(rpy_rad_from_quaternions([quat]), [[roll, pitch, yaw]])


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
