"""current_node: the ocean current from a DVL in water track, live (paper 003).

    current_node [--ros-args --params-file buoy.yaml --params-file current.yaml ...]

Subscribes (reliable, deep queue):

- ``dvl/velocity`` (geometry_msgs/TwistWithCovarianceStamped, frame ``dvl_link``): the DVL's
  velocity relative to the water in its own axes; NaN components for a ping it flags invalid
- ``nav/odometry`` and ``nav/fix``, as ``compensation_node`` takes them

Publishes:

- ``current/velocity`` (geometry_msgs/Vector3Stamped, frame ``map``): the current, ENU, m/s
  (where the water flows TOWARD), exactly one message per ``dvl/velocity`` message, with the
  same header stamp, in arrival order:

      current = v_nav + R_nb·(ω × l) − R_nb·R_bd·v_dvl

  with the navigation interpolated to the DVL's stamp (attitude R_nb by slerp, body rate ω and
  velocity v_nav linearly), R_bd and l the DVL's mounting and position. A sample that cannot be
  computed (a ping flagged invalid, a velocity beyond ``current.max_dvl_speed_mps``, another
  frame than ``current.dvl_frame_id`` (``dvl_link`` by default), a stamp not after the previous
  one, no navigation around its stamp) is published with NaN components, never dropped, and
  counted by reason; so is a sample whose 1σ exceeds ``current.max_current_sigma_*_mps``.
- ``current/velocity_with_covariance`` (geometry_msgs/TwistWithCovarianceStamped, frame
  ``map``): the same current with its ENU covariance (m²/s², from the navigation's
  covariances and the DVL message's own), as ``wind/true_with_covariance``.
- ``current/mean_1min``, ``current/mean_10min`` (geometry_msgs/Vector3Stamped, frame ``map``):
  vector mean of the current over each window, stamped with the window end.
- ``current/stats_1min``, ``current/stats_10min`` (std_msgs/Float64MultiArray): statistics of
  the same windows in the order of :data:`wind_comp.compensation_messages.CURRENT_STATS_FIELDS`
  (speed_mps, direction_deg (oceanographic, TOWARD), std_u_mps, std_v_mps, std_w_mps, n_valid,
  n_invalid, window_start_s, window_end_s, first_sample_s, last_sample_s, coverage,
  quality_flag, mean_u_standard_error_mps, mean_v_standard_error_mps,
  mean_w_standard_error_mps). A single DVL sample carries the waves' orbital velocity at the
  DVL's depth; the means average it away (see docs/benchmarks.md, "Current"), the standard
  deviations keep it.
- ``diagnostics``: DVL samples in and out, valid and invalid by reason, navigation samples seen,
  input rates, latency, rejected messages by reason.

Parameters: ``dvl.position`` (double[3], m, default [0, 0, -2]) and ``dvl.rpy_deg`` (double[3],
deg, default [0, 0, 0]) of the shared buoy file; every other
:class:`wind_comp.config.CurrentConfig` field as ``current.<field>``; and
``current.nav_timeout_s`` (s, default 5.0), the latency budget, as ``compensation_node``'s (a
current is an average over minutes: a DVL sample may well wait for late navigation).

A sample in another frame is logged once per frame as an error naming the frame expected; a
run whose samples came out mostly invalid ends with an error naming the main reason. On SIGINT
or SIGTERM the samples still waiting for navigation are published (invalid) before the node
exits with code 0.
"""

from __future__ import annotations

from geometry_msgs.msg import TwistWithCovarianceStamped

from buoy_common.base_node import main_for
from buoy_common.contract import (
    CURRENT_TOPIC,
    CURRENT_WITH_COVARIANCE_TOPIC,
    DVL_TOPIC,
    current_mean_topic,
    current_stats_topic,
)
from wind_comp.compensation_messages import dvl_record
from wind_comp.compensation_node import CorrectionNode
from wind_comp.config import (
    CURRENT_NAV_TIMEOUT,
    CURRENT_NODE_NAME,
    CURRENT_PARAMETER_PREFIX,
    CurrentConfig,
)
from wind_comp.pipeline import current_pipeline


class CurrentNode(CorrectionNode):
    def __init__(self):
        super().__init__(
            CURRENT_NODE_NAME,
            CURRENT_PARAMETER_PREFIX,
            CurrentConfig,
            current_pipeline,
            DVL_TOPIC,
            TwistWithCovarianceStamped,
            dvl_record,
            CURRENT_TOPIC,
            CURRENT_WITH_COVARIANCE_TOPIC,
            (current_mean_topic, current_stats_topic),
            "dvl",
            "dvl_frame_id",
            CURRENT_NAV_TIMEOUT,
        )


main = main_for(CurrentNode, __doc__)
