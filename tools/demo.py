"""`make demo`: the whole suite live on a simulated buoy at sea, recorded, checked against truth.

Runs the `sea_state` scenario for 70 s at real time through `run_scenario`: the truth, IMU, GNSS
and anemometer simulators, the fusion node, the compensation node and the bag recorder, each its
own process talking over DDS. Then reads the recorded bag back and prints what was recorded, that
every anemometer sample got exactly one `wind/true`, the wind with and without motion correction
against the simulated truth, and the last 1-minute wind product; and the commands to watch
`wind/true` live and to draw the report of the bag.

    demo.py [--bag BAG]    (--bag: analyse an existing bag instead of running the simulation)
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from buoy_common.bag_io import BagReader
from buoy_common.contract import (
    NANOSECONDS_PER_SECOND,
    NAV_ODOMETRY_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
)
from buoy_processing.report.data import (
    ReportData,
    ReportDataError,
    report_data_from_bag,
    stamped_vectors,
    utc_text,
)
from tools.ros_domains import own_domain_unless_chosen
from wind_comp.config import compensator_config_from_files
from wind_comp.miller import mounting_rotation_from_rpy_deg
from wind_comp.products import WindAverager, meteorological_direction_deg

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PARAMS_FILE = REPO / "src/buoy_common/config/buoy.yaml"
SCENARIO = "sea_state"
# 70 s: the first 1-minute window (corrected from the filter's alignment at about 10 s on) closes
# with the first sample after 60 s, with a margin.
DURATION_S = 70
RATE_FACTOR = 1


def shown(path: Path) -> str:
    """``path`` relative to the repository when inside it, for commands the user can paste."""
    try:
        return str(path.resolve().relative_to(REPO))
    except ValueError:
        return str(path)


def record_live_run() -> Path:
    """Run the scenario with every node and the recorder, in a ROS domain of their own unless
    the caller chose one; return the new bag."""
    own_domain_unless_chosen("tools")
    name = time.strftime(f"{SCENARIO}_%Y%m%d_%H%M%S")
    bag = REPO / "out" / "demo" / name
    bag.parent.mkdir(parents=True, exist_ok=True)
    arguments = [
        SCENARIO,
        "--set",
        f"duration_s={DURATION_S}",
        "--rate-factor",
        str(RATE_FACTOR),
        "--params-file",
        shown(PARAMS_FILE),
        "--fusion",
        "--compensation",
        "--record",
        shown(bag),
        "--log-dir",
        shown(bag.with_name(name + "_logs")),
    ]
    print("+ run_scenario", " ".join(arguments), flush=True)
    runner = subprocess.Popen([str(BIN / "run_scenario"), *arguments], cwd=REPO)
    try:
        returncode = runner.wait()
    except KeyboardInterrupt:
        # Ctrl-C reached run_scenario too; it stops its nodes itself, which takes a moment.
        returncode = runner.wait()
    if returncode != 0:
        sys.exit(returncode)
    return bag


def print_topics(reader: BagReader) -> None:
    """Messages per topic and their rate over the span of their header stamps: what the nodes
    produced, whenever the recorder received it. Topics without a header get no rate."""
    first_s: dict[str, float] = {}
    last_s: dict[str, float] = {}
    for message in reader.messages():
        header = getattr(reader.decode(message), "header", None)
        if header is not None:
            t_s = header.stamp.sec + header.stamp.nanosec * 1e-9
            first_s.setdefault(message.topic, t_s)
            last_s[message.topic] = t_s
    print(f"\n{'topic':20s} {'messages':>8s} {'rate':>10s}")
    for topic, info in sorted(reader.topics.items()):
        span_s = last_s.get(topic, 0.0) - first_s.get(topic, 0.0)
        rate = ""
        if info.count > 1 and span_s > 0:
            rate_hz = (info.count - 1) / span_s
            rate = f"{rate_hz:.0f} Hz" if rate_hz >= 1 else f"1/{1 / rate_hz:.0f} s"
        print(f"{topic:20s} {info.count:8d} {rate:>10s}")


def print_one_output_per_sample(reader: BagReader, data: ReportData, aligned_s: float) -> None:
    """Check the contract: exactly one ``wind/true`` per ``anemometer/wind`` sample, same stamp.

    The recorder picks topics up as they appear, so the two topics may start being recorded at
    different moments; the check covers the stamps both were recorded over.
    """
    measured = stamped_vectors(reader, WIND_RAW_TOPIC).stamps_ns
    corrected = np.sort(stamped_vectors(reader, WIND_TRUE_TOPIC).stamps_ns)
    start, end = max(measured[0], corrected[0]), min(measured[-1], corrected[-1])
    measured_in_span = measured[(measured >= start) & (measured <= end)]
    corrected_in_span = corrected[(corrected >= start) & (corrected <= end)]
    outputs_per_sample = np.searchsorted(
        corrected, measured_in_span, side="right"
    ) - np.searchsorted(corrected, measured_in_span, side="left")
    exactly_one = bool(np.all(outputs_per_sample == 1)) and len(measured_in_span) == len(
        corrected_in_span
    )
    start_s, end_s = (stamp / NANOSECONDS_PER_SECOND - data.time_origin_s for stamp in (start, end))
    print(
        f"\n{WIND_RAW_TOPIC} -> {WIND_TRUE_TOPIC}, matched by header stamp over "
        f"{start_s:.2f}-{end_s:.2f} s (recorded on both):"
    )
    print(
        f"  {len(measured_in_span)} samples, {len(corrected_in_span)} {WIND_TRUE_TOPIC}, "
        f"exactly one per sample: {'yes' if exactly_one else 'NO'}"
    )
    outside = len(corrected) - len(corrected_in_span), len(measured) - len(measured_in_span)
    if any(outside):
        print(
            f"  recorded outside that span: {outside[0]} {WIND_TRUE_TOPIC}, "
            f"{outside[1]} {WIND_RAW_TOPIC} (the recorder subscribed one topic later)"
        )
    invalid = ~np.all(np.isfinite(data.corrected_wind_enu_mps), axis=1)
    before_alignment = data.t_s < aligned_s
    invalid_after = np.count_nonzero(invalid & ~before_alignment)
    print(
        f"  NaN {WIND_TRUE_TOPIC}: {np.count_nonzero(invalid & before_alignment)} before the "
        f"filter aligned at {aligned_s - data.time_origin_s:.2f} s, {invalid_after} after"
    )
    if invalid_after:
        # After alignment the live node gives a sample up only when navigation has not caught up
        # within compensation.nav_timeout_s; the recorder's receive times show how late it was.
        delay_s = max_delay_s(reader, NAV_ODOMETRY_TOPIC)
        print(
            f"  {NAV_ODOMETRY_TOPIC} reached the recorder up to {delay_s:.2f} s after its stamps: "
            "samples whose navigation\n  comes later than compensation.nav_timeout_s "
            "(default 1 s) are published invalid"
        )


def max_delay_s(reader: BagReader, topic: str) -> float:
    """Largest delay from header stamp to the recorder's log time of ``topic``'s messages, s."""
    delays_ns = [
        message.log_time_ns - _header_stamp_ns(reader.decode(message))
        for message in reader.messages([topic])
    ]
    return max(delays_ns, default=0) / NANOSECONDS_PER_SECOND


def _header_stamp_ns(message) -> int:
    return message.header.stamp.sec * NANOSECONDS_PER_SECOND + message.header.stamp.nanosec


def circular_mean_rad(angles_rad: np.ndarray) -> float:
    return math.atan2(np.mean(np.sin(angles_rad)), np.mean(np.cos(angles_rad)))


def print_comparison(data: ReportData, aligned_s: float) -> None:
    """Uncorrected and corrected wind against truth over the samples after alignment."""
    aligned_nav = data.attitude_t_s >= aligned_s
    mean_yaw_rad = circular_mean_rad(data.nav_rpy_rad[aligned_nav, 2])
    # Without motion correction a buoy reports the anemometer reading turned into ENU with the
    # mounting and the buoy's mean heading: its tilt, yaw swings, rotation and velocity all stay
    # in the wind. Mounting (anemometer→body) first, then body→ENU about the vertical.
    mounting = mounting_rotation_from_rpy_deg(
        compensator_config_from_files([str(PARAMS_FILE)]).anemometer_rpy_deg
    )
    mean_heading = Rotation.from_euler("z", mean_yaw_rad) * mounting
    uncorrected = mean_heading.apply(data.measured_wind_sensor_mps)
    usable = (
        (data.t_s >= aligned_s)
        & np.all(np.isfinite(data.corrected_wind_enu_mps), axis=1)
        & np.all(np.isfinite(data.true_wind_enu_mps), axis=1)
    )
    truth = data.true_wind_enu_mps[usable]
    stamps = data.t_s[usable] - data.time_origin_s
    print(
        f"\nwind after the filter aligned ({stamps[0]:.2f}-{stamps[-1]:.2f} s, "
        f"{np.count_nonzero(usable)} samples; mean heading "
        f"{(90.0 - math.degrees(mean_yaw_rad)) % 360.0:.1f} deg from North):"
    )
    print(
        f"{'':24s} {'mean speed':>10s} {'from':>7s} {'std w':>6s}   "
        f"{'RMS error vs truth (m/s)':>24s}"
    )
    print(f"{'':24s} {'(m/s)':>10s} {'(deg)':>7s} {'(m/s)':>6s}   {'u':>6s} {'v':>8s} {'w':>8s}")
    rows = [
        ("uncorrected (mean hdg)", uncorrected[usable]),
        ("corrected (wind/true)", data.corrected_wind_enu_mps[usable]),
        ("truth (truth/wind)", truth),
    ]
    for label, wind in rows:
        mean = wind.mean(axis=0)
        speed = np.hypot(wind[:, 0], wind[:, 1]).mean()
        direction = meteorological_direction_deg(mean[0], mean[1])
        line = f"{label:24s} {speed:10.2f} {direction:7.1f} {wind[:, 2].std():6.2f}"
        if wind is not truth:
            rms = np.sqrt(np.mean((wind - truth) ** 2, axis=0))
            line += f"   {rms[0]:6.3f} {rms[1]:8.3f} {rms[2]:8.3f}"
        print(line)


def print_last_minute(data: ReportData) -> None:
    """The last 1-minute product whose window the run completed, beside the same statistics of
    the truth at the samples the product used."""
    complete = [
        product
        for product in data.products
        if product.window_s == 60.0 and product.window_end_s <= data.t_s[-1]
    ]
    if not complete:
        print("\nno 1-minute window completed")
        return
    product = complete[-1]
    valid = np.all(np.isfinite(data.corrected_wind_enu_mps), axis=1)
    truth = np.where(valid[:, None], data.true_wind_enu_mps, np.nan)
    averager = WindAverager(product.window_s)
    truth_products = averager.add_batch(data.t_s, truth) + averager.flush()
    truth_product = next(p for p in truth_products if p.window_start_s == product.window_start_s)
    start, end = (utc_text(t_s)[11:19] for t_s in (product.window_start_s, product.window_end_s))
    print(
        f"\nlast 1-min product, {start}-{end} UTC, {product.n_valid} valid / "
        f"{product.n_invalid} invalid samples\n  {data.products_source}:"
    )
    print(
        f"{'':24s} {'vector mean':>11s} {'from':>6s} {'scalar mean':>11s} {'gust':>6s} "
        f"{'std u':>6s} {'std v':>6s} {'std w':>6s}"
    )
    print(f"{'':24s} {'(m/s)':>11s} {'(deg)':>6s} {'(m/s)':>11s}" + f" {'(m/s)':>6s}" * 4)
    for label, row in (("product", product), ("truth, same samples", truth_product)):
        print(
            f"{label:24s} {row.vector_mean_speed_mps:11.2f} {row.vector_mean_direction_deg:6.1f} "
            f"{row.scalar_mean_speed_mps:11.2f} {row.gust_mps:6.2f} {row.std_u_mps:6.2f} "
            f"{row.std_v_mps:6.2f} {row.std_w_mps:6.2f}"
        )


def analyse(bag: Path) -> int:
    try:
        data = report_data_from_bag(bag)
    except ReportDataError as error:
        print(f"demo: {error}", file=sys.stderr)
        return 1
    if data.attitude_t_s is None or not data.attitude_t_s.size or data.true_wind_enu_mps is None:
        print(f"demo: {shown(bag)} holds no nav/odometry or no truth/wind: nothing to compare")
        return 1
    aligned_s = float(data.attitude_t_s[0])
    with BagReader(bag) as reader:
        print(f"\n{shown(bag)}: {reader.duration_s:.1f} s recorded")
        print_topics(reader)
        print_one_output_per_sample(reader, data, aligned_s)
    print_comparison(data, aligned_s)
    print_last_minute(data)
    print(
        f"\nwatch {WIND_TRUE_TOPIC} live (two terminals, in {REPO}):\n"
        f"  .venv/bin/run_scenario {SCENARIO} --params-file {shown(PARAMS_FILE)} --compensation\n"
        "  .venv/bin/wind_echo --every 20"
    )
    print(
        f"draw the report of this bag (figures and tables into {shown(bag)}_report/):\n"
        f"  .venv/bin/wind_report {shown(bag)}"
    )
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="demo", description=__doc__.split("\n")[0])
    parser.add_argument("--bag", type=Path, help="analyse this bag instead of running the demo")
    arguments = parser.parse_args(argv)
    bag = arguments.bag or record_live_run()
    return analyse(bag)


if __name__ == "__main__":
    sys.exit(main())
