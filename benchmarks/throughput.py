"""Benchmark: pick-points per second and physics steps per second against batch size.

For each object, backend and batch size: compile time (MJX: lower + compile, once per
shape; MuJoCo C: the controller kernel's jit and the Batch) apart from run time (median
of repeats over distinct pick-point sets, after a warm-up), pick-points per second,
physics steps per second, peak device memory per pick-point (MJX on GPU), success rate.
One CSV row per configuration.

  python benchmarks/throughput.py --objects door_opener,block --backends mjx \\
      --batch-sizes 1024,4096,16384,65536 --out benchmarks/out

Side by side (--run, repeated): each run takes the first n of ONE shared set of
pick-points; MuJoCo C runs first and the others' labels are compared with its labels
on the pick-points both ran; rows go to side_by_side.jsonl (see
mjx_pick.studies.throughput.side_by_side for the fields):

  python benchmarks/throughput.py --objects door_opener \\
      --run mujoco:n=4096:batch=1024 \\
      --run warp:n=16384:batch=16384:refill=0:warmup=16384 \\
      --run warp:n=65536:batch=16384:warmup=65536 \\
      --run mjx:n=2048:batch=2048:refill=0 --out benchmarks/out

A warm-up of the same n compiles and captures exactly the program the timed run uses
(a refilled run's program depends on its pool size and its padded queue length).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import time
from pathlib import Path

import jax

import mjx_pick as mp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.studies.throughput import RunSpec, measure, side_by_side


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--backends", default="mjx")
    ap.add_argument("--batch-sizes", default="1024,4096,16384")
    ap.add_argument(
        "--repeats", type=int, default=3, help="timed runs after a warm-up; 0: time the first run"
    )
    ap.add_argument("--grasp", help="GraspConfig TOML (default: GraspConfig())")
    ap.add_argument("--solver", help="SolverParams TOML (default: SolverParams())")
    ap.add_argument("--out", default="benchmarks/out")
    ap.add_argument("--tag", default="", help="free text recorded with each row")
    ap.add_argument(
        "--devices", default="", help="comma-separated device counts to shard over (default: all)"
    )
    ap.add_argument(
        "--run",
        action="append",
        default=[],
        help="side by side: BACKEND:n=N[:batch=B][:refill=0|1][:ticks_per_call=K]"
        "[:graph_mode=M][:warmup=W] (repeat; replaces --backends/--batch-sizes)",
    )
    ap.add_argument("--seed", type=int, default=0, help="pick-point seed (side by side)")
    args = ap.parse_args()
    from mjx_pick.core.config import load_toml

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
    stamp = {"date": time.strftime("%Y-%m-%d"), "commit": commit, "tag": args.tag}
    if args.run:
        specs = [RunSpec.parse(r) for r in args.run]
        for obj_name in args.objects.split(","):

            def keep(row, path=out / "side_by_side.jsonl"):
                row.update(stamp)
                _append(path, row)
                print(" ".join(f"{k}={v}" for k, v in row.items()), flush=True)

            side_by_side(obj_name, gripper, specs, grasp, solver, seed=args.seed, on_row=keep)
        return
    path = out / "throughput.csv"
    for obj_name in args.objects.split(","):
        for backend_name in args.backends.split(","):
            for batch in (int(b) for b in args.batch_sizes.split(",")):
                for nd in [int(x) for x in args.devices.split(",")] if args.devices else [None]:
                    row = measure(
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
                    row.update(stamp)
                    _append(path, row)
                    print(" ".join(f"{k}={v}" for k, v in row.items()), flush=True)


def _append(path: Path, row: dict) -> None:
    """Append a row: CSV (header from the file's first row) or, for .jsonl, one JSON
    object per line (side-by-side rows differ in fields: Warp adds its buffers)."""
    if path.suffix == ".jsonl":
        with path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        return
    new = not path.exists()
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)


if __name__ == "__main__":
    main()
