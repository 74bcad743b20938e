"""The aiding sources one engine runs: built from their classes, checked to be told apart, and
found by the measurement type or the topic they take."""

from collections.abc import Iterable

from buoy_nav.aiding.base import AIDED_QUANTITIES, AidingSource
from buoy_nav.config import FusionConfig
from buoy_nav.health import IMU
from buoy_nav.state_layout import StateLayout


class SourceRegistry:
    """One instance of each class of ``source_classes``, in their order (the order of the stacked
    update of one stamp), built from ``config`` and the error states ``states``.

    Raises ValueError when two sources share a kind, a measurement type or a topic, when a kind
    is that of the IMU, or when a source aids a quantity not in :data:`AIDED_QUANTITIES`.
    """

    def __init__(
        self,
        config: FusionConfig,
        states: StateLayout,
        source_classes: Iterable[type[AidingSource]],
    ):
        self.sources: tuple[AidingSource, ...] = tuple(
            source(config, states) for source in source_classes
        )
        self.kinds: tuple[str, ...] = tuple(source.kind for source in self.sources)
        self._of_type = {source.measurement_type: source for source in self.sources}
        self._of_topic = {source.topic: source for source in self.sources if not source.pseudo}
        self.pseudo: tuple[AidingSource, ...] = tuple(
            source for source in self.sources if source.pseudo and source.enabled
        )
        """The enabled constraints that read no topic: the engine asks them at IMU samples."""
        self._check_distinct()
        self.aided_index = {source: AIDED_QUANTITIES.index(source.aids) for source in self.sources}
        """Index in :data:`AIDED_QUANTITIES` of what each source aids."""

    def _check_distinct(self) -> None:
        kinds = self.kinds
        if len(set(kinds)) != len(kinds) or IMU in kinds:
            raise ValueError(f"aiding sources need distinct kinds other than '{IMU}': {kinds}")
        topic_sources = sum(1 for source in self.sources if not source.pseudo)
        if len(self._of_type) != len(kinds) or len(self._of_topic) != topic_sources:
            raise ValueError("aiding sources need distinct measurement types and topics")
        for source in self.sources:
            if source.aids not in AIDED_QUANTITIES:
                raise ValueError(
                    f"{source.kind} aids '{source.aids}', not one of {AIDED_QUANTITIES}"
                )

    def of_measurement(self, measurement) -> AidingSource:
        """The source whose ``measurement_type`` ``measurement`` is (TypeError naming the type
        when none is: a programming error)."""
        source = self._of_type.get(type(measurement))
        if source is None:
            raise TypeError(f"no aiding source of the fusion takes {type(measurement).__name__}")
        return source

    def of_topic(self, topic: str) -> AidingSource:
        """The source that reads ``topic`` (ValueError naming it when none does)."""
        source = self._of_topic.get(topic)
        if source is None:
            raise ValueError(f"'{topic}' is not an input topic of the fusion")
        return source
