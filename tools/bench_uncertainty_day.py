"""A whole day through process_bag: GNSS outages, an uncalibrated magnetometer the fusion
suspends, memory flat, the stated uncertainty honest hour after hour.

    python -m tools.bench_uncertainty_day [--hours H] [--outage-every-s S] [--outage-s S]

Simulates ``set_e_imperfect`` moored (no current) with a lagging motion pack beside its one
antenna at 1 Hz off the IMU grid and its uncalibrated magnetometer, for ``hours`` with a silent
GNSS outage of ``outage_s`` every ``outage_every_s``; runs the ``process_bag`` command on it
while sampling the process's resident memory (``/proc``), and judges the valid corrected wind
against the truth hour by hour (the share beyond 3σ, the count beyond 5σ). Prints the hourly
table and the memory after the first hour and at the end; writes
out/bench/uncertainty_day.json (and, as the run goes, the memory samples to
out/bench/uncertainty_day/memory.tsv). Simulating a day takes a few minutes; processing it takes
the rest, about 55 minutes of one core (docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from sensor_sim.scenario import load_scenario
from tools.bench_plan import PROCESSING_PARAMS, REPO
from tools.bench_uncertainty import MOORED, Case, wind_errors, write_parameters

OUT = REPO / "out" / "bench"
WORK = OUT / "uncertainty_day"
SCENARIO = "set_e_imperfect"
SCENARIO_OVERRIDES = (
    "current=null",
    "sensors.ahrs.fitted=true",
    "sensors.ahrs.sample_every=1",
    "sensors.ahrs.lag_time_constant_s=0.3",
    "sensors.ahrs.claimed_sigma_deg=[0.1, 0.1, 0.5]",
    "sensors.ahrs.yaw_reference=magnetic_north",
)
"""A moored buoy whose motion pack gives the heading while its magnetometer, uncalibrated, is
suspended."""
TRUTH_OVERRIDES = ("sensors.rates.truth_hz=10",)
"""The truth on the sonic's 10 Hz sample times, the only truth the judgement reads (at 50 Hz,
the scenario's rate, it would be two fifths of the simulated messages, passed through
``process_bag`` unread)."""
MEMORY_SAMPLE_S = 5.0
NANOSECONDS_PER_HOUR = 3_600_000_000_000


def outages(duration_s: float, every_s: float, length_s: float) -> list[list[float]]:
    """[start, end) of an outage of ``length_s`` every ``every_s``, the first after ``every_s``."""
    starts = [every_s * k for k in range(1, int(duration_s // every_s) + 1)]
    return [[start, start + length_s] for start in starts if start + length_s < duration_s]


def simulate_day(in_bag: Path, duration_s: float, outage_list) -> None:
    overrides = [
        *SCENARIO_OVERRIDES,
        *TRUTH_OVERRIDES,
        f"duration_s={duration_s}",
        f"sensors.gnss.silent_outages_s={outage_list}",
    ]
    command = [str(Path(sys.executable).parent / "simulate_bag"), SCENARIO, str(in_bag)]
    command.append("--overwrite")
    for override in overrides:
        command += ["--set", override]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)


def resident_mib(pid: int) -> float | None:
    """The resident memory of process ``pid`` (MiB), None once it has ended."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except (FileNotFoundError, ProcessLookupError):
        return None
    return None


def process_with_memory(in_bag: Path, out_bag: Path, params: list[str]) -> list[tuple]:
    """Run ``process_bag`` on the bag; (wall s, resident MiB) every MEMORY_SAMPLE_S, also
    written to memory.tsv as they come (what a run stopped early has)."""
    command = [str(Path(sys.executable).parent / "process_bag"), str(in_bag), str(out_bag)]
    for path in params:
        command += ["--params-file", path]
    command.append("--overwrite")
    log = (WORK / "process.log").open("w")
    process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
    started, samples = time.monotonic(), []
    with (WORK / "memory.tsv").open("w") as table:
        table.write("wall_s\tresident_mib\n")
        while process.poll() is None:
            rss = resident_mib(process.pid)
            if rss is not None:
                samples.append((time.monotonic() - started, rss))
                table.write(f"{samples[-1][0]:.1f}\t{rss:.1f}\n")
                table.flush()
            time.sleep(MEMORY_SAMPLE_S)
    if process.returncode != 0:
        raise SystemExit(f"process_bag failed ({process.returncode}); see {WORK / 'process.log'}")
    return samples


def hourly(out_bag: Path) -> list[dict]:
    errors = wind_errors(out_bag)
    first, last = int(errors.stamps_ns[0]), int(errors.stamps_ns[-1])
    hours = range(0, (last - first) // NANOSECONDS_PER_HOUR + 1)
    return [
        {"hour": h}
        | errors.summary(first + h * NANOSECONDS_PER_HOUR, first + (h + 1) * NANOSECONDS_PER_HOUR)
        for h in hours
    ]


def memory_figures(samples: list[tuple], hours: float) -> dict:
    """Resident memory after the first hour's share of the run and at its end."""
    if not samples:
        return {}
    total_s = samples[-1][0]
    after_first_hour = [rss for t, rss in samples if t >= total_s / hours] or [samples[-1][1]]
    return {
        "first_hour_mib": after_first_hour[0],
        "end_mib": samples[-1][1],
        "largest_mib": max(rss for _, rss in samples),
        "wall_s": total_s,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=24.0, help="length of the day, h")
    parser.add_argument("--outage-every-s", type=float, default=1800.0)
    parser.add_argument("--outage-s", type=float, default=60.0)
    args = parser.parse_args(argv)
    WORK.mkdir(parents=True, exist_ok=True)
    duration_s = args.hours * 3600.0
    in_bag, out_bag = WORK / "in", WORK / "out"
    started = time.monotonic()
    simulate_day(in_bag, duration_s, outages(duration_s, args.outage_every_s, args.outage_s))
    simulated_s = time.monotonic() - started
    print(f"simulated {args.hours:g} h in {simulated_s:.0f} s", file=sys.stderr, flush=True)
    scenario = load_scenario(SCENARIO, [*SCENARIO_OVERRIDES, f"duration_s={duration_s}"], None)
    case = Case(SCENARIO, "a day", (), (MOORED,))
    params = [*PROCESSING_PARAMS, write_parameters(WORK, scenario, case)]
    memory = memory_figures(process_with_memory(in_bag, out_bag, params), args.hours)
    table = hourly(out_bag)
    log = (WORK / "process.log").read_text()
    suspended = [line.strip() for line in log.splitlines() if " suspended" in line]
    result = {
        "hours": args.hours,
        "simulation_wall_s": simulated_s,
        "memory": memory,
        "hourly": table,
        "suspended": suspended,
    }
    (OUT / "uncertainty_day.json").write_text(json.dumps(result, indent=1, default=float))
    print("| hour | valid | beyond 3σ (E/N/U) | beyond 5σ (E/N/U) | median σ m/s |")
    print("|---|---|---|---|---|")
    for row in table:
        share = row["beyond_3_sigma_share"]
        print(
            f"| {row['hour']} | {row['valid_share']:.0%} | "
            f"{'–' if share is None else '/'.join(f'{v:.3f}' for v in share)} | "
            f"{'–' if share is None else '/'.join(map(str, row['beyond_5_sigma']))} | "
            f"{'–' if share is None else '/'.join(f'{v:.2f}' for v in row['median_sigma_mps'])} |"
        )
    print(
        f"memory: {memory.get('first_hour_mib', float('nan')):.0f} MiB after the first hour, "
        f"{memory.get('end_mib', float('nan')):.0f} MiB at the end; simulated in "
        f"{simulated_s:.0f} s, processed in {memory.get('wall_s', float('nan')):.0f} s"
    )
    print("\n".join(suspended) or "no source suspended")


if __name__ == "__main__":
    main()
