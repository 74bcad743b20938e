"""The ROS domains of the suite's live runs: disjoint ranges, valid domains, and a domain held by
one process is never handed to another until it is let go."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from tools import ros_domains
from tools.ros_domains import (
    DOMAIN_RANGES,
    MAX_DOMAIN,
    NoFreeDomainError,
    claim_domain,
    own_domain_unless_chosen,
    release_domain,
)

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_ranges_are_disjoint_valid_and_leave_the_default_domain():
    kinds = list(DOMAIN_RANGES)
    for index, kind in enumerate(kinds):
        domains = set(DOMAIN_RANGES[kind])
        assert domains, kind
        assert 0 not in domains, kind
        assert max(domains) <= MAX_DOMAIN, kind
        # DDS's ports of domain d start at 7400 + 250 d: from 102 to 214 they fall in the
        # 32768-60999 Linux lends to outgoing connections.
        assert not domains & set(range(102, 215)), kind
        for other in kinds[index + 1 :]:
            assert not domains & set(DOMAIN_RANGES[other]), (kind, other)


@pytest.fixture
def private_locks(tmp_path, monkeypatch):
    """Lock files of this test's own, apart from the runs on the machine."""
    monkeypatch.setattr(ros_domains, "_LOCK_DIRECTORY", tmp_path)
    return tmp_path


def hold_in_another_process(lock_directory, kind: str):
    """A process that claims every domain of ``kind``'s range but the first and holds them
    until its input closes; returns it once it holds them."""
    script = textwrap.dedent(
        f"""
        import sys
        from pathlib import Path
        from tools import ros_domains
        ros_domains._LOCK_DIRECTORY = Path({str(lock_directory)!r})
        for domain in list(ros_domains.DOMAIN_RANGES[{kind!r}])[1:]:
            assert ros_domains._try_lock(domain) is not None
        print("held", flush=True)
        sys.stdin.read()
        """
    )
    process = subprocess.Popen(
        [sys.executable, "-c", script],
        cwd=REPO,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert process.stdout.readline().strip() == "held"
    return process


def test_a_domain_held_elsewhere_is_never_claimed(private_locks):
    kind = "bench_live"
    first = DOMAIN_RANGES[kind][0]
    holder = hold_in_another_process(private_locks, kind)
    try:
        domain = claim_domain(kind)
        assert domain == first
        with pytest.raises(NoFreeDomainError, match=f"bench_live runs \\({first}-"):
            claim_domain(kind)
        release_domain(domain)
        assert claim_domain(kind) == first
        release_domain(first)
    finally:
        holder.stdin.close()
        holder.wait(timeout=10)
    # The holder's end lets its domains go.
    claimed = [claim_domain(kind) for _ in DOMAIN_RANGES[kind]]
    assert sorted(claimed) == list(DOMAIN_RANGES[kind])
    for domain in claimed:
        release_domain(domain)


def test_a_chosen_domain_is_kept_and_a_wrong_one_refused(private_locks, monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert own_domain_unless_chosen("tools") == 42
    for wrong in ("x1", "-3", "233"):
        monkeypatch.setenv("ROS_DOMAIN_ID", wrong)
        with pytest.raises(SystemExit, match="is no ROS domain"):
            own_domain_unless_chosen("tools")
    monkeypatch.delenv("ROS_DOMAIN_ID")
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")
    domain = own_domain_unless_chosen("tools")
    try:
        assert domain in DOMAIN_RANGES["tools"]
        assert os.environ["ROS_DOMAIN_ID"] == str(domain)
        assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
        assert "ROS_LOCALHOST_ONLY" not in os.environ
    finally:
        release_domain(domain)
