"""What the configured and present sensors leave unobserved, derived from what each aiding
source of the registry declares it aids."""

from buoy_common.contract import (
    GNSS_BASELINE_TOPIC,
    GNSS_FIX_TOPIC,
    GNSS_VELOCITY_TOPIC,
    IMU_RAW_TOPIC,
    MAGNETOMETER_TOPIC,
)
from buoy_nav.aiding import AIDING_SOURCES, GnssFixSource, MagnetometerSource
from buoy_nav.config import FusionConfig
from buoy_nav.observability import unobserved_quantities

DUAL_ANTENNA = (IMU_RAW_TOPIC, GNSS_FIX_TOPIC, GNSS_VELOCITY_TOPIC, GNSS_BASELINE_TOPIC)


def test_the_dual_antenna_set_observes_everything_the_wind_needs():
    assert unobserved_quantities(FusionConfig(), DUAL_ANTENNA) == []
    assert unobserved_quantities(FusionConfig()) == []


def test_without_a_heading_reference_the_fusion_says_it_cannot_align():
    (sentence,) = unobserved_quantities(FusionConfig(), (GNSS_FIX_TOPIC, GNSS_VELOCITY_TOPIC))
    assert sentence.startswith("no heading reference: no dual-antenna GNSS")
    assert "magnetometer or motion pack" in sentence
    assert "cannot align" in sentence


def test_a_magnetometer_without_gnss_or_mooring_leaves_the_velocity_unobserved():
    velocity, position = unobserved_quantities(FusionConfig(), (MAGNETOMETER_TOPIC,))
    assert velocity.startswith("no velocity reference: no GNSS or moored constraint")
    assert "(switched off)" in velocity
    assert "grow without bound" in velocity
    assert position.startswith("no position reference: no GNSS")
    moored = unobserved_quantities(FusionConfig(moored=True), (MAGNETOMETER_TOPIC,))
    assert [s.split(":")[0] for s in moored] == ["no position reference", "mooring unverified"]


def test_a_mooring_is_unverified_only_without_a_gnss_fix_or_velocity():
    """The mooring is judged against what the receiver measures of the motion: a fix or a
    velocity is enough; with neither the statement says the assumption is unchecked."""
    config = FusionConfig(moored=True)
    (unverified,) = [
        s for s in unobserved_quantities(config, (MAGNETOMETER_TOPIC,)) if "mooring" in s
    ]
    assert "fusion.moored" in unverified and "σ is too small" in unverified
    for present in ((GNSS_FIX_TOPIC,), (GNSS_VELOCITY_TOPIC,)):
        sentences = unobserved_quantities(config, (MAGNETOMETER_TOPIC, *present))
        assert not any("mooring" in s for s in sentences)
    assert not any("mooring" in s for s in unobserved_quantities(FusionConfig(), ()))


def test_a_switched_off_source_does_not_count_and_is_named_so():
    config = FusionConfig(use_magnetometer=False, moored=True)
    heading, position, mooring = unobserved_quantities(config, (MAGNETOMETER_TOPIC,))
    assert heading.startswith("no heading reference")
    assert "magnetometer (switched off)" in heading
    assert position.startswith("no position reference")
    assert mooring.startswith("mooring unverified")


def test_the_sentences_follow_the_registry_it_is_given():
    """A registry of a fix alone leaves the heading unobserved; with a magnetometer, nothing."""
    assert unobserved_quantities(FusionConfig(), None, (GnssFixSource,)) == [
        "no heading reference: no source registered for it — the fusion cannot align: no "
        "navigation and no wind"
    ]
    assert unobserved_quantities(FusionConfig(), None, (GnssFixSource, MagnetometerSource)) == []
    assert unobserved_quantities(FusionConfig(), None, AIDING_SOURCES) == []
