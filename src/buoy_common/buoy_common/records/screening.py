"""Screening a record's raw values: which samples are data and why the others are not.

A logger marks a missing measurement with a fill code (OOI's FDCHP writes 32767, the largest
16-bit word, for every word of a failed sonic); an instrument flags a bad one with an invalid
code; and a value outside what the quantity can plausibly be is out of range. Each is imported
as an invalid sample (NaN), never as data, and counted apart, so that a user sees how much of a
record was missing, flagged or implausible. Codes and ranges are in the record's own unit,
before any scaling, where the logger wrote them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FieldCounts:
    """How one field's samples were screened: every sample read is in exactly one of
    ``filled``, ``invalid``, ``out_of_range`` or data (``valid``)."""

    read: int
    filled: int
    """Equal to one of the field's fill codes."""
    invalid: int
    """Equal to one of its invalid codes, or not a finite number in the record."""
    out_of_range: int
    """A finite value, no code, outside the field's valid range."""

    @property
    def valid(self) -> int:
        return self.read - self.filled - self.invalid - self.out_of_range

    def as_dict(self) -> dict[str, int]:
        return {
            "read": self.read,
            "filled": self.filled,
            "invalid": self.invalid,
            "out_of_range": self.out_of_range,
        }


@dataclass(frozen=True)
class Screening:
    """Boolean masks of the samples of one field that are not data, one reason each (a fill
    code first, then an invalid code or a non-number, then the range)."""

    filled: np.ndarray
    invalid: np.ndarray
    out_of_range: np.ndarray

    @property
    def rejected(self) -> np.ndarray:
        return self.filled | self.invalid | self.out_of_range

    def counts(self) -> FieldCounts:
        return FieldCounts(
            read=int(self.filled.size),
            filled=int(np.count_nonzero(self.filled)),
            invalid=int(np.count_nonzero(self.invalid)),
            out_of_range=int(np.count_nonzero(self.out_of_range)),
        )


def screen(
    raw_values: np.ndarray,
    fill_codes: tuple[float, ...],
    invalid_codes: tuple[float, ...],
    valid_range: tuple[float, float],
) -> Screening:
    """Which of ``raw_values`` (record units) are a fill code, an invalid code or not a finite
    number, or outside ``valid_range`` (inclusive bounds, record units)."""
    values = np.asarray(raw_values, dtype=float)
    filled = np.isin(values, fill_codes)
    invalid = ~filled & (~np.isfinite(values) | np.isin(values, invalid_codes))
    with np.errstate(invalid="ignore"):
        outside = (values < valid_range[0]) | (values > valid_range[1])
    out_of_range = outside & ~filled & ~invalid
    return Screening(filled=filled, invalid=invalid, out_of_range=out_of_range)
