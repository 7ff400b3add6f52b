"""Benchmark: the per-pick cost ``studies.duration`` estimates a run's time from.

For each backend, object and procedure (the default, and a short one: 5 mm lift, 0.05 s
hold), ``evaluate`` of n and of n/8 pick-points on every CPU thread (MuJoCo C) or on
one GPU (Warp): the seconds one unit spends per pick-point -- a CPU thread's CPU
seconds (the two runs' difference: the fixed costs cancel, and a machine others load
does not count), a GPU's wall seconds -- against the pick's expected simulated seconds
(``duration.expected_pick_s``). A line of least squares through those points gives the
backend's ``registry.Rate.per_sim_s`` (its overhead, printed too, should be near 0). One
JSON line per run, then the fit per backend.

  python benchmarks/duration_rates.py --backends mujoco --n 512
  python benchmarks/duration_rates.py --backends warp --n 65536
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

import mjx_pick as mp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine import registry
from mjx_pick.studies.duration import expected_pick_s, units_here

PROCEDURES = {
    "default": GraspConfig(),
    "short": GraspConfig(lift_height_mm=5.0, hold_s=0.05),
}


def _run(obj, backend: str, grasp: GraspConfig, n: int) -> tuple[dict, float]:
    """One evaluate of n pick-points: (its summary, the CPU seconds it took, every thread
    of this process counted)."""
    cpu0 = time.process_time()
    ev = mp.evaluate(obj, n=n, backend=backend, grasp=grasp, n_traces=0)
    return ev, time.process_time() - cpu0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backends", default="mujoco")
    ap.add_argument("--objects", default="block,door_opener")
    ap.add_argument("--n", type=int, default=512)
    args = ap.parse_args()
    for backend in args.backends.split(","):
        entry = registry.ENTRIES[backend]
        units, what = units_here(entry)
        on_cpu = entry.device is registry.Device.CPU
        points = []
        for obj_name in args.objects.split(","):
            obj = mp.load_asset(obj_name)
            for proc_name, grasp in PROCEDURES.items():
                small = max(args.n // 8, 1)
                _run(obj, backend, grasp, small)  # compiled programs and caches warm
                ev_small, cpu_small = _run(obj, backend, grasp, small)
                ev, cpu = _run(obj, backend, grasp, args.n)
                simulate_s = ev.summary["time_s"]["simulate"]
                reached = np.asarray(ev.table["t_reached_s"], float)
                # on the CPU, CPU seconds per pick-point (the difference of two runs: the
                # fixed costs cancel), what one thread spends on it whatever else the
                # machine runs; on a GPU, its wall seconds
                unit_s = (
                    (cpu - cpu_small) / (args.n - small) if on_cpu else simulate_s * units / args.n
                )
                row = {
                    "backend": backend,
                    "object": obj_name,
                    "procedure": proc_name,
                    "n": args.n,
                    "units": units,
                    "unit": what,
                    "device": ev.summary["device"],
                    "load_1min": os.getloadavg()[0],
                    "simulate_s": round(simulate_s, 3),
                    "picks_per_s": round(args.n / simulate_s, 2),
                    "cpu_s": round(cpu, 3),
                    "expected_pick_s": round(expected_pick_s(grasp), 4),
                    "mean_t_reached_s": round(float(reached[reached >= 0].mean()), 4),
                    "unit_s_per_pick": round(unit_s, 5),
                }
                points.append((row["expected_pick_s"], unit_s))
                print(json.dumps(row), flush=True)
        x, y = np.array(points).T
        per_sim_s, overhead_s = np.polyfit(x, y, 1)
        print(
            json.dumps(
                {
                    "backend": backend,
                    "fit": "unit_s_per_pick = overhead_s + per_sim_s x expected_pick_s",
                    "overhead_s": round(float(overhead_s), 5),
                    "per_sim_s": round(float(per_sim_s), 5),
                    "units": units,
                    "unit": what,
                }
            ),
            flush=True,
        )


if __name__ == "__main__":
    main()
