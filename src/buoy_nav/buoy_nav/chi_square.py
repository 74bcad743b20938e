"""The chi-square quantiles every judgement of the fusion is made against: the gate's, a
contradiction's and a watch's, computed one way."""

from __future__ import annotations

from scipy.special import gammaincinv

AGREEMENT_PROBABILITY = 0.99
"""A contradiction is lifted once the evidence is below this chi-square quantile: a source
whose evidence hovers about the contradiction's quantile does not flap in and out."""


def chi_square_quantile(dimension: int, probability: float) -> float:
    """The chi-square quantile of ``probability`` with ``dimension`` degrees of freedom, as
    scipy.stats.chi2.ppf computes it, without the half second that importing scipy.stats adds
    to the start of every node and tool."""
    return float(2.0 * gammaincinv(0.5 * dimension, probability))
