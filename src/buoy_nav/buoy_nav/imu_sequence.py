"""IMU samples out of the accepted sequence, held until they prove to be the IMU's.

A second IMU publishing on the same topic (another buoy's nodes on the same ROS domain) looks,
sample by sample, like a step of the IMU's clock or the end of an outage: its stamps lie off the
buoy's own, back or ahead. What tells it apart is that the buoy's own samples go on between its
samples. So a sample that does not follow the latest one of the accepted sequence at the IMU's
rate (:data:`buoy_nav.imu_clock.SEQUENCE_INTERVALS`) never moves the filter's time: it is held.
Held samples that follow each other make a new sequence; when its stamps span
:data:`CONFIRMING_SPAN_S` with no sample of the accepted sequence in between, the accepted
sequence has stopped and the new one is the IMU's (after a step of its clock, or an outage): its
samples are released, none lost. A sample of the accepted sequence gives the held ones up: they
were another stream's (or a single stale sample), and are counted rejected.

Messages arrive in bursts (a recorder or a busy middleware delivers a topic's messages up to a
second late and together), so the span is far longer than a burst: a second stream interleaved
with the IMU's never spans it, and a real step or outage only delays the samples after it.
"""

import math

CONFIRMING_SPAN_S = 2.0
"""Span of stamps (s) over which held samples must follow each other, with none of the accepted
sequence in between, to be the IMU's new sequence."""


class HeldSequence:
    """Samples (stamp s, ω_ib body rad/s, specific force body m/s²) out of the accepted
    sequence, oldest first, that follow each other at the IMU's rate."""

    def __init__(self):
        self.samples: list[tuple] = []
        self.newest_aiding_s = -math.inf
        """The newest aiding stamp (s) when the first held sample came."""

    def confirmed(self) -> bool:
        """Whether the held samples span :data:`CONFIRMING_SPAN_S`."""
        samples = self.samples
        return bool(samples) and samples[-1][0] - samples[0][0] >= CONFIRMING_SPAN_S

    def take(self) -> list[tuple]:
        """The held samples, leaving none."""
        samples, self.samples = self.samples, []
        return samples
