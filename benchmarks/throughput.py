"""Benchmark: pick-points per second and physics steps per second against batch size.

For each object, backend and batch size: compile time (MJX: lower + compile, once per
shape; MuJoCo C: the controller kernel's jit and the Batch) apart from run time (median
of repeats over distinct pick-point sets, after a warm-up), pick-points per second,
physics steps per second, peak device memory per pick-point (MJX on GPU), success rate.
One CSV row per configuration.

  python benchmarks/throughput.py --objects door_opener,block --backends mjx \\
      --batch-sizes 1024,4096,16384,65536 --out benchmarks/out
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import subprocess
import time
from pathlib import Path

import jax
import numpy as np

import mjx_pick as mp
from mjx_pick import pickpoints as pp
from mjx_pick.grasp import GraspConfig
from mjx_pick.simulate import make_backend, make_inputs


def device_name(n: int | None = None) -> str:
    d = jax.devices()[0]
    n = n or len(jax.devices())
    return f"{n}x {d.device_kind}" if d.platform != "cpu" else "cpu"


def peak_bytes() -> int | None:
    stats = jax.devices()[0].memory_stats() if jax.devices()[0].platform != "cpu" else None
    return None if not stats else int(stats.get("peak_bytes_in_use", 0))


def tile_picks(picks: pp.PickBatch, n: int, offset: int) -> pp.PickBatch:
    idx = (np.arange(n) + offset) % len(picks)
    return picks.take(idx)


def bench(obj_name, gripper, backend_name, batch, repeats, grasp, solver, n_devices=None):
    obj = mp.load_object(obj_name)
    scene = mp.build_scene(obj, gripper, solver=solver)
    pool = pp.generate_normal(obj, gripper, min(max(batch, 256), 20000), seed=0)
    devices = jax.local_devices()[:n_devices] if n_devices else None
    backend = make_backend(backend_name, scene, grasp, batch_size=batch, devices=devices)
    steps = grasp.n_ticks() * grasp.substeps(scene.solver)
    first = make_inputs(scene, grasp, tile_picks(pool, batch, 0))
    t0 = time.perf_counter()
    out, _ = backend.run(first)  # compiles, then runs once (warm-up)
    first_wall = time.perf_counter() - t0
    compile_s = backend.stats.compile_s
    times = []
    for r in range(repeats):
        inputs = make_inputs(scene, grasp, tile_picks(pool, batch, (r + 1) * 7919))
        before = backend.stats.run_s
        out, _ = backend.run(inputs)
        times.append(backend.stats.run_s - before)
    run_s = statistics.median(times)
    peak = peak_bytes()
    return {
        "object": obj_name,
        "backend": backend.name,
        "device": device_name(n_devices) if backend.name == "mjx" else backend.device,
        "batch": batch,
        "compile_s": round(compile_s, 2),
        "first_call_s": round(first_wall, 2),
        "run_s_median": round(run_s, 3),
        "picks_per_s": round(batch / run_s, 1),
        "physics_steps_per_s": round(batch * steps / run_s),
        "steps_per_pick": steps,
        "peak_mem_mb_per_pick": round(peak / batch / 2**20, 3) if peak else None,
        "success_rate": round(float(np.mean(out["success"])), 4),
        "diverged": int(np.sum(out["diverged"])),
        "timestep_s": scene.solver.timestep_s,
        "cone": scene.solver.cone,
        "iterations": scene.solver.iterations,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--backends", default="mjx")
    ap.add_argument("--batch-sizes", default="1024,4096,16384")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--grasp", help="GraspConfig TOML (default: GraspConfig())")
    ap.add_argument("--solver", help="SolverParams TOML (default: SolverParams())")
    ap.add_argument("--out", default="benchmarks/out")
    ap.add_argument("--tag", default="", help="free text recorded with each row")
    ap.add_argument(
        "--devices", default="", help="comma-separated device counts to shard over (default: all)"
    )
    args = ap.parse_args()
    from mjx_pick.config import load_toml

    grasp = load_toml(GraspConfig, args.grasp) if args.grasp else GraspConfig()
    solver = load_toml(mp.SolverParams, args.solver) if args.solver else mp.SolverParams()
    gripper = mp.load_gripper(args.gripper)
    # a device machine gets the tree without .git: pass the commit in MJX_PICK_COMMIT
    commit = (
        os.environ.get("MJX_PICK_COMMIT")
        or subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "throughput.csv"
    for obj_name in args.objects.split(","):
        for backend_name in args.backends.split(","):
            for batch in (int(b) for b in args.batch_sizes.split(",")):
                for nd in [int(x) for x in args.devices.split(",")] if args.devices else [None]:
                    row = bench(
                        obj_name,
                        gripper,
                        backend_name,
                        batch * (nd or 1),
                        args.repeats,
                        grasp,
                        solver,
                        nd,
                    )
                    row["n_devices"] = nd or len(jax.local_devices())
                    row.update(
                        {"date": time.strftime("%Y-%m-%d"), "commit": commit, "tag": args.tag}
                    )
                    new = not path.exists()
                    with path.open("a", newline="") as fh:
                        w = csv.DictWriter(fh, fieldnames=list(row))
                        if new:
                            w.writeheader()
                        w.writerow(row)
                    print(" ".join(f"{k}={v}" for k, v in row.items()), flush=True)


if __name__ == "__main__":
    main()
