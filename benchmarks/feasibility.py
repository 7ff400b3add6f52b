"""Benchmark: geometric feasibility checks of pick-point candidates.

Measures, for one object and gripper: the one-time silhouette stack (rasterising every
yaw bin), the first call and the steady-state time of checking N
candidates (median of repeats), on the host (numpy), and the whole Normal-mode search
for --picks feasible pick-points (drawing included), for each thread count of
--threads (0: every core; 1: one block after the other, as before the checks ran on
threads). Writes one CSV row per thread count (feasibility.csv).

--device (Warp devices, e.g. cuda:0): the same on the Warp kernel
(kernels/feasibility_warp.py), one row per device (feasibility_warp.csv): the module's
build in a fresh kernel cache (a first use on a machine) and its load from that cache
(what a later process pays) apart from the first call (the stack copied to the device)
and the steady time (copy in, launch, copy out; the launch alone beside it), the
results checked bit for bit against numpy's (the timed candidates and poses at the
checks' edges), and the search on the device against the search on the host.

  python benchmarks/feasibility.py --object door_opener --n 1000000 --picks 100000 \
      --threads 1,0 --out benchmarks/out
  python benchmarks/feasibility.py --object door_opener --n 1000000 --picks 262144 \
      --threads 0 --device cuda:0 --repeats 7 --out benchmarks/out
"""

from __future__ import annotations

import argparse
import atexit
import csv
import os
import platform
import shutil
import statistics
import subprocess
import tempfile
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
    ap.add_argument("--threads", default="0", help="comma-separated; 0: every core; '': none")
    ap.add_argument("--device", default="", help="comma-separated Warp devices (cuda:0, cpu)")
    ap.add_argument("--out", default="benchmarks/out")
    args = ap.parse_args()
    devices = [d for d in args.device.split(",") if d]
    if devices:  # before Warp starts: a fresh kernel cache, so that the build is one
        import warp as wp

        wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="feasibility_warp_cache_")
        atexit.register(shutil.rmtree, wp.config.kernel_cache_dir, ignore_errors=True)
        wp.config.log_level = wp.LOG_WARNING  # the build is timed here, not logged

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
    for threads in (int(t) for t in args.threads.split(",") if t):
        fk.MAX_THREADS = threads or default_threads
        fk._pool.cache_clear()  # a pool of the new size
        row = measure(args, obj, gripper, checker, sets)
        row["stack_s"] = round(stack_s, 3)
        write(row, Path(args.out) / "feasibility.csv")
    fk.MAX_THREADS = default_threads
    fk._pool.cache_clear()
    for device in devices:
        row = measure_device(args, obj, gripper, checker, sets, device)
        write(row, Path(args.out) / "feasibility_warp.csv")
        if not (row["bitwise_equal"] and row["edge_bitwise_equal"] and row.get("same_picks", True)):
            raise SystemExit(f"{device}: the kernel's results differ from numpy's (row above)")


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
        "commit": commit(),
    }


def measure_device(args, obj, gripper, checker, sets, device: str) -> dict:
    """One row for the Warp kernel on device; numpy's threads give the reference."""
    import warp as wp

    from mjx_pick.kernels import feasibility_warp as fw

    dev = wp.get_device(device)
    wp.synchronize_device(dev)  # the device's context made: not counted as the build
    module = fw.check_kernel.module
    t0 = time.perf_counter()
    fw.prepare(device)  # compiled: the cache is fresh
    build_s = time.perf_counter() - t0
    module.unload()
    t0 = time.perf_counter()
    fw.prepare(device)  # loaded from the cache, as by a later process
    load_s = time.perf_counter() - t0

    stack, band = checker.stack, checker.band

    def check(x, y, yaw_deg):
        return fw.check_candidates(stack, band, x, y, np.deg2rad(yaw_deg), device=device)

    t0 = time.perf_counter()
    got = check(*sets[0])
    first_s = time.perf_counter() - t0
    times, kernel_times = [], []
    for r in range(args.repeats):
        t0 = time.perf_counter()
        check(*sets[r % 3])  # NumPy arrays back on the host: the work is complete
        times.append(time.perf_counter() - t0)
    resident = fk.candidates(sets[0][0], sets[0][1], np.deg2rad(sets[0][2]))
    resident = [wp.array(np.ascontiguousarray(a), dtype=wp.float32, device=dev) for a in resident]
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        fw.launch(stack, band, *resident)
        wp.synchronize_device(dev)
        kernel_times.append(time.perf_counter() - t0)
    run_s = statistics.median(times)

    ref = fk.check_candidates(stack, band, sets[0][0], sets[0][1], np.deg2rad(sets[0][2]))
    edge = edge_poses(band, stack.res_mm, len(stack.crops))
    edge_ref = fk.check_candidates(stack, band, *edge)
    edge_got = fw.check_candidates(stack, band, *edge, device=device)
    search = {}
    if args.picks:
        t0 = time.perf_counter()
        picks = pp.generate_normal(obj, gripper, args.picks, seed=0, device=device)
        search_s = time.perf_counter() - t0
        host = pp.generate_normal(obj, gripper, args.picks, seed=0)
        same = picks.n_candidates == host.n_candidates and picks.rejected == host.rejected
        for k in ("pick_id", "opening_mm", "coverage", "gap_left_mm", "gap_right_mm"):
            same = same and np.array_equal(getattr(picks, k), getattr(host, k))
        search = {
            "picks": args.picks,
            "search_s": round(search_s, 3),
            "search_candidates": picks.n_candidates,
            "same_picks": same,
        }
    return {
        "date": time.strftime("%Y-%m-%d"),
        "device": dev.name,
        "warp_device": device,
        "object": args.object,
        "gripper": args.gripper,
        "n": args.n,
        "yaw_bins": len(stack.crops),
        "build_s": round(build_s, 3),
        "load_s": round(load_s, 3),
        "first_call_s": round(first_s, 4),
        "check_s_median": round(run_s, 4),
        "kernel_s_median": round(statistics.median(kernel_times), 5),
        "candidates_per_s": round(args.n / run_s),
        "bitwise_equal": differing(ref, got) == 0,
        "edge_bitwise_equal": differing(edge_ref, edge_got) == 0,
        **search,
        "commit": commit(),
    }


def edge_poses(band, res_mm: float, n_bins: int):
    """Poses at the checks' edges (x, y mm, yaw rad, fixed openings mm): NaN, infinite
    and far-off poses, yaw on the bins' edges, openings whose fingers meet a column's
    centre or edge, or an ulp either side of the stroke."""
    rng = np.random.default_rng(1)
    odd = np.array([np.nan, np.inf, -np.inf, 1e12, -3e9, 0.0, 10.0, -10.0])
    x, y, yaw = (a.ravel() for a in np.meshgrid(odd, odd, odd, indexing="ij"))
    centres = np.abs(fk._columns(band, res_mm))
    stroke = np.float32(band.stroke_mm)
    openings = np.concatenate(
        [
            2 * centres,
            2 * centres + res_mm,
            2 * (centres - band.finger_depth_mm),
            [np.nextafter(stroke, np.float32(0)), stroke, np.nextafter(stroke, np.inf), 0, -5],
        ]
    )
    n = 20_000
    yaw_edges = np.arange(-2 * n_bins, 4 * n_bins) * 0.5 * np.pi / n_bins
    near = (
        rng.uniform(-30, 30, n),
        rng.uniform(-30, 30, n),
        rng.choice(yaw_edges, n),
        np.where(rng.random(n) < 0.5, rng.choice(openings, n), np.nan),
    )
    return tuple(
        np.concatenate([a, b])
        for a, b in zip((x, y, yaw, np.full(len(x), np.nan)), near, strict=True)
    )


def differing(a: tuple, b: tuple) -> int:
    """Elements of two check_candidates results whose 32 bits differ (NaN's included)."""
    return sum(
        int(np.count_nonzero(u.view(np.int32) != v.view(np.int32)))
        for u, v in zip(a, b, strict=True)
    )


def commit() -> str:
    return subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()


def write(row: dict, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
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
