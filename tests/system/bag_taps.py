"""A tap for :class:`buoy_common.bag_io.BackgroundBagWriter` in tests: importable by name in the
writing process, which unpickles it there."""

from std_msgs.msg import Float64MultiArray


class EchoTap:
    """A tap that writes, for every record of ``topic``, its log time as a Float64MultiArray
    record of ``echo_topic``, and reports how many it took and the end log time."""

    def __init__(self, writer, topic, echo_topic):
        self.writer = writer
        self.topics = {topic}
        self.echo_topic = echo_topic
        self.taken = 0

    def take(self, topic, log_time_ns, raw):
        self.taken += 1
        self.writer.write(
            self.echo_topic,
            "std_msgs/msg/Float64MultiArray",
            log_time_ns,
            Float64MultiArray(data=[float(log_time_ns)]),
        )

    def finish(self, log_time_ns):
        return self.taken, log_time_ns
