"""Write the pinned result tables that tests/test_pinned.py holds every later tree to.

Four small runs of the user's commands on MuJoCo C (a door-opener evaluate, a sweep, a
gripper comparison and a calibration), each reduced to a CSV of its result table. A
change that is meant to leave behaviour alone (a refactor, a layout move) must leave
these tables as they are; a change that is meant to move them regenerates them in its
own commit, and says why:

    python tests/pinned/make_pinned.py            # rewrite tests/pinned/*.csv
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from ast import literal_eval
from pathlib import Path

import pyarrow.parquet as pq

HERE = Path(__file__).resolve().parent
SHORT = ["--backend", "mujoco", "--no-progress", "--lift-height-mm", "20", "--hold-s", "0.2"]

# name -> (CLI arguments after `mjx-pick`, the table file in --out)
RUNS = {
    "evaluate_door_opener": (
        ["evaluate", "door_opener", "--n", "12", "--seed", "3", "--traces", "0", *SHORT],
        "results.parquet",
    ),
    "sweep_block_friction": (
        [
            "sweep",
            "block",
            "--n",
            "6",
            "--seed",
            "1",
            "--param",
            "contact.pad_friction=0.1,0.8",
            *SHORT,
        ],
        "results.parquet",
    ),
    "compare_door_opener": (
        [
            "compare",
            "door_opener",
            "--grippers",
            "robotiq-2f85,franka-hand",
            "--n",
            "6",
            "--seed",
            "2",
            *SHORT,
        ],
        "results.parquet",
    ),
    "calibrate_block": (
        [
            "calibrate",
            "block_1kg_rg2",
            "block",
            "--mass-g",
            "1000",
            "--gripper",
            "onrobot-rg2",
            "--steps",
            "2",
            "--no-identify",
            "--backend",
            "mujoco",
            "--no-progress",
        ],
        "calibration.json",
    ),
}

# what a calibration's result pins: the fit, not its wall time
FIT_KEYS = ("parameters", "estimator", "initial", "fitted", "optimum", "not_identified", "bounds")


def run_table(name: str, out_root: Path):
    """Run one pinned command into out_root/name; returns its table as a pyarrow Table
    (parquet) or a flat dict (JSON)."""
    args, table = RUNS[name]
    out = out_root / name
    cmd = [sys.executable, "-m", "mjx_pick.cli", *args, "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    path = out / table
    if path.suffix == ".parquet":
        return pq.read_table(path)
    fit = json.loads(path.read_text())
    return {k: fit[k] for k in FIT_KEYS}


def to_rows(value) -> list[dict]:
    """A table as rows of plain values, the pinned CSV's form."""
    if isinstance(value, dict):
        return [
            {"key": k, "value": json.dumps(v, sort_keys=True)} for k, v in sorted(value.items())
        ]
    return value.to_pylist()


def cell(text: str):
    """A pinned CSV cell back as the value it was written from (repr of a Python value)."""
    if text in ("nan", "inf", "-inf"):
        return float(text)
    return literal_eval(text)


def main() -> None:
    import csv

    with tempfile.TemporaryDirectory() as tmp:
        for name in RUNS:
            rows = to_rows(run_table(name, Path(tmp)))
            with open(HERE / f"{name}.csv", "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=list(rows[0]))
                w.writeheader()
                w.writerows({k: repr(v) for k, v in r.items()} for r in rows)
            print(name, len(rows), "rows")


if __name__ == "__main__":
    main()
