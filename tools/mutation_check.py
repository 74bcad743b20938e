"""Mutation check of the physics (`make mutants`): flip a sign or a convention of the core and
see which tests fail.

Each mutant is a few edits (file, exact original text, replacement) applied to a copy of the
repository in a temporary directory, never to the working tree; the copy's packages are put
first on PYTHONPATH, so the tests and every executable they start (nodes, ``process_bag``) run
the mutated code. On the unmutated copy and on each mutant the script runs the packages' unit
tests (``src/*/test``) and the system tests that judge results against the simulator's truth
(:data:`SYSTEM_TESTS`; those about bag files, tools and packaging are left out, no mutant here
touches them). A test catches a mutant when it fails on the mutant, passes on the unmutated
copy, and, if it talks to nodes over DDS, fails again when rerun alone. Every mutant must be
caught by at least one unit test and at least one system test; the script prints a table and
exits with 1 otherwise (or when a mutant no longer applies because the code it edits moved).

    python -m tools.mutation_check                 # every mutant (about an hour on two cores)
    python -m tools.mutation_check --only gravity  # some of them
    python -m tools.mutation_check --list          # the mutants and their edits
    python -m tools.mutation_check --first-catch --workers 2   # quicker: see below

``--first-catch`` stops each mutant's system run at its first catching test (pytest ``-x``,
the unmutated copy's own failures deselected), so the table names one catching system test
per mutant rather than all of them; ``--workers N`` runs the system tests on N pytest-xdist
workers, the live ones on one of them as in ``make test``; ``--system-tests`` picks the modules.

The unit tests of several mutants run in parallel (``--jobs``); the system tests, whose live
tests are sensitive to a busy machine, one mutant at a time. Results go to
``out/mutants/results.json``.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("buoy_common", "sensor_sim", "buoy_nav", "wind_comp", "buoy_processing")
UNIT_TESTS = tuple(f"src/{package}/test" for package in PACKAGES)
SYSTEM_TESTS = (
    "tests/system/test_fuse_bag.py",
    "tests/system/test_process_bag.py",
    "tests/system/test_wind_report.py",
    "tests/system/test_nav_simulated.py",
    "tests/system/test_unseen_configuration.py",
    "tests/system/test_miller_on_the_simulator.py",
    "tests/system/test_fusion_node.py",
    "tests/system/test_compensation_node.py",
    "tests/system/test_live_replay.py",
)
# Not copied into the mutants' repositories (large, generated, or the bags, which are linked).
NOT_COPIED = (".git", ".venv", "out", "build", "install", "log", "bags", "__pycache__")
NOT_COPIED += (".pytest_cache", ".ruff_cache")
UNIT_TIMEOUT_S = 900.0
SYSTEM_TIMEOUT_S = 2400.0
SHOWN_PER_CELL = 3


@dataclass(frozen=True)
class Edit:
    """Replace the one occurrence of ``original`` in ``path`` (repository-relative)."""

    path: str
    original: str
    replacement: str


@dataclass(frozen=True)
class Mutant:
    name: str
    what: str
    edits: tuple[Edit, ...]


MILLER = "src/wind_comp/wind_comp/miller.py"
COMPENSATOR = "src/wind_comp/wind_comp/compensator.py"
STRAPDOWN_KERNEL = "src/buoy_nav/buoy_nav/strapdown_kernel.py"

MUTANTS = (
    Mutant(
        "miller_tilt",
        "Miller tilt term: the reading turned by R_nb transposed (ENU→body) instead of R_nb",
        (
            Edit(
                MILLER,
                "    tilt_term = rotate_components(attitude_elements_nb, flow_body)\n",
                "    a = attitude_elements_nb\n"
                "    tilt_term = rotate_components(\n"
                "        (a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]), flow_body\n"
                "    )\n",
            ),
        ),
    ),
    Mutant(
        "miller_rotation",
        "Miller rotation term R_nb (ω × B) left out",
        (
            Edit(
                MILLER,
                "rotation_term = rotate_components(attitude_elements_nb, lever_arm_velocity_body)",
                "rotation_term = tuple(0.0 * c for c in lever_arm_velocity_body)",
            ),
        ),
    ),
    Mutant(
        "miller_translation",
        "Miller translation term: the platform velocity subtracted instead of added",
        (
            Edit(
                MILLER,
                "    translation_term = (east, north, up)\n",
                "    translation_term = (-east, -north, -up)\n",
            ),
        ),
    ),
    Mutant(
        "anemometer_lever_arm",
        "anemometer lever arm B negated where the compensation takes it from its parameters",
        (
            Edit(
                COMPENSATOR,
                "_lever_arm_elements_body_m = tuple(float(c) for c in sensor.position_body_m)",
                "_lever_arm_elements_body_m = tuple(-float(c) for c in sensor.position_body_m)",
            ),
        ),
    ),
    Mutant(
        "mounting_rotation",
        "anemometer mounting rotation inverted (body→anemometer instead of anemometer→body)",
        (
            Edit(
                MILLER,
                "[yaw_deg, pitch_deg, roll_deg], degrees=True)\n",
                "[yaw_deg, pitch_deg, roll_deg], degrees=True).inv()\n",
            ),
        ),
    ),
    Mutant(
        "gravity",
        "gravity added to the vertical velocity instead of subtracted (mechanization)",
        (
            Edit(
                STRAPDOWN_KERNEL,
                "new_vu = vu + fnu - (ce * vn - cn * ve + gravity) * dt_s",
                "new_vu = vu + fnu - (ce * vn - cn * ve - gravity) * dt_s",
            ),
        ),
    ),
    Mutant(
        "earth_rate",
        "north component of the Earth rate negated (Earth model and the integrator's copy)",
        (
            Edit(
                "src/buoy_nav/buoy_nav/earth.py",
                "        EARTH_RATE_RAD_S * np.cos(latitude_rad),\n",
                "        -EARTH_RATE_RAD_S * np.cos(latitude_rad),\n",
            ),
            Edit(
                STRAPDOWN_KERNEL,
                "    state[NAV_FRAME_RATE + 1] = _OMEGA * math.cos(lat) + ve / east_radius\n",
                "    state[NAV_FRAME_RATE + 1] = -_OMEGA * math.cos(lat) + ve / east_radius\n",
            ),
            Edit(STRAPDOWN_KERNEL, "wie_n = _OMEGA * cos_lat", "wie_n = -_OMEGA * cos_lat"),
        ),
    ),
    Mutant(
        "gnss_velocity_lever_arm",
        "GNSS velocity: the antenna's lever arm negated in the measurement model",
        (
            Edit(
                "src/buoy_nav/buoy_nav/aiding/gnss_velocity.py",
                "            np.asarray(point.nav_frame_rate_enu_rad_s, dtype=float),\n"
                "            self._lever_arm_body_m,\n",
                "            np.asarray(point.nav_frame_rate_enu_rad_s, dtype=float),\n"
                "            -self._lever_arm_body_m,\n",
            ),
        ),
    ),
    Mutant(
        "heading_tilt",
        "dual-antenna heading predicted as if level: yaw plus the baseline's body azimuth",
        (
            Edit(
                "src/buoy_nav/buoy_nav/aiding/gnss_heading.py",
                "            return None\n        return MeasurementModel(\n",
                "            return None\n"
                "        rotation, baseline = point.rotation_nb, self._baseline_body_m\n"
                "        predicted = math.atan2(rotation[1][0], rotation[0][0]) + math.atan2(\n"
                "            baseline[1], baseline[0]\n"
                "        )\n"
                "        return MeasurementModel(\n",
            ),
        ),
    ),
    Mutant(
        "quaternion_order_written",
        "nav/* attitude quaternions written in (w, x, y, z) order instead of (x, y, z, w)",
        (
            Edit(
                "src/buoy_nav/buoy_nav/fusion_messages.py",
                "        attitude_xyzw=(x, y, z, w),\n",
                "        attitude_xyzw=(w, x, y, z),\n",
            ),
        ),
    ),
    Mutant(
        "quaternion_order_read",
        "the compensation reads nav/odometry's quaternion as (w, x, y, z)",
        (
            Edit(
                "src/wind_comp/wind_comp/compensation_messages.py",
                "        pose[3:7],\n",
                "        (pose[6], *pose[3:6]),\n",
            ),
            Edit(
                "src/wind_comp/wind_comp/compensation_messages.py",
                "(float(orientation.x), float(orientation.y), float(orientation.z), "
                "float(orientation.w)),",
                "(float(orientation.w), float(orientation.x), float(orientation.y), "
                "float(orientation.z)),",
            ),
        ),
    ),
)


class MutantDoesNotApplyError(Exception):
    """An edit's original text is not in its file exactly once: the code moved or changed."""


def copy_repository(target: Path) -> None:
    shutil.copytree(REPO, target, symlinks=True, ignore=shutil.ignore_patterns(*NOT_COPIED))
    (target / "bags").symlink_to(REPO / "bags")


def apply(mutant: Mutant, root: Path) -> None:
    for edit in mutant.edits:
        path = root / edit.path
        text = path.read_text() if path.is_file() else ""
        count = text.count(edit.original)
        if count != 1:
            raise MutantDoesNotApplyError(
                f"{mutant.name}: {edit.path} holds {count} copies of {edit.original.strip()!r}"
            )
        path.write_text(text.replace(edit.original, edit.replacement))


def environment(root: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [*(str(root / "src" / package) for package in PACKAGES), env.get("PYTHONPATH", "")]
    ).rstrip(os.pathsep)
    return env


def check_imports_from(root: Path) -> None:
    """The copy's packages, not the working tree's, are what Python imports there."""
    probe = subprocess.run(
        [
            sys.executable,
            "-c",
            "import buoy_nav, wind_comp; print(buoy_nav.__file__, wind_comp.__file__)",
        ],
        capture_output=True,
        text=True,
        env=environment(root),
        cwd=root,
        check=True,
    )
    for path in probe.stdout.split():
        if not Path(path).resolve().is_relative_to(root.resolve()):
            raise RuntimeError(f"the copy at {root} imports {path}")


@dataclass
class Outcome:
    """Test node ids that failed (or errored) and whether the run ended in time."""

    failed: set[str]
    passed: set[str]
    timed_out: bool = False


def run_tests(root: Path, paths, junit: Path, timeout_s: float, extra=()) -> Outcome:
    command = [
        sys.executable,
        "-m",
        "pytest",
        "-q",
        "-p",
        "no:cacheprovider",
        f"--junit-xml={junit}",
        f"--basetemp={root / '.pytest_tmp'}",
        *extra,
        *paths,
    ]
    try:
        subprocess.run(
            command,
            cwd=root,
            env=environment(root),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            timeout=timeout_s,
            start_new_session=True,
        )
    except subprocess.TimeoutExpired:
        return Outcome(set(), set(), timed_out=True)
    if not junit.is_file():
        return Outcome({"(pytest did not run)"}, set())
    failed, passed = set(), set()
    for case in ElementTree.parse(junit).iter("testcase"):
        module = case.get("classname", "").replace(".", "/")
        name = f"{module}.py::{case.get('name')}"
        if case.find("failure") is not None or case.find("error") is not None:
            failed.add(name)
        elif case.find("skipped") is None:
            passed.add(name)
    return Outcome(failed, passed)


def short(test_id: str) -> str:
    return test_id.rsplit("/", 1)[-1]


def ros_tests(root: Path, system_tests) -> set[str]:
    """Node ids of the tests that start nodes over DDS (marker ``ros``)."""
    collect = ("-q", "--collect-only", "-p", "no:cacheprovider", "-m", "ros")
    listed = subprocess.run(
        [sys.executable, "-m", "pytest", *collect, *system_tests],
        cwd=root,
        env=environment(root),
        capture_output=True,
        text=True,
    )
    return {line.strip() for line in listed.stdout.splitlines() if "::" in line}


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="mutation_check", description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="+", metavar="NAME", help="run only these mutants")
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel unit runs")
    parser.add_argument("--out", default=str(REPO / "out" / "mutants"), help="results directory")
    parser.add_argument(
        "--system-tests",
        nargs="+",
        default=list(SYSTEM_TESTS),
        metavar="PATH",
        help="system test modules to run (default: those that judge results against the truth)",
    )
    parser.add_argument(
        "--workers", type=int, default=1, help="pytest-xdist workers of each system run (1)"
    )
    parser.add_argument(
        "--first-catch",
        action="store_true",
        help="stop each mutant's system run at its first catching test",
    )
    return parser.parse_args(argv)


def catching(outcome: Outcome, baseline: Outcome) -> list[str]:
    return sorted(outcome.failed & baseline.passed)


def main(argv=None) -> int:
    arguments = parse_arguments(sys.argv[1:] if argv is None else argv)
    mutants = [m for m in MUTANTS if not arguments.only or m.name in arguments.only]
    if arguments.only and len(mutants) != len(arguments.only):
        known = ", ".join(m.name for m in MUTANTS)
        print(
            f"mutation_check: unknown mutant in {arguments.only}; known: {known}", file=sys.stderr
        )
        return 2
    if arguments.list:
        print_mutants(mutants)
        return 0
    out = Path(arguments.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="mutation_check-") as scratch:
        scratch = Path(scratch)
        roots, problems = prepare_copies(scratch, mutants)
        runnable = [m for m in mutants if m.name in roots]
        unit = run_unit_tests(roots, runnable, scratch, arguments.jobs)
        system = run_system_tests(roots, runnable, scratch, arguments, started)
    results, rows = tally(runnable, unit, system, arguments, problems)
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    print_report(rows, results, time.monotonic() - started, out / "results.json")
    return 0 if all(row[-1] for row in rows) and not problems else 1


def print_mutants(mutants) -> None:
    for mutant in mutants:
        print(f"{mutant.name}: {mutant.what}")
        for edit in mutant.edits:
            print(f"    {edit.path}: {edit.original.strip()!r} -> {edit.replacement.strip()!r}")


def prepare_copies(scratch: Path, mutants) -> tuple[dict[str, Path], list[str]]:
    """A copy of the repository for the baseline and for each mutant, the mutant applied;
    returns the copies by name (those of mutants that no longer apply left out) and why
    each of those did not apply."""
    roots = {}
    problems = []
    for name in ["baseline", *(m.name for m in mutants)]:
        roots[name] = scratch / name
        copy_repository(roots[name])
    for mutant in mutants:
        try:
            apply(mutant, roots[mutant.name])
        except MutantDoesNotApplyError as error:
            problems.append(str(error))
            del roots[mutant.name]
    for root in roots.values():
        check_imports_from(root)
    return roots, problems


def run_unit_tests(roots: dict[str, Path], runnable, scratch: Path, jobs: int) -> dict:
    """Outcome of the unit tests of the baseline and of each mutant, ``jobs`` at a time."""

    def unit_run(name):
        return name, run_tests(
            roots[name], UNIT_TESTS, scratch / f"{name}-unit.xml", UNIT_TIMEOUT_S
        )

    print(f"mutation_check: unit tests of the baseline and {len(runnable)} mutants", flush=True)
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        return dict(pool.map(unit_run, ["baseline", *(m.name for m in runnable)]))


def run_system_tests(
    roots: dict[str, Path], runnable, scratch: Path, arguments, started_s: float
) -> dict:
    """Outcome of the system tests of the baseline and of each mutant, one copy at a time;
    ``started_s`` (monotonic clock, s) dates the progress lines."""
    system = {}
    system_tests = arguments.system_tests
    live = ros_tests(roots["baseline"], system_tests)
    parallel = ("-n", str(arguments.workers), "--dist", "loadgroup")
    system_options = parallel if arguments.workers > 1 else ()
    for name in ["baseline", *(m.name for m in runnable)]:
        print(
            f"mutation_check: system tests of {name} ({time.monotonic() - started_s:.0f} s)",
            flush=True,
        )
        options = system_options
        if name != "baseline" and arguments.first_catch:
            deselected = (f"--deselect={test}" for test in sorted(system["baseline"].failed))
            options = (*system_options, "-x", *deselected)
        outcome = run_tests(
            roots[name], system_tests, scratch / f"{name}-system.xml", SYSTEM_TIMEOUT_S, options
        )
        flaky_candidates = sorted(outcome.failed & live)
        if name != "baseline" and flaky_candidates:
            # A live test that fails on a busy machine is believed only when it fails twice.
            again = run_tests(
                roots[name], flaky_candidates, scratch / f"{name}-rerun.xml", SYSTEM_TIMEOUT_S
            )
            outcome.failed -= again.passed
        system[name] = outcome
    return system


def tally(runnable, unit: dict, system: dict, arguments, problems: list[str]):
    """The results (for results.json) and one report row per mutant: the tests that catch it
    and whether it is caught by both a unit and a system test."""
    results = {
        "system_tests": arguments.system_tests,
        "first_catch_only": arguments.first_catch,
        "baseline_failures": {
            "unit": sorted(unit["baseline"].failed),
            "system": sorted(system["baseline"].failed),
        },
        "mutants": {},
        "not_applied": problems,
    }
    rows = []
    for mutant in runnable:
        unit_catch = catching(unit[mutant.name], unit["baseline"])
        system_catch = catching(system[mutant.name], system["baseline"])
        timeouts = [
            k
            for k, o in (("unit", unit[mutant.name]), ("system", system[mutant.name]))
            if o.timed_out
        ]
        caught = bool(unit_catch) and bool(system_catch)
        results["mutants"][mutant.name] = {
            "what": mutant.what,
            "unit": unit_catch,
            "system": system_catch,
            "timed_out": timeouts,
            "caught": caught,
        }
        rows.append((mutant, unit_catch, system_catch, timeouts, caught))
    return results, rows


def print_report(rows, results, elapsed_s: float, results_path: Path) -> None:
    def cell(tests):
        shown = ", ".join(short(t) for t in tests[:SHOWN_PER_CELL])
        more = f", +{len(tests) - SHOWN_PER_CELL} more" if len(tests) > SHOWN_PER_CELL else ""
        return f"{len(tests)}: {shown}{more}" if tests else "NONE"

    print()
    print(f"Mutation check: {len(rows)} mutants in {elapsed_s / 60:.0f} min")
    if results["first_catch_only"]:
        print("  each mutant's system run stopped at its first catching test")
    for label, failures in results["baseline_failures"].items():
        if failures:
            print(
                f"  the unmutated copy fails {len(failures)} {label} tests (not counted): "
                + ", ".join(short(t) for t in failures)
            )
    for problem in results["not_applied"]:
        print(f"  NOT APPLIED (re-target the edit): {problem}")
    print()
    for mutant, unit_catch, system_catch, timeouts, caught in rows:
        status = "caught" if caught else "NOT CAUGHT"
        extra = f" (timed out: {', '.join(timeouts)})" if timeouts else ""
        print(f"{mutant.name}: {status}{extra} — {mutant.what}")
        print(f"    unit tests   {cell(unit_catch)}")
        print(f"    system tests {cell(system_catch)}")
    print(f"\nEvery catching test of every mutant: {results_path}")


if __name__ == "__main__":
    sys.exit(main())
