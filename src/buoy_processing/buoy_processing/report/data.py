"""Everything a wind report shows, as plain arrays, and where it comes from.

:class:`ReportData` holds the anemometer's samples, the corrected wind, the true wind and the
attitude errors when known, and the averaged wind products. :func:`report_data_from_bag`
gathers them from a bag that holds ``anemometer/wind`` and ``wind/true`` (written by
``process_bag`` or recorded from the running nodes), with the truth and navigation topics when
present; :func:`save_report_data` and :func:`load_report_data` keep them in a ``.npz`` file.

The readers below (:func:`stamped_vectors`, :func:`odometry_series`, :func:`vectors_at_stamps`,
:func:`interpolate_vectors`) turn a topic into arrays by header stamp; the benchmark reads its
bags with them too.
"""

import datetime
import math
import sys
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import NamedTuple, get_type_hints

import numpy as np

from buoy_common.bag_io import BagError, BagReader
from buoy_common.contract import (
    NANOSECONDS_PER_SECOND,
    NAV_ODOMETRY_TOPIC,
    TRUTH_ODOMETRY_TOPIC,
    TRUTH_WIND_TOPIC,
    WIND_FLUXES_PREFIX,
    WIND_MEAN_PREFIX,
    WIND_RAW_TOPIC,
    WIND_STATS_PREFIX,
    WIND_TRUE_TOPIC,
    QualityFlag,
    window_label,
)
from buoy_common.namespaces import TopicView
from buoy_nav.rotations import rotate_by_quaternion_components
from buoy_processing.bag_processing import WIND_PRODUCTS_CSV_SUFFIX
from buoy_processing.output_facts import (
    clockwise_from_north_text,
    north_token_of_bag,
    sensor_text_of_bag,
)
from buoy_processing.report.attitude import (
    interpolate_rpy_rad,
    rpy_rad_from_quaternions,
    rpy_sigma_rad,
)
from wind_comp.compensation_messages import stats_values
from wind_comp.config import CompensatorConfig
from wind_comp.flux_products import FluxProduct
from wind_comp.products import WindAverager, WindProduct

# Plots count time from the start of the minute of the first sample, so simulated runs (which
# start on a whole minute) show scenario time and the 1-minute windows start on round numbers.
_TIME_ORIGIN_STEP_S = 60


class ReportDataError(ValueError):
    """Report input arrays are missing or have inconsistent shapes."""


@dataclass(eq=False)
class ReportData:
    """Everything a report shows, as plain arrays.

    Attributes:
        t_s: (N,) anemometer sample stamps, s.
        measured_wind_sensor_mps: (N, 3) measured air velocity in anemometer axes, m/s.
        corrected_wind_enu_mps: (N, 3) motion-corrected wind, ENU, m/s (NaN where invalid).
        true_wind_enu_mps: (N, 3) true wind, ENU, m/s, or None when unknown.
        attitude_t_s: (M,) stamps of the attitude series, s, or None.
        nav_rpy_rad: (M, 3) estimated roll, pitch, yaw (R = Rz(yaw)·Ry(pitch)·Rx(roll)), rad.
        truth_rpy_rad: (M, 3) true roll, pitch, yaw at ``attitude_t_s``, rad, or None.
        nav_rpy_sigma_rad: (M, 3) the filter's 1σ of the estimated roll, pitch and yaw, rad, or
            None (see :func:`rpy_sigma_rad`).
        nav_up_velocity_mps: (M,) the navigation's vertical velocity of the body origin (ENU
            up, m/s) at ``attitude_t_s``, or None: the platform motion whose spectrum gives the
            record's wave band.
        products: averaged wind products.
        fluxes: the eddy-covariance fluxes per window, as published (``wind/fluxes_<window>``;
            empty when the source has none: the report does not compute them).
        title: figure title prefix, e.g. the scenario name.
        time_origin_s: stamp (s) that the time axes of the figures count from.
        products_source: where the products come from, stated under their table.
        north: the north the directions are referenced to, as
            :attr:`~buoy_processing.output_facts.OutputFacts.north_token` (``true_north``,
            ``magnetic_north``); empty when the source does not record it.
        sensors: the sensors the outputs rest on, in words
            (:meth:`~buoy_processing.output_facts.OutputFacts.sensor_text`); empty when the
            source does not record them.
    """

    t_s: np.ndarray
    measured_wind_sensor_mps: np.ndarray
    corrected_wind_enu_mps: np.ndarray
    true_wind_enu_mps: np.ndarray | None = None
    attitude_t_s: np.ndarray | None = None
    nav_rpy_rad: np.ndarray | None = None
    truth_rpy_rad: np.ndarray | None = None
    nav_rpy_sigma_rad: np.ndarray | None = None
    nav_up_velocity_mps: np.ndarray | None = None
    products: list[WindProduct] = field(default_factory=list)
    fluxes: list[FluxProduct] = field(default_factory=list)
    title: str = ""
    time_origin_s: float = 0.0
    products_source: str = ""
    north: str = ""
    sensors: str = ""

    @property
    def sensors_sentence(self) -> str:
        """Which sensors the outputs rest on, or that the source does not say."""
        if self.sensors:
            return f"Sensors used: {self.sensors}."
        return (
            "The sensors used are not recorded with these data (a bag recorded from the nodes, "
            "or processed before process_bag stored its outputs' facts in the bag)."
        )

    @property
    def north_text(self) -> str:
        """``clockwise from true north`` (or the north the data have), for labels."""
        return clockwise_from_north_text(self.north)

    def __post_init__(self):
        self.t_s = _array("t_s", self.t_s, (None,))
        n_samples = self.t_s.shape[0]
        for name in ("measured_wind_sensor_mps", "corrected_wind_enu_mps"):
            setattr(self, name, _array(name, getattr(self, name), (n_samples, 3)))
        if self.true_wind_enu_mps is not None:
            self.true_wind_enu_mps = _array(
                "true_wind_enu_mps", self.true_wind_enu_mps, (n_samples, 3)
            )
        if (self.nav_rpy_rad is None) != (self.attitude_t_s is None):
            raise ReportDataError("attitude_t_s and nav_rpy_rad must be given together")
        for name in ("truth_rpy_rad", "nav_rpy_sigma_rad", "nav_up_velocity_mps"):
            if getattr(self, name) is not None and self.nav_rpy_rad is None:
                raise ReportDataError(f"{name} needs attitude_t_s and nav_rpy_rad")
        if self.attitude_t_s is not None:
            self.attitude_t_s = _array("attitude_t_s", self.attitude_t_s, (None,))
            n_attitudes = self.attitude_t_s.shape[0]
            for name in ("nav_rpy_rad", "truth_rpy_rad", "nav_rpy_sigma_rad"):
                if getattr(self, name) is not None:
                    setattr(self, name, _array(name, getattr(self, name), (n_attitudes, 3)))
            if self.nav_up_velocity_mps is not None:
                self.nav_up_velocity_mps = _array(
                    "nav_up_velocity_mps", self.nav_up_velocity_mps, (n_attitudes,)
                )


def _array(name: str, values, shape: tuple) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as error:
        raise ReportDataError(f"{name} must be a numeric array ({error})") from error
    expected = tuple(array.shape[0] if size is None and array.ndim else size for size in shape)
    if array.ndim != len(shape) or array.shape != expected:
        wanted = ", ".join("N" if size is None else str(size) for size in shape)
        wanted = f"({wanted},)" if len(shape) == 1 else f"({wanted})"
        raise ReportDataError(f"{name} must have shape {wanted}, got {array.shape}")
    return array


_ARRAY_FIELDS = (
    "t_s",
    "measured_wind_sensor_mps",
    "corrected_wind_enu_mps",
    "true_wind_enu_mps",
    "attitude_t_s",
    "nav_rpy_rad",
    "truth_rpy_rad",
    "nav_rpy_sigma_rad",
    "nav_up_velocity_mps",
)
_PRODUCT_PREFIX = "product_"
_FLUX_PREFIX = "flux_"


def save_report_data(data: ReportData, path) -> Path:
    """Store ``data`` as a NumPy ``.npz`` file readable by :func:`load_report_data`."""
    arrays = {
        name: getattr(data, name) for name in _ARRAY_FIELDS if getattr(data, name) is not None
    }
    for prefix, windows in ((_PRODUCT_PREFIX, data.products), (_FLUX_PREFIX, data.fluxes)):
        for window_field in fields(type(windows[0])) if windows else ():
            arrays[prefix + window_field.name] = np.array(
                [getattr(window, window_field.name) for window in windows], dtype=float
            )
    path = Path(path)
    np.savez(
        path,
        title=np.array(data.title),
        time_origin_s=np.array(data.time_origin_s),
        products_source=np.array(data.products_source),
        north=np.array(data.north),
        sensors=np.array(data.sensors),
        **arrays,
    )
    return path


def load_report_data(path) -> ReportData:
    """Read a file written by :func:`save_report_data`."""
    try:
        stored = np.load(path)
    except (OSError, ValueError) as error:
        raise ReportDataError(f"{path}: not a readable report data file ({error})") from error
    with stored:
        missing = [name for name in _ARRAY_FIELDS[:3] if name not in stored]
        if missing:
            raise ReportDataError(f"{path}: missing array(s) {missing}")
        arrays = {name: stored[name] for name in _ARRAY_FIELDS if name in stored}
        products = _stored_windows(stored, _PRODUCT_PREFIX, WindProduct)
        fluxes = _stored_windows(stored, _FLUX_PREFIX, FluxProduct)
        title = str(stored["title"]) if "title" in stored else ""
        time_origin_s = float(stored["time_origin_s"]) if "time_origin_s" in stored else 0.0
        source = str(stored["products_source"]) if "products_source" in stored else ""
        north = str(stored["north"]) if "north" in stored else ""
        sensors = str(stored["sensors"]) if "sensors" in stored else ""
    return ReportData(
        **arrays,
        products=products,
        fluxes=fluxes,
        title=title,
        time_origin_s=time_origin_s,
        products_source=source,
        north=north,
        sensors=sensors,
    )


def _stored_windows(stored, prefix: str, window_class) -> list:
    """The windows (``window_class`` instances) stored as one column per field under
    ``prefix``; none when the file has no such columns."""
    columns = {
        window_field.name: stored[prefix + window_field.name]
        for window_field in fields(window_class)
        if prefix + window_field.name in stored
    }
    count = min((len(column) for column in columns.values()), default=0)
    return [
        _window(window_class, {name: column[i] for name, column in columns.items()})
        for i in range(count)
    ]


def _window(window_class, values: dict):
    """A ``window_class`` (a product dataclass) of ``values`` (field name: number), its counts
    and flags as integers."""
    types = get_type_hints(window_class)
    return window_class(
        **{
            name: int(value) if types[name] is int else float(value)
            for name, value in values.items()
        }
    )


class StampedVectors(NamedTuple):
    """The ``Vector3Stamped`` messages of one topic, in bag order."""

    stamps_ns: np.ndarray
    """(N,) int64 header stamps, ns since the epoch."""
    vectors: np.ndarray
    """(N, 3) vector components, in the topic's unit and frame."""


def stored_topic(reader: BagReader, topic: str) -> str | None:
    """The name under which ``reader`` stores relative ``topic`` (with or without "/"), or None."""
    for candidate in (topic, "/" + topic.lstrip("/")):
        if candidate in reader.topics:
            return candidate
    return None


def has_messages(reader: BagReader, topic: str) -> bool:
    """Whether ``reader``'s bag holds messages of relative ``topic``."""
    name = stored_topic(reader, topic)
    return name is not None and reader.topics[name].count > 0


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * NANOSECONDS_PER_SECOND + int(header.stamp.nanosec)


def stamped_vectors(reader: BagReader, topic: str) -> StampedVectors:
    """Header stamps and vectors of every ``Vector3Stamped`` message of ``topic``."""
    stamps, vectors = [], []
    for message in reader.messages([topic]):
        decoded = reader.decode(message)
        stamps.append(_stamp_ns(decoded.header))
        vectors.append((decoded.vector.x, decoded.vector.y, decoded.vector.z))
    return StampedVectors(
        np.array(stamps, dtype=np.int64), np.array(vectors, dtype=float).reshape(-1, 3)
    )


class OdometrySeries(NamedTuple):
    """The ``Odometry`` messages of one topic, in bag order."""

    stamps_ns: np.ndarray
    """(M,) int64 header stamps, ns since the epoch."""
    quat_xyzw: np.ndarray
    """(M, 4) body→ENU attitudes."""
    angular_rate_body_rad_s: np.ndarray
    """(M, 3) ``twist.twist.angular``: body rate, body axes, rad/s."""
    velocity_body_mps: np.ndarray
    """(M, 3) ``twist.twist.linear``: velocity of the body origin, body axes, m/s."""
    attitude_covariance_enu_rad2: np.ndarray
    """(M, 3, 3) the pose covariance's rotation block: the ENU rotation-vector error, rad²."""


def odometry_series(reader: BagReader, topic: str) -> OdometrySeries:
    """Stamps, attitudes, body rates and velocities and attitude covariances of every
    ``Odometry`` message of ``topic``."""
    stamps, quats, rates, velocities, covariances = [], [], [], [], []
    for message in reader.messages([topic]):
        decoded = reader.decode(message)
        orientation = decoded.pose.pose.orientation
        twist = decoded.twist.twist
        stamps.append(_stamp_ns(decoded.header))
        quats.append((orientation.x, orientation.y, orientation.z, orientation.w))
        rates.append((twist.angular.x, twist.angular.y, twist.angular.z))
        velocities.append((twist.linear.x, twist.linear.y, twist.linear.z))
        covariances.append(np.reshape(decoded.pose.covariance, (6, 6))[3:, 3:])
    return OdometrySeries(
        np.array(stamps, dtype=np.int64),
        np.array(quats, dtype=float).reshape(-1, 4),
        np.array(rates, dtype=float).reshape(-1, 3),
        np.array(velocities, dtype=float).reshape(-1, 3),
        np.array(covariances, dtype=float).reshape(-1, 3, 3),
    )


def vectors_at_stamps(stamps_ns: np.ndarray, source: StampedVectors) -> np.ndarray:
    """(N, 3): for each stamp (ns), the vector of the ``source`` message carrying exactly that
    header stamp; NaN where no message does."""
    order = np.argsort(source.stamps_ns, kind="stable")
    sorted_stamps = source.stamps_ns[order]
    matched = np.full((len(stamps_ns), 3), np.nan)
    if sorted_stamps.size == 0:
        return matched
    index = np.minimum(np.searchsorted(sorted_stamps, stamps_ns), sorted_stamps.size - 1)
    found = sorted_stamps[index] == stamps_ns
    matched[found] = source.vectors[order[index[found]]]
    return matched


def interpolate_vectors(stamps_ns: np.ndarray, source: StampedVectors) -> np.ndarray:
    """(N, 3) ``source`` vectors linearly interpolated at ``stamps_ns`` (ns); NaN outside the
    span of the source stamps."""
    interpolated = np.full((len(stamps_ns), 3), np.nan)
    if source.stamps_ns.size == 0:
        return interpolated
    order = np.argsort(source.stamps_ns, kind="stable")
    # Relative seconds keep nanosecond resolution that epoch seconds in float64 would lose.
    origin_ns = source.stamps_ns[order[0]]
    source_t_s = (source.stamps_ns[order] - origin_ns) * 1e-9
    t_s = (np.asarray(stamps_ns, dtype=np.int64) - origin_ns) * 1e-9
    for axis in range(3):
        interpolated[:, axis] = np.interp(
            t_s, source_t_s, source.vectors[order, axis], left=np.nan, right=np.nan
        )
    return interpolated


def report_data_from_bag(
    bag, title: str | None = None, view: TopicView | None = None
) -> ReportData:
    """The :class:`ReportData` of a bag holding ``anemometer/wind`` and ``wind/true``.

    - ``t_s`` and the measured wind: every ``anemometer/wind`` message (header stamps).
    - corrected wind: the ``wind/true`` message with the same header stamp, NaN when none.
    - true wind (with ``truth/wind``): interpolated linearly to the anemometer stamps.
    - attitude (with ``nav/odometry``): at the navigation stamps, with ``truth/odometry``
      slerped to them.
    - products: the ``wind/stats_<window>`` messages (mean vectors from ``wind/mean_<window>``)
      when the bag has them, otherwise recomputed from the corrected wind with the default
      windows of the compensation.
    - fluxes: the ``wind/fluxes_<window>`` messages, when the bag has them (never recomputed:
      their parameters, such as the planar fit, are the processing's, not the report's).

    Topics are read in ``view``'s namespace (the root when None).

    Raises :class:`ReportDataError` (one line) for a missing or unreadable bag or one without
    the two wind topics.
    """
    try:
        with BagReader(bag, view) as reader:
            if reader.recovery is not None:
                print(f"wind_report: warning: {reader.recovery.describe(bag)}", file=sys.stderr)
            return _report_data(reader, Path(bag).name if title is None else title)
    except BagError as error:
        raise ReportDataError(str(error)) from error


def _report_data(reader: BagReader, title: str) -> ReportData:
    required = (WIND_RAW_TOPIC, WIND_TRUE_TOPIC)
    missing = [topic for topic in required if not has_messages(reader, topic)]
    if missing:
        raise ReportDataError(
            f"bag {reader.path} has no {' and no '.join(missing)} messages; a wind report needs "
            f"{' and '.join(required)} (a bag written by process_bag, or recorded with "
            "compensation_node running)"
        )
    measured = stamped_vectors(reader, WIND_RAW_TOPIC)
    corrected = vectors_at_stamps(measured.stamps_ns, stamped_vectors(reader, WIND_TRUE_TOPIC))
    t_s = measured.stamps_ns / NANOSECONDS_PER_SECOND
    true_wind = None
    if has_messages(reader, TRUTH_WIND_TOPIC):
        true_wind = interpolate_vectors(
            measured.stamps_ns, stamped_vectors(reader, TRUTH_WIND_TOPIC)
        )
    attitude_t_s = nav_rpy = truth_rpy = nav_rpy_sigma = nav_up_velocity = None
    if has_messages(reader, NAV_ODOMETRY_TOPIC):
        nav = odometry_series(reader, NAV_ODOMETRY_TOPIC)
        attitude_t_s = nav.stamps_ns / NANOSECONDS_PER_SECOND
        nav_rpy = rpy_rad_from_quaternions(nav.quat_xyzw)
        nav_rpy_sigma = rpy_sigma_rad(nav_rpy, nav.attitude_covariance_enu_rad2)
        velocity_enu = rotate_by_quaternion_components(nav.quat_xyzw.T, nav.velocity_body_mps.T)
        nav_up_velocity = velocity_enu[2]
        if has_messages(reader, TRUTH_ODOMETRY_TOPIC):
            truth = odometry_series(reader, TRUTH_ODOMETRY_TOPIC)
            truth_rpy = interpolate_rpy_rad(nav.stamps_ns, truth.stamps_ns, truth.quat_xyzw)
    products, products_source = _products(reader, t_s, corrected)
    fluxes = published_fluxes(reader)
    minute_ns = _TIME_ORIGIN_STEP_S * NANOSECONDS_PER_SECOND
    return ReportData(
        t_s=t_s,
        measured_wind_sensor_mps=measured.vectors,
        corrected_wind_enu_mps=corrected,
        true_wind_enu_mps=true_wind,
        attitude_t_s=attitude_t_s,
        nav_rpy_rad=nav_rpy,
        truth_rpy_rad=truth_rpy,
        nav_rpy_sigma_rad=nav_rpy_sigma,
        nav_up_velocity_mps=nav_up_velocity,
        products=products,
        fluxes=fluxes,
        title=title,
        time_origin_s=float(measured.stamps_ns[0] // minute_ns * _TIME_ORIGIN_STEP_S),
        products_source=products_source,
        north=north_token_of_bag(reader.path, WIND_PRODUCTS_CSV_SUFFIX),
        sensors=sensor_text_of_bag(reader.path),
    )


def _products(
    reader: BagReader, t_s: np.ndarray, corrected_wind_enu_mps: np.ndarray
) -> tuple[list[WindProduct], str]:
    """The bag's published wind products, or products recomputed from the corrected wind; and a
    sentence saying which."""
    stats_topics = sorted(
        name for name in reader.topics if name.lstrip("/").startswith(WIND_STATS_PREFIX)
    )
    if stats_topics:
        per_topic = {topic: _published_products(reader, topic) for topic in stats_topics}
        products = sorted(
            (product for topic_products in per_topic.values() for product in topic_products),
            key=lambda product: (product.window_s, product.window_start_s),
        )
        by_window = sorted(
            per_topic, key=lambda topic: min((p.window_s for p in per_topic[topic]), default=0.0)
        )
        return products, "published on " + ", ".join(name.lstrip("/") for name in by_window)
    defaults = {field.name: field.default for field in fields(CompensatorConfig)}
    windows_s = defaults["product_windows_s"]
    gust_window_s = defaults["gust_window_s"]
    products = []
    for window_s in windows_s:
        averager = WindAverager(window_s, gust_window_s)
        products += averager.add_batch(t_s, corrected_wind_enu_mps) + averager.flush()
    labels = " and ".join(window_label(window_s) for window_s in windows_s)
    return products, (
        f"recomputed from {WIND_TRUE_TOPIC}, {labels} windows, {gust_window_s:g} s gust "
        f"(the bag has no {WIND_STATS_PREFIX}* topic)"
    )


def _published_products(reader: BagReader, stats_topic: str) -> list[WindProduct]:
    """Products from the ``wind/stats_<window>`` messages of ``stats_topic``, each with the mean
    vector of the ``wind/mean_<window>`` message stamped at the window end (when recorded; else
    u and v from speed and direction, and w NaN). The gust window is not published: NaN."""
    mean_topic = stored_topic(
        reader, WIND_MEAN_PREFIX + stats_topic.lstrip("/").removeprefix(WIND_STATS_PREFIX)
    )
    means = (
        stamped_vectors(reader, mean_topic)
        if mean_topic
        else StampedVectors(np.empty(0, dtype=np.int64), np.empty((0, 3)))
    )
    products = []
    for message in reader.messages([stats_topic]):
        try:
            values = stats_values(reader.decode(message))
            product = _product_from_stats(values, means)
        except (KeyError, ValueError) as error:
            raise ReportDataError(
                f"bag {reader.path}: {stats_topic} message at log time {message.log_time_ns} ns "
                f"is not a wind statistics layout ({error})"
            ) from error
        products.append(product)
    return products


def _product_from_stats(values: dict[str, float], means: StampedVectors) -> WindProduct:
    end_ns = round(values["window_end_s"] * NANOSECONDS_PER_SECOND)
    mean = vectors_at_stamps(np.array([end_ns], dtype=np.int64), means)[0]
    if np.isnan(mean[0]):
        speed = values["vector_mean_speed_mps"]
        from_rad = math.radians(values["vector_mean_direction_deg"])
        mean = np.array([-speed * math.sin(from_rad), -speed * math.cos(from_rad), math.nan])
    return WindProduct(
        window_s=values["window_end_s"] - values["window_start_s"],
        window_start_s=values["window_start_s"],
        window_end_s=values["window_end_s"],
        first_sample_s=values["first_sample_s"],
        last_sample_s=values["last_sample_s"],
        n_valid=int(values["n_valid"]),
        n_invalid=int(values["n_invalid"]),
        mean_u_enu_mps=float(mean[0]),
        mean_v_enu_mps=float(mean[1]),
        mean_w_enu_mps=float(mean[2]),
        vector_mean_speed_mps=values["vector_mean_speed_mps"],
        vector_mean_direction_deg=values["vector_mean_direction_deg"],
        scalar_mean_speed_mps=values["scalar_mean_speed_mps"],
        gust_mps=values["gust_mps"],
        gust_window_s=math.nan,
        std_u_mps=values["std_u_mps"],
        std_v_mps=values["std_v_mps"],
        std_w_mps=values["std_w_mps"],
        # Bags written before coverage was published carry neither: not evaluated.
        coverage=values.get("coverage", math.nan),
        quality_flag=int(values.get("quality_flag", QualityFlag.NOT_EVALUATED)),
        # Bags written before the standard errors were published carry none: unknown.
        mean_u_standard_error_mps=values.get("mean_u_standard_error_mps", math.nan),
        mean_v_standard_error_mps=values.get("mean_v_standard_error_mps", math.nan),
        mean_w_standard_error_mps=values.get("mean_w_standard_error_mps", math.nan),
    )


def published_fluxes(reader: BagReader) -> list[FluxProduct]:
    """The flux windows of every ``wind/fluxes_<window>`` topic of ``reader``'s bag, as
    published (each message's values taken by their ``layout.dim`` labels), ordered by window
    length and start; none when the bag has no such topic."""
    topics = [name for name in reader.topics if name.lstrip("/").startswith(WIND_FLUXES_PREFIX)]
    if not topics:
        return []
    names = [flux_field.name for flux_field in fields(FluxProduct)]
    # Bags written before the wave motion left or the named flux tests were published lack the
    # fields appended with them: their values unknown, their tests not evaluated.
    appended = names[names.index("quality_flag") + 1 :]
    absent = {
        name: QualityFlag.NOT_EVALUATED if name.endswith("_flag") else math.nan for name in appended
    }
    fluxes = []
    for message in reader.messages(topics):
        try:
            values = {**absent, **stats_values(reader.decode(message))}
            fluxes.append(_window(FluxProduct, {name: values[name] for name in names}))
        except (KeyError, ValueError) as error:
            raise ReportDataError(
                f"bag {reader.path}: {message.topic} message at log time {message.log_time_ns} "
                f"ns is not a flux layout ({error})"
            ) from error
    return sorted(fluxes, key=lambda flux: (flux.window_s, flux.window_start_s))


def wind_series(data: ReportData) -> list[tuple[str, np.ndarray, str]]:
    """(label, (N, 3) wind, style) of each series; the measured one is in sensor axes."""
    series = [
        ("measured (sensor axes)", data.measured_wind_sensor_mps, "tab:gray"),
        ("corrected", data.corrected_wind_enu_mps, "tab:blue"),
    ]
    if data.true_wind_enu_mps is not None:
        series.append(("true", data.true_wind_enu_mps, "tab:green"))
    return series


def titled(data: ReportData, what: str) -> str:
    """A figure or table title: ``what``, after the run's title when it has one."""
    return f"{data.title}: {what}" if data.title else what


def utc_text(t_s: float) -> str:
    """ISO 8601 UTC time of ``t_s`` (s since the epoch), whole seconds."""
    moment = datetime.datetime.fromtimestamp(t_s, tz=datetime.UTC)
    return moment.strftime("%Y-%m-%dT%H:%M:%SZ")
