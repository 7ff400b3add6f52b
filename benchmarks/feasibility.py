"""Benchmark: geometric feasibility checks of pick-point candidates.

Measures, for one object and gripper: the one-time silhouette stack (rasterising every
yaw bin), the first call and the steady-state time of checking N
candidates (median of repeats), on the host (numpy). Writes one CSV row per run.

  python benchmarks/feasibility.py --object door_opener --n 100000 --out benchmarks/out
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--out", default="benchmarks/out")
    args = ap.parse_args()

    obj = mp.load_object(args.object)
    gripper = mp.load_gripper(args.gripper)
    t0 = time.perf_counter()
    checker = pp.FeasibilityChecker(obj, gripper)
    stack_s = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    half = 0.5 * obj.length_mm
    sets = [
        (
            rng.uniform(-half, half, args.n),
            rng.uniform(-half, half, args.n),
            rng.uniform(0, 360, args.n),
        )
        for _ in range(3)
    ]
    t0 = time.perf_counter()
    checker(*sets[0])
    first_s = time.perf_counter() - t0
    times = []
    for r in range(args.repeats):
        t0 = time.perf_counter()
        res = checker(*sets[r % 3])  # returns NumPy arrays: the work is complete
        times.append(time.perf_counter() - t0)
    run_s = statistics.median(times)
    feasible = float(np.mean(res["reason"] == 0))
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    row = {
        "date": time.strftime("%Y-%m-%d"),
        "device": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
        "object": args.object,
        "gripper": args.gripper,
        "n": args.n,
        "yaw_bins": len(checker.stack.crops),
        "stack_s": round(stack_s, 3),
        "first_call_s": round(first_s, 3),
        "check_s_median": round(run_s, 4),
        "candidates_per_s": round(args.n / run_s),
        "feasible_fraction": round(feasible, 4),
        "commit": commit,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "feasibility.csv"
    new = not path.exists()
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)
    for k, v in row.items():
        print(f"{k:>20}: {v}")


if __name__ == "__main__":
    main()
