"""Re-record the committed bags in bags/ from the live simulation nodes (`make bags`).

Each bag is one `run_scenario ... --record` run: every sensor node, the truth node, the clock
and the recorder as separate processes over DDS, given the shipped buoy parameters and, for a
bag with a buoy of its own, its parameter file ``bags/NAME.yaml`` after them. bags/README.md
lists the same commands.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from tools.ros_domains import own_domain_unless_chosen

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
RATE_FACTOR = "4"
# Bags recorded at another pace: at 4x real time the IMU node of open_ocean needs about half a
# core, more than a busy machine gives it, and a recorder that falls behind logs late.
RATE_FACTORS = {"off_axis": "1"}

# name -> run_scenario arguments (scenario first)
BAGS = {
    "static": ["static", "--set", "duration_s=120", "--seed", "1"],
    "tilt_table": ["tilt_table", "--seed", "2"],
    "wind_tunnel_10": [
        "wind_tunnel",
        "--set",
        "duration_s=120",
        "--set",
        "wind.speed_mps=10",
        "--seed",
        "3",
    ],
    "vertical_wind_5": ["vertical_wind", "--set", "duration_s=120", "--seed", "4"],
    "sea_state": ["sea_state", "--set", "duration_s=180", "--seed", "5"],
    "open_ocean": ["open_ocean", "--set", "duration_s=180", "--seed", "6"],
    "off_axis": ["open_ocean", "--set", "duration_s=150", "--seed", "7"],
}


def main() -> None:
    selected = sys.argv[1:] or list(BAGS)
    unknown = [name for name in selected if name not in BAGS]
    if unknown:
        sys.exit(f"record_bags: unknown bag(s) {unknown}; known: {list(BAGS)}")
    # The recording's nodes in a domain of their own, unless the caller chose one.
    own_domain_unless_chosen("tools")
    bags = REPO / "bags"
    for name in selected:
        target = bags / name
        if target.exists():
            shutil.rmtree(target)
        parameter_files = [REPO / "src/buoy_common/config/buoy.yaml", bags / f"{name}.yaml"]
        command = [
            str(BIN / "run_scenario"),
            *BAGS[name],
            *(
                a
                for path in parameter_files
                if path.is_file()
                for a in ("--params-file", str(path))
            ),
            "--rate-factor",
            RATE_FACTORS.get(name, RATE_FACTOR),
            "--record",
            str(target),
        ]
        print("+", " ".join(command[1:]).replace(str(REPO) + "/", ""), flush=True)
        subprocess.run(command, check=True)


if __name__ == "__main__":
    main()
