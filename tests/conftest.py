"""Fixtures shared by the whole test tree: isolated DDS domains and node processes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tools.ros_domains import claim_domain, isolated_environment, release_domain

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def _isolated_ros_environment(domain: int) -> dict[str, str]:
    """An environment whose DDS traffic stays on loopback, in ``domain`` (claimed from the
    tests' range of tools/ros_domains.py, so that no other run on the machine uses it)."""
    env = isolated_environment(domain, dict(os.environ))
    env["AMENT_PREFIX_PATH"] = str(BIN.parent)
    env["PYTHONUNBUFFERED"] = "1"
    return env


class NodeProcesses:
    """Starts suite executables as separate processes in one isolated domain; stops them all."""

    def __init__(self, log_dir: Path):
        self.domain = claim_domain("tests")
        self.env = _isolated_ros_environment(self.domain)
        self.log_dir = log_dir
        self.processes: list[tuple[str, subprocess.Popen]] = []

    def start(self, executable: str, *args: str) -> subprocess.Popen:
        log = open(self.log_dir / f"{executable}-{len(self.processes)}.log", "w")  # noqa: SIM115
        process = subprocess.Popen(
            [str(BIN / executable), *args],
            env=self.env,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self.processes.append((executable, process))
        return process

    def run(self, executable: str, *args: str, timeout_s: float = 120.0):
        """Run an executable to completion in this domain; returns the CompletedProcess."""
        return subprocess.run(
            [str(BIN / executable), *args],
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout_s,
        )

    def interrupt(self, process: subprocess.Popen, timeout_s: float = 15.0) -> int:
        """SIGINT, as Ctrl-C would; returns the exit code."""
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        try:
            return process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
            raise

    def log_of(self, process: subprocess.Popen) -> str:
        for index, (executable, candidate) in enumerate(self.processes):
            if candidate is process:
                return (self.log_dir / f"{executable}-{index}.log").read_text()
        raise KeyError(process)

    def stop_all(self) -> None:
        for _, process in self.processes:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 15.0
        for _, process in self.processes:
            try:
                process.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        release_domain(self.domain)


# Tests that run nodes over DDS share one pytest-xdist worker, one after another: side by side
# on a 2-core machine their nodes would starve each other of the CPU their latency budgets
# assume. The offline tests of one module stay on one worker too, so that a module's fixtures
# (simulated bags, processed bags) are made once rather than once per worker.
LIVE_FIXTURES = {"nodes", "ros_env", "module_ros_env"}


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the groups
def pytest_collection_modifyitems(config, items):
    for item in items:
        if LIVE_FIXTURES & set(item.fixturenames) or item.get_closest_marker("ros"):
            item.add_marker(pytest.mark.xdist_group("live"))
        else:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))


@pytest.fixture
def nodes(tmp_path):
    """Start node executables in an isolated DDS domain; all are stopped after the test."""
    processes = NodeProcesses(tmp_path)
    yield processes
    processes.stop_all()


@pytest.fixture
def ros_env():
    """An isolated environment for subprocesses that talk DDS."""
    domain = claim_domain("tests")
    yield _isolated_ros_environment(domain)
    release_domain(domain)


@pytest.fixture(scope="module")
def module_ros_env():
    """An isolated environment shared by the tests of one module (expensive shared runs)."""
    domain = claim_domain("tests")
    yield _isolated_ros_environment(domain)
    release_domain(domain)
