"""The year-shaped archive of the archive_year bench (tools/bench_archive_year.py), on two short
simulated motion-pack files: every hour of the year once, linked to a distinct hour; a sample
spread over the year; each sampled hour's products in the combined table once."""

from __future__ import annotations

import csv
import itertools

import pytest

from tools import bench_archive_year
from tools.bench_archive_year import (
    coverage,
    hours_of_year,
    link_tree,
    process_tree,
    processing_parameters,
    spread_sample,
)

SIMULATED_S = 150.0
DISTINCT = ("sway", "jonswap_tp_2_s")
HOURS_A_YEAR = 8760


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    directory = tmp_path_factory.mktemp("distinct")
    for name in DISTINCT:
        bench_archive_year.simulate_hour(directory / name, name, SIMULATED_S)
    return [directory / name for name in DISTINCT]


def test_the_year_tree_holds_every_hour_once_each_a_link_to_a_distinct_hour(sources, tmp_path):
    year = hours_of_year(2026)
    assert len(year) == len(set(year)) == HOURS_A_YEAR
    assert (year[0], year[-1]) == ("2026/01/01/00", "2026/12/31/23")
    assert len(hours_of_year(2028)) == HOURS_A_YEAR + 24
    tree = link_tree(tmp_path / "year", year, sources)
    targets = [(tree / relative).resolve() for relative in year]
    assert set(targets) == {source.resolve() for source in sources}
    assert sorted(p.relative_to(tree).as_posix() for p in tree.glob("*/*/*/*")) == year


def test_the_sample_is_spread_evenly_over_the_year():
    year = hours_of_year(2026)
    sample = spread_sample(year, 12)
    assert [relative[5:7] for relative in sample] == [f"{month:02d}" for month in range(1, 13)]
    positions = [year.index(relative) for relative in spread_sample(year, 100)]
    gaps = {later - earlier for earlier, later in itertools.pairwise(positions)}
    assert gaps <= {HOURS_A_YEAR // 100, HOURS_A_YEAR // 100 + 1}
    assert spread_sample(year, HOURS_A_YEAR + 1) == year


def test_each_sampled_hour_has_its_products_in_the_combined_table_once(sources, tmp_path):
    sample = spread_sample(hours_of_year(2026), 5)
    tree = link_tree(tmp_path / "sample", sample, sources)
    out = tmp_path / "out"
    run = process_tree(tree, out, processing_parameters(tmp_path / "params"), workers=1)
    assert run["files"] == len(sample)
    assert run["data_s"] == pytest.approx(len(sample) * SIMULATED_S, rel=0.01)
    covered = coverage(out, sample, sources)
    assert covered["complete"]
    products = 0
    for relative in sample:
        with (out / f"{relative}_wind_products.csv").open() as stream:
            products += sum(1 for _ in csv.DictReader(stream))
    assert covered["rows"] == products > len(sample)
    assert not list(out.rglob("*.mcap"))
    # What the hours' sensors leave unobserved (no GNSS) is kept with every hour.
    assert run["warnings"] and set(run["warnings"].values()) == {len(sample)}
    assert any("no velocity reference" in w or "mooring" in w for w in run["warnings"])
    # An hour the run did not process is missed, not passed over.
    unprocessed = "2026/06/15/12"
    missed = coverage(out, [*sample, unprocessed], sources)
    assert not missed["complete"]
    assert missed["missing"] == [unprocessed]
