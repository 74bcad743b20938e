"""``process_bag``: fusion and wind correction over a recorded bag, the offline twin of the nodes.

    process_bag IN_BAG OUT_BAG [--params-file buoy.yaml] [--params-file compensation.yaml]
                [--overwrite]

Runs over the bag's sensor topics, in log-time order, the same core as ``fusion_node`` followed
by ``compensation_node``: the navigation solutions pass through the numbers the ``nav/*``
messages carry, each gets the latitude of the solution before it (as the node gets it from
``nav/fix``), and every ``anemometer/wind`` sample yields exactly one ``wind/true`` (NaN when it
cannot be corrected). The new bag holds ``nav/*``, ``wind/true``, the wind products
(``wind/mean_<window>``, ``wind/stats_<window>``), the measured ``anemometer/wind`` and any
truth topics; every output message carries the log time of the input message after which it
was produced. The wind products are also written to ``<OUT_BAG>_wind_products.csv``.

Both outputs are written under temporary names beside them and appear only when complete; they
may not be, contain or lie inside IN_BAG. Exit codes: 0 done; 2 bad arguments, parameters or
bags (one line on stderr); 3 done, but IN_BAG was cut short (a recorder killed or out of power)
and was processed up to its last complete chunk (a warning says how much was read).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from collections import Counter, deque
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import NamedTuple

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from tqdm import tqdm

from buoy_common.bag_io import (
    RECOVERED_BAG_EXIT_CODE,
    BackgroundBagWriter,
    BagError,
    BagReader,
    BagWriter,
    Recovery,
    jazzy_typestore,
)
from buoy_common.contract import (
    NAV_FIX_TOPIC,
    NAV_MSGTYPES,
    NAV_ODOMETRY_TOPIC,
    WIND_RAW_TOPIC,
    WIND_TRUE_TOPIC,
    Reason,
    bag_topic,
    seconds_to_stamp,
    window_label,
)
from buoy_common.parameters import (
    ParameterError,
    build_config,
    load_parameter_files,
)
from buoy_common.safe_output import OutputError, check_outputs_apart_from_inputs, staged_file
from buoy_nav.config import FusionConfig
from buoy_nav.fuse_bag import (
    OfflineFusion,
    fusion_config_from_files,
    relative_topic,
    sensor_topics_of,
    truth_topics_of,
)
from wind_comp.compensator import (
    CompensatorConfig,
    CorrectedWind,
    WindCompensator,
    WindStatus,
)
from wind_comp.nav_messages import (
    StampOrder,
    WindSample,
    anemometer_sample,
    anemometer_sample_cdr,
    body_to_enu,
    checked_fix_latitude_deg,
    fix_fields_cdr,
    odometry_fields,
    odometry_fields_cdr,
    product_messages,
    remove_earth_rate,
    true_wind_cdr,
)
from wind_comp.products import WindAverager, WindProduct

COMPENSATION_NODE_NAME = "compensation_node"
TRUE_WIND_BAG_TOPIC = bag_topic(WIND_TRUE_TOPIC)
ODOMETRY_BAG_TOPIC = bag_topic(NAV_ODOMETRY_TOPIC)
NAV_FIX_BAG_TOPIC = bag_topic(NAV_FIX_TOPIC)
ODOMETRY_MSGTYPE = NAV_MSGTYPES[NAV_ODOMETRY_TOPIC]
NAV_FIX_MSGTYPE = NAV_MSGTYPES[NAV_FIX_TOPIC]
VECTOR3_STAMPED = "geometry_msgs/msg/Vector3Stamped"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
PRODUCTS_CSV_SUFFIX = "_wind_products.csv"
PROGRESS_EVERY_MESSAGES = 2000


def compensator_config_from_files(paths) -> CompensatorConfig:
    """The :class:`CompensatorConfig` ``compensation_node`` would build from these files."""
    values = load_parameter_files(paths, COMPENSATION_NODE_NAME)
    return build_config(CompensatorConfig, values, prefix="compensation.")


def products_csv_path(out_bag) -> Path:
    """Where the wind products of ``out_bag`` go: beside it, ``<name>_wind_products.csv``."""
    out_bag = Path(out_bag)
    if not out_bag.name:  # "." or "..": named after the directory it stands for
        out_bag = out_bag.resolve()
    return out_bag.with_name(out_bag.name + PRODUCTS_CSV_SUFFIX)


@dataclass
class ProcessSummary:
    """What a run did: counts of outputs and rejections, products, timing."""

    wind_status_counts: dict[WindStatus, int] = field(default_factory=dict)
    rejected_wind_messages: Counter = field(default_factory=Counter)
    products: list[WindProduct] = field(default_factory=list)
    topic_counts: dict[str, int] = field(default_factory=dict)
    fusion_lines: list[str] = field(default_factory=list)
    duration_s: float = 0.0
    wall_s: float = 0.0
    csv_path: Path | None = None
    recovery: Recovery | None = None


class CompensationResult(NamedTuple):
    """What :class:`OfflineCompensation` reports at the end of the data."""

    wind_status_counts: dict[WindStatus, int]
    rejected_wind_messages: Counter
    products: list[WindProduct]


class OfflineCompensation:
    """The compensation node's processing fed from the bag records being written.

    It takes what ``compensation_node`` subscribes to, as CDR bytes: ``nav/odometry`` and
    ``nav/fix`` as written by the fusion and the copied ``anemometer/wind`` (see
    :class:`CompensatingWriter`), so a solution gets the latitude of the ``nav/fix`` before it,
    as the node does, and writes ``wind/true`` and the products to the same bag. Navigation and
    wind samples are handed to the compensator in chunks of a quarter of ``nav_history_s`` of
    wind: its decisions depend on stamps only, so chunking changes nothing but the speed.
    """

    def __init__(
        self,
        writer: BagWriter | BackgroundBagWriter,
        config: CompensatorConfig,
        stored_wind_topic: str,
    ):
        self.compensator = WindCompensator(config)
        self.averagers = [
            WindAverager(window_s, config.gust_window_s) for window_s in config.product_windows_s
        ]
        self.writer = writer
        self.topics = {stored_wind_topic, ODOMETRY_BAG_TOPIC, NAV_FIX_BAG_TOPIC}
        self._wind_topic = stored_wind_topic
        self._typestore = jazzy_typestore()
        self.products: list[WindProduct] = []
        self.rejected: Counter[str] = Counter()
        self._chunk_s = config.nav_history_s / 4.0
        self._wind_order = StampOrder()
        self._pending_stamps: deque[tuple[int, int]] = deque()
        self._nav_chunk: list[tuple] = []
        self._wind_stamps_s: list[float] = []
        self._winds_sensor_mps: list[np.ndarray] = []
        self._latitude_deg = math.nan

    def take(self, topic: str, log_time_ns: int, raw: bytes) -> None:
        """One record of a topic in :attr:`topics`, as written to the bag."""
        if topic == ODOMETRY_BAG_TOPIC:
            fields = odometry_fields_cdr(raw)
            if fields is None:
                fields = odometry_fields(self._decode(raw, ODOMETRY_MSGTYPE))
            self._nav_chunk.append((*fields, self._latitude_deg))
        elif topic == NAV_FIX_BAG_TOPIC:
            fields = fix_fields_cdr(raw)
            if fields is None:
                message = self._decode(raw, NAV_FIX_MSGTYPE)
                fields = (message.status.status, message.latitude)
            latitude = checked_fix_latitude_deg(*fields)
            if latitude is not None:
                self._latitude_deg = latitude
        else:
            parsed = anemometer_sample_cdr(raw)
            if parsed is None:
                message = self._decode(raw, VECTOR3_STAMPED)
                stamp = message.header.stamp
                parsed = (anemometer_sample(message), stamp.sec, stamp.nanosec)
            self._add_sample(*parsed, log_time_ns)

    def _decode(self, raw: bytes, msgtype: str):
        return self._typestore.deserialize_cdr(raw, msgtype)

    def _add_sample(self, sample: WindSample, sec: int, nanosec: int, log_time_ns: int) -> None:
        if sample.rejection is not None:
            self.rejected[sample.rejection] += 1
        elif not self._wind_order.advance(sample.t_s):
            self.rejected[Reason.STAMP_NOT_INCREASING] += 1
        self._pending_stamps.append((sec, nanosec))
        self._wind_stamps_s.append(sample.t_s)
        self._winds_sensor_mps.append(sample.wind_sensor_mps)
        if sample.t_s - self._wind_stamps_s[0] >= self._chunk_s:
            self._process_chunk(log_time_ns)

    def finish(self, log_time_ns: int) -> CompensationResult:
        """End of data: every pending sample decided and written, partial windows closed."""
        self._process_chunk(log_time_ns)
        self._write_results(self.compensator.flush(), log_time_ns)
        for averager in self.averagers:
            self._write_products(averager.flush(), log_time_ns)
        return CompensationResult(dict(self.compensator.counts), self.rejected, self.products)

    def _process_chunk(self, log_time_ns: int) -> None:
        self._feed_navigation()
        if self._wind_stamps_s:
            self.compensator.add_wind_batch(
                np.array(self._wind_stamps_s), np.array(self._winds_sensor_mps)
            )
            self._wind_stamps_s, self._winds_sensor_mps = [], []
        self._write_results(self.compensator.ready(), log_time_ns)

    def _feed_navigation(self) -> None:
        """Convert the buffered solutions as the node converts ``nav/odometry``."""
        samples, self._nav_chunk = self._nav_chunk, []
        if not samples:
            return
        stamps, quats, rates, velocities_body, latitudes = (
            np.array(column) for column in zip(*samples, strict=True)
        )
        rates_nb = remove_earth_rate(rates, quats, latitudes)
        velocities_enu = body_to_enu(quats, velocities_body)
        self.compensator.add_nav_batch(stamps, quats, rates_nb, velocities_enu)

    def _write_results(self, results: list[CorrectedWind], log_time_ns: int) -> None:
        for result in results:
            sec, nanosec = self._pending_stamps.popleft()
            self.writer.write_raw(
                TRUE_WIND_BAG_TOPIC,
                VECTOR3_STAMPED,
                log_time_ns,
                true_wind_cdr(sec, nanosec, result.true_wind_enu_mps.tolist()),
            )
            for averager in self.averagers:
                self._write_products(
                    averager.add(result.t_s, result.true_wind_enu_mps), log_time_ns
                )

    def _write_products(self, products: list[WindProduct], log_time_ns: int) -> None:
        for product in products:
            self.products.append(product)
            mean, stats = product_messages(
                Vector3Stamped, Float64MultiArray, MultiArrayDimension, product
            )
            label = window_label(product.window_s)
            self.writer.write(bag_topic(f"wind/mean_{label}"), VECTOR3_STAMPED, log_time_ns, mean)
            self.writer.write(
                bag_topic(f"wind/stats_{label}"), FLOAT64_MULTI_ARRAY, log_time_ns, stats
            )


class CompensatingWriter:
    """Writes records to the output bag and hands the ones the compensation subscribes to over
    to it, as ``compensation_node`` receives what ``fusion_node`` publishes."""

    def __init__(self, writer: BackgroundBagWriter, compensation: OfflineCompensation):
        self._writer = writer
        self._compensation = compensation
        self._taken = compensation.topics

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes) -> None:
        self._writer.write_raw(topic, msgtype, log_time_ns, raw)
        if topic in self._taken:
            self._compensation.take(topic, log_time_ns, raw)


def write_products_csv(products: list[WindProduct], path: Path) -> None:
    """One row per closed averaging window; columns named with their units. The file appears
    only once complete."""
    names = [f.name for f in fields(WindProduct)]
    with staged_file(path) as stream:
        writer = csv.writer(stream)
        writer.writerow(names)
        for product in products:
            writer.writerow([_csv_value(getattr(product, name)) for name in names])


def _csv_value(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6f}"
    return str(value)


def process_bag(
    in_bag,
    out_bag,
    fusion_config: FusionConfig,
    compensator_config: CompensatorConfig,
    overwrite: bool = False,
) -> ProcessSummary:
    """Fuse and correct ``in_bag`` into ``out_bag`` and the products CSV beside it.

    OutputError, before anything is read or written, if an output is, contains or lies inside
    ``in_bag``. The fusion and the compensation run here; packing and writing the bag run in a
    process of their own, so the two share the machine's cores.
    """
    started = time.monotonic()
    csv_path = products_csv_path(out_bag)
    check_outputs_apart_from_inputs([in_bag], [out_bag, csv_path])
    with BagReader(in_bag) as reader:
        sensors = sensor_topics_of(reader, fusion_config, extra_required=(WIND_RAW_TOPIC,))
        stored_wind = next(n for n in reader.topics if relative_topic(n) == WIND_RAW_TOPIC)
        truth = truth_topics_of(reader)
        relative_of = {stored: relative for relative, stored in sensors.items()}
        with (
            tqdm(
                total=math.ceil(reader.duration_s),
                desc=f"process_bag {in_bag}",
                unit="bag s",
                disable=None,
            ) as progress,
            BackgroundBagWriter(out_bag, overwrite=overwrite) as bag_writer,
        ):
            compensation = OfflineCompensation(bag_writer, compensator_config, stored_wind)
            writer = CompensatingWriter(bag_writer, compensation)
            fusion = OfflineFusion(fusion_config, writer)
            topics = [*sensors.values(), stored_wind, *truth]
            log_time_ns = reader.start_ns
            for index, message in enumerate(reader.messages(topics)):
                log_time_ns = message.log_time_ns
                topic = relative_of.get(message.topic)
                if topic is None:
                    writer.write_raw(message.topic, message.msgtype, log_time_ns, message.raw)
                else:
                    fusion.add_message(reader, topic, message)
                if index % PROGRESS_EVERY_MESSAGES == 0:
                    progress.update(int((log_time_ns - reader.start_ns) * 1e-9) - progress.n)
            fusion.finish()
            result = compensation.finish(log_time_ns)
            progress.update(progress.total - progress.n)
        duration_s = reader.duration_s
    write_products_csv(result.products, csv_path)
    return ProcessSummary(
        wind_status_counts=result.wind_status_counts,
        rejected_wind_messages=result.rejected_wind_messages,
        products=result.products,
        topic_counts=bag_writer.counts,
        fusion_lines=fusion.summary(),
        duration_s=duration_s,
        wall_s=time.monotonic() - started,
        csv_path=csv_path,
        recovery=reader.recovery,
    )


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="process_bag", description=__doc__.split("\n")[0])
    parser.add_argument(
        "in_bag",
        help="bag with imu/data_raw, gnss/fix, gnss/heading, anemometer/wind"
        "[, gnss/vel, gnss/baseline]",
    )
    parser.add_argument("out_bag", help="bag directory to create")
    parser.add_argument(
        "--params-file",
        action="append",
        default=[],
        help="ROS parameter YAML as given to the nodes (repeatable; later files win)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing OUT_BAG")
    return parser.parse_args(argv)


def _print_summary(summary: ProcessSummary, out_bag: str) -> None:
    for line in summary.fusion_lines:
        print(line)
    counts = summary.wind_status_counts
    invalid = ", ".join(
        f"{status.reason} {n}" for status, n in counts.items() if status != WindStatus.VALID and n
    )
    print(
        f"wind samples: {sum(counts.values())} in, {counts.get(WindStatus.VALID, 0)} corrected, "
        f"invalid: {invalid or 'none'}"
    )
    for reason, n in sorted(summary.rejected_wind_messages.items()):
        print(f"rejected message {WIND_RAW_TOPIC}: {reason}: {n}")
    for product in summary.products:
        if product.window_end_s - product.window_start_s < product.window_s:
            continue
        start_sec, _ = seconds_to_stamp(product.window_start_s)
        print(
            f"{window_label(product.window_s):>6s} window from {start_sec}: "
            f"{product.vector_mean_speed_mps:6.2f} m/s from "
            f"{product.vector_mean_direction_deg:6.1f} deg, gust {product.gust_mps:6.2f} m/s, "
            f"{product.n_valid} valid / {product.n_invalid} invalid"
        )
    for topic, count in sorted(summary.topic_counts.items()):
        print(f"{topic:22s} {count:8d}")
    print(f"wrote {out_bag} and {summary.csv_path}")
    print(
        f"{summary.duration_s:.1f} s of data in {summary.wall_s:.1f} s "
        f"({summary.duration_s / max(summary.wall_s, 1e-9):.0f}x real time)"
    )


def main(argv=None) -> None:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    try:
        summary = process_bag(
            arguments.in_bag,
            arguments.out_bag,
            fusion_config_from_files(arguments.params_file),
            compensator_config_from_files(arguments.params_file),
            arguments.overwrite,
        )
    except (ParameterError, BagError, OutputError, OSError) as error:
        print(f"process_bag: {error}", file=sys.stderr)
        sys.exit(2)
    _print_summary(summary, arguments.out_bag)
    if summary.recovery is not None:
        print(
            f"process_bag: warning: {summary.recovery.describe(arguments.in_bag)}",
            file=sys.stderr,
        )
        if summary.recovery.truncated:
            sys.exit(RECOVERED_BAG_EXIT_CODE)
