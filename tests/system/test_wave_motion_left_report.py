"""The wave motion left, through ``process_bag`` and ``wind_report``, on a buoy that heaves.

Seven minutes of ``open_ocean`` (JONSWAP sea, Tp 9 s) simulated and processed with 6-min flux
windows: the fused navigation's correction leaves no wave motion in w (the test passes, the
window's wave band holds 1/Tp); the report's figure plots each window's published share and
coherence with its flag, read back from the matplotlib figure against the bag's own messages;
and the vertical wind spectrum shades the wave band of the record's own heave.
About a minute and a half on two cores: a long run.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from buoy_common.bag_io import BagReader
from buoy_common.contract import NAV_VELOCITY_TOPIC, WIND_FLUXES_PREFIX, QualityFlag
from buoy_nav.config import fusion_config_from_files
from buoy_processing.bag_processing import process_bag
from buoy_processing.report import figures
from buoy_processing.report.data import report_data_from_bag
from buoy_processing.wind_report import main
from sensor_sim.simulate_bag import parse_arguments, simulate
from wind_comp.compensation_messages import stats_values
from wind_comp.config import compensator_config_from_files
from wind_comp.wave_motion_left import DEFAULT_THRESHOLDS, platform_wave_band_hz

pytestmark = pytest.mark.long

REPO = Path(__file__).resolve().parents[2]
PEAK_PERIOD_S = 9.0
FLUX_WINDOW_S = 360.0
DURATION_S = 420.0


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("open_ocean")
    sensors, processed = folder / "sensors", folder / "processed"
    flux_window = folder / "flux_window.yaml"
    flux_window.write_text(
        f"/**:\n  ros__parameters:\n    compensation:\n      flux_window_s: {FLUX_WINDOW_S}\n"
    )
    files = [str(REPO / "src/buoy_common/config/buoy.yaml"), str(flux_window)]
    simulate(
        parse_arguments(
            ["open_ocean", str(sensors), "--set", f"duration_s={DURATION_S:g}"]
            + [argument for path in files for argument in ("--params-file", path)]
        )
    )
    process_bag(
        sensors, processed, fusion_config_from_files(files), compensator_config_from_files(files)
    )
    return processed


def published_fluxes(bag) -> list[dict[str, float]]:
    """Every ``wind/fluxes_*`` message as {label: value}, straight from the bag."""
    with BagReader(bag) as reader:
        topics = [n for n in reader.topics if n.lstrip("/").startswith(WIND_FLUXES_PREFIX)]
        rows = [stats_values(reader.decode(message)) for message in reader.messages(topics)]
    return sorted(rows, key=lambda row: row["window_start_s"])


def test_the_correction_of_a_heaving_buoy_leaves_no_wave_motion(processed):
    evaluated = [row for row in published_fluxes(processed) if row["motion_left_flag"] != 2]
    assert evaluated, "a full 6-min window is long enough to judge"
    for row in evaluated:
        assert row["wave_band_low_hz"] <= 1.0 / PEAK_PERIOD_S <= row["wave_band_high_hz"], row
        assert row["motion_left_share"] < DEFAULT_THRESHOLDS.suspect_share, row
        assert row["motion_left_flag"] == QualityFlag.GOOD


def plotted_points(axis) -> list[tuple[float, float, int]]:
    """(x, y, flag) of every marker the axis plots, the flag from the marker's legend."""
    points = []
    for line in axis.lines:
        if not line.get_label().startswith("flag "):
            continue
        flag = int(line.get_label().split()[1])
        points += [(x, y, flag) for x, y in zip(line.get_xdata(), line.get_ydata(), strict=True)]
    return sorted(points)


def test_the_figure_plots_each_windows_published_wave_motion_left(processed):
    data = report_data_from_bag(processed)
    share_axis, coherence_axis = figures.wave_motion_left_figure(data).axes
    judged = [row for row in published_fluxes(processed) if row["motion_left_flag"] != 2]
    assert judged
    for axis, label in (
        (share_axis, "motion_left_share"),
        (coherence_axis, "motion_left_coherence"),
    ):
        expected = sorted(
            (
                0.5 * (row["window_start_s"] + row["window_end_s"]) - data.time_origin_s,
                row[label],
                int(row["motion_left_flag"]),
            )
            for row in judged
        )
        plotted = plotted_points(axis)
        assert [flag for _, _, flag in plotted] == [flag for _, _, flag in expected]
        np.testing.assert_allclose(
            [point[:2] for point in plotted], [point[:2] for point in expected], rtol=1e-12
        )
    thresholds = {line.get_ydata()[0] for line in share_axis.lines if line.get_linestyle() == "--"}
    assert thresholds == {DEFAULT_THRESHOLDS.suspect_share, DEFAULT_THRESHOLDS.fail_share}
    (threshold_line,) = [line for line in coherence_axis.lines if line.get_marker() == "_"]
    rows = published_fluxes(processed)
    np.testing.assert_allclose(
        threshold_line.get_ydata(), [row["motion_left_coherence_threshold"] for row in rows]
    )


def test_the_spectrum_shades_the_records_own_wave_band(processed, monkeypatch, tmp_path):
    drawn = {}
    save = figures._save

    def keep(figure, path, *arguments, **keywords):
        drawn[path.name] = figure
        return save(figure, path, *arguments, **keywords)

    monkeypatch.setattr(figures, "_save", keep)
    assert main([str(processed), "--out", str(tmp_path)]) == 0
    assert (tmp_path / "wave_motion_left.png").is_file()
    density_axis = drawn["vertical_wind_spectrum.png"].axes[0]
    (span,) = [p for p in density_axis.patches if p.get_label() == "wave band (platform heave)"]
    shaded = (span.get_x(), span.get_x() + span.get_width())
    # The record's heave, from its nav/velocity messages (ENU), read here on their own.
    with BagReader(processed) as reader:
        rows = []
        for message in reader.messages([NAV_VELOCITY_TOPIC]):
            decoded = reader.decode(message)
            stamp = decoded.header.stamp
            rows.append((stamp.sec + stamp.nanosec * 1e-9, decoded.twist.twist.linear.z))
    t_s, up_mps = np.array(rows).T
    expected = platform_wave_band_hz(t_s, up_mps, float(np.median(np.diff(t_s))))
    np.testing.assert_allclose(shaded, expected, rtol=1e-6)
    assert expected[0] <= 1.0 / PEAK_PERIOD_S <= expected[1]
