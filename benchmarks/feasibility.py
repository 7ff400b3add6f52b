"""Benchmark: geometric feasibility checks of pick-point candidates.

Measures, for one object and gripper: the one-time silhouette stack (rasterising every
yaw bin), the first call and the steady-state time of checking N
candidates (median of repeats), on the host (numpy), and the whole Normal-mode search
for --picks feasible pick-points (drawing included), for each thread count of
--threads (0: every core; 1: one block after the other, as before the checks ran on
threads). Writes one CSV row per thread count.

  python benchmarks/feasibility.py --object door_opener --n 1000000 --picks 100000 \
      --threads 1,0 --out benchmarks/out
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
from mjx_pick.kernels import feasibility as fk


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--picks", type=int, default=0, help="also time generate_normal(n=picks)")
    ap.add_argument("--threads", default="0", help="comma-separated; 0: every core")
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
    default_threads = fk.MAX_THREADS
    for threads in (int(t) for t in args.threads.split(",")):
        fk.MAX_THREADS = threads or default_threads
        fk._pool.cache_clear()  # a pool of the new size
        row = measure(args, obj, gripper, checker, sets)
        row["stack_s"] = round(stack_s, 3)
        write(row, Path(args.out))


def measure(args, obj, gripper, checker, sets) -> dict:
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
    search = {}
    if args.picks:
        t0 = time.perf_counter()
        picks = pp.generate_normal(obj, gripper, args.picks, seed=0)
        search = {
            "picks": args.picks,
            "search_s": round(time.perf_counter() - t0, 3),
            "search_candidates": picks.n_candidates,
        }
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    return {
        "date": time.strftime("%Y-%m-%d"),
        "device": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
        "object": args.object,
        "gripper": args.gripper,
        "n": args.n,
        "threads": fk.threads(),
        "yaw_bins": len(checker.stack.crops),
        "first_call_s": round(first_s, 3),
        "check_s_median": round(run_s, 4),
        "candidates_per_s": round(args.n / run_s),
        "feasible_fraction": round(feasible, 4),
        **search,
        "commit": commit,
    }


def write(row: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "feasibility.csv"
    new = not path.exists()
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(row), extrasaction="ignore")
        if new:
            w.writeheader()
        w.writerow(row)
    for k, v in row.items():
        print(f"{k:>20}: {v}")


if __name__ == "__main__":
    main()
