"""The ROS domains of the suite's own live runs: each kind of run a range of its own, each run a
domain no other run on the machine holds.

A fusion node never recovers once a second buoy's streams join its domain, and the tests, the
benchmarks, the soak and the demo of several checkouts may run side by side on one machine. So
the kinds never share a domain (disjoint ranges, declared here and nowhere else), and within
its range a run claims a domain by locking a file named after it in the temporary directory
(``flock``): the lock holds until the run releases it or its process ends, however it ends, and
a run that finds every domain of its range held says so instead of joining one.

The ranges lie in 0-101 and 215-232, whose DDS ports stay out of Linux's ephemeral port range
(32768-60999), where an outgoing connection of any program could take one of them; domain 0,
every ROS installation's default, is left to the nodes started by hand.
"""

from __future__ import annotations

import fcntl
import os
import random
import tempfile
from pathlib import Path

DOMAIN_RANGES = {
    "tests": range(1, 80),
    "tools": range(80, 90),
    "bench_live": range(90, 102),
    "soak": range(215, 233),
}
"""Which ROS domains each kind of live run takes: ``tests`` the node tests (tests/conftest.py),
``tools`` the demo and the recording of the committed bags (``make demo``, ``make bags``),
``bench_live`` the live benchmark (tools/bench_live.py), ``soak`` the soak (tools/soak.py)."""

MAX_DOMAIN = 232
"""The largest domain whose DDS ports fit in 16 bits."""
_LOCK_DIRECTORY = Path(tempfile.gettempdir())
_held: dict[int, int] = {}
"""The domains this process holds, with the descriptor of each one's locked file."""


class NoFreeDomainError(RuntimeError):
    """Every domain of a range is held by other runs on this machine."""


def _lock_path(domain: int) -> Path:
    return _LOCK_DIRECTORY / f"buoy-wind-ros-domain-{domain}.lock"


def _try_lock(domain: int) -> int | None:
    """The descriptor of ``domain``'s lock file, locked; None when another process holds it."""
    descriptor = os.open(_lock_path(domain), os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(descriptor)
        return None
    return descriptor


def claim_domain(kind: str) -> int:
    """A domain of ``kind``'s range that no other run on this machine holds, held by this
    process until :func:`release_domain` or its end; NoFreeDomainError when there is none."""
    candidates = [domain for domain in DOMAIN_RANGES[kind] if domain not in _held]
    random.shuffle(candidates)
    for domain in candidates:
        descriptor = _try_lock(domain)
        if descriptor is not None:
            _held[domain] = descriptor
            return domain
    first, last = DOMAIN_RANGES[kind][0], DOMAIN_RANGES[kind][-1]
    raise NoFreeDomainError(
        f"every ROS domain of the {kind} runs ({first}-{last}) is held by another run on this "
        f"machine (lock files {_lock_path(first)} ... {_lock_path(last).name})"
    )


def release_domain(domain: int) -> None:
    """Let other runs take ``domain`` again (nothing when this process does not hold it)."""
    descriptor = _held.pop(domain, None)
    if descriptor is not None:
        os.close(descriptor)


def isolated_environment(domain: int, environment: dict[str, str]) -> dict[str, str]:
    """``environment`` put in ``domain`` with discovery kept on this machine (in place; also
    returned)."""
    environment["ROS_DOMAIN_ID"] = str(domain)
    environment["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    environment.pop("ROS_LOCALHOST_ONLY", None)
    return environment


def own_domain_unless_chosen(kind: str) -> int:
    """For a command-line tool: the caller's ``ROS_DOMAIN_ID`` when it set one; otherwise a
    claimed domain of ``kind``, set with loopback discovery in this process's environment (its
    children inherit both). SystemExit with the reason when neither can be had."""
    chosen = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if chosen:
        if not chosen.isdigit() or int(chosen) > MAX_DOMAIN:
            raise SystemExit(f"ROS_DOMAIN_ID={chosen!r} is no ROS domain (0-{MAX_DOMAIN})")
        return int(chosen)
    try:
        domain = claim_domain(kind)
    except NoFreeDomainError as error:
        raise SystemExit(str(error)) from None
    isolated_environment(domain, os.environ)
    return domain
