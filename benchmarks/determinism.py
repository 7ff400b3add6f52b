"""Benchmark: are a backend's labels the same when the same pick-points run again?

MuJoCo C is deterministic: the same inputs give bit-identical results. MuJoCo Warp on a
GPU is not guaranteed to be: its collision kernels number contacts with atomic counters
(the order of the constraint rows changes from run to run) and some reductions are
float atomics, so two runs can differ in the last bits, and a pick-point whose outcome
is balanced on a threshold (a part that just holds, just slips) can change its label.
This measures how often, so that a user knows how far a GPU label is reproducible:

* ``repeat``: the same pick-points, the same batch size, R times in one process;
* ``batch``: the same pick-points with another batch size (the pool's shape);
* ``shift``: the same pick-points moved by a micrometre (``--shift-um``): on MuJoCo C,
  which is deterministic, this asks how many labels rest on a threshold that a change far
  below any real pose error crosses -- the physics' own sensitivity, which bounds how
  reproducible any engine's label there can be;
* per backend: the share of pick-points whose label (success) or failure reason differs
  from the first run in any repeat, and the spread (max - min over the runs) of the
  graded score, the final lift, the left pad's peak force and the slip.

    python benchmarks/determinism.py --backends mujoco --n 64 --repeats 2      # a CPU
    python benchmarks/determinism.py --backends warp,mujoco --n 4096 --repeats 3 \\
        --out benchmarks/results/determinism_h100.json                     # a GPU machine
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from pathlib import Path

import numpy as np

import mjx_pick as mp
from mjx_pick.core.config import write_json
from mjx_pick.studies.calibration import Problem

COLUMNS = ("score", "lift_height_mm", "max_force_left_n", "slip_mm")


def run_backend(obj: str, n: int, seed: int, backend: str, repeats: int, batch: int | None):
    """R repeats at the default batch size and one at ``batch``; returns the tables and,
    per run, [wall, compile, run] seconds."""
    tables, walls = [], []
    for r in range(repeats + (1 if batch else 0)):
        t0 = time.perf_counter()
        ev = mp.evaluate(
            obj, n=n, seed=seed, backend=backend, batch_size=batch if r == repeats else None
        )
        # the evaluate's wall time and its backend's compile and simulating time (s)
        walls.append(
            [round(time.perf_counter() - t0, 1)]
            + [round(float(ev.summary[k]), 1) for k in ("compile_s", "run_s")]
        )
        tables.append(ev.table.to_pandas())
    return tables, walls


def run_shifted(obj, table, backend: str, shift_um: float):
    """The pick-points of table moved by shift_um micrometres along x (the object's
    offset under the gripper), one run: how far a label rests on a threshold that a
    micrometre crosses. Returns the table in table's pick order."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "picks.csv"
        lines = ["x_mm,y_mm,yaw_deg"] + [
            f"{float(x) + shift_um * 1e-3!r},{float(y)!r},{float(yaw)!r}"
            for x, y, yaw in zip(table["x_mm"], table["y_mm"], table["yaw_deg"], strict=True)
        ]
        csv.write_text("\n".join(lines) + "\n")
        ev = mp.evaluate(obj, picks=csv, backend=backend)
    return ev.table.to_pandas()


def overlap(repeats, shifted) -> dict:
    """Does a label that the shift flips (what ``evaluate --stability-um`` flags) predict
    the labels that change between repeats? Counts over the pick-points."""
    ref = repeats[0]["success"].to_numpy()
    flagged = shifted["success"].to_numpy() != ref
    flipped = np.zeros(len(ref), bool)
    for t in repeats[1:]:
        flipped |= t["success"].to_numpy() != ref
    return {
        "flagged": int(flagged.sum()),
        "flipped_between_repeats": int(flipped.sum()),
        "flipped_and_flagged": int((flipped & flagged).sum()),
    }


def compare(tables, first: int = 0) -> dict:
    """Label, failure-reason and value differences of tables[1:] against tables[first]."""
    ref = tables[first]
    flips = np.zeros(len(ref), bool)
    reasons = np.zeros(len(ref), bool)
    for t in tables[1:]:
        flips |= t["success"].to_numpy() != ref["success"].to_numpy()
        reasons |= t["failure"].to_numpy() != ref["failure"].to_numpy()
    out = {
        "runs": len(tables),
        "labels_changed": int(flips.sum()),
        "labels_changed_share": float(flips.mean()),
        "failure_reason_changed": int(reasons.sum()),
        "bit_identical": all(
            np.array_equal(t[c].to_numpy(), ref[c].to_numpy(), equal_nan=True)
            for t in tables[1:]
            for c in COLUMNS
        ),
    }
    for c in COLUMNS:
        v = np.stack([t[c].to_numpy(float) for t in tables])  # (runs, n)
        spread = np.nanmax(v, axis=0) - np.nanmin(v, axis=0)
        out[f"{c}_spread"] = {
            "median": float(np.nanmedian(spread)),
            "p99": float(np.nanpercentile(spread, 99)),
            "max": float(np.nanmax(spread)),
            "share_nonzero": float(np.mean(spread > 0)),
        }
    return out


def sibling(name: str):
    """benchmarks/<name>.py as a module."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def calibration_loss(backend: str, repeats: int, params: int = 3) -> dict:
    """The calibration benchmark's loss (benchmarks/calibration.py: 16 rows, three
    replicas per traced row) at the hidden parameters, evaluated ``repeats`` times one
    vector per call, then as ``repeats`` copies in one call: how much of an estimator's
    step is the engine's own run-to-run noise."""
    cb = sibling("calibration")
    names = cb.SETS[params]
    obj, base, train, _ = cb.setup(16, 0, names, backend)
    problem = Problem(obj, train, names, base, backend=backend, replicates=3)
    truth = problem.space.theta([cb.HIDDEN[n] for n in names])
    one_by_one = [float(problem.loss(truth[None])[0]) for _ in range(repeats)]
    together = problem.loss(np.repeat(truth[None], repeats, axis=0)).astype(float).tolist()
    return {
        "backend": backend,
        "hidden_parameters": params,
        "one_per_call": one_by_one,
        "copies_in_one_call": together,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="door_opener,050_medium_clamp")
    ap.add_argument("--backends", default="mujoco")
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=2, help="runs at the default batch size")
    ap.add_argument(
        "--batch", type=int, default=0, help="one more run at this batch size (0: none)"
    )
    ap.add_argument(
        "--calibration-loss",
        type=int,
        default=0,
        help="also: the calibration benchmark's loss at its hidden parameters this many "
        "times per backend (0: not)",
    )
    ap.add_argument(
        "--shift-um",
        default="",
        help="also: runs with every pick-point moved these micrometres along x (comma-"
        "separated), compared with the first run; the first shift's flips (what "
        "evaluate --stability-um flags) against the repeats' and the other shifts' flips",
    )
    ap.add_argument("--out", default="benchmarks/out/determinism.json")
    args = ap.parse_args()
    if args.repeats < 2:
        ap.error(f"--repeats must be >= 2 to compare runs, got {args.repeats}")
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    report = {"date": time.strftime("%Y-%m-%d"), "commit": commit, "args": vars(args), "rows": []}
    real_objects = sibling("real_objects")  # the YCB manifest and loader
    ycb = real_objects.ycb_manifest()
    for name in args.objects.split(","):
        # a shipped YCB part by its manifest name, else a shipped asset name
        obj = real_objects.load_ycb(name) if name in ycb else name
        for backend in args.backends.split(","):
            tables, walls = run_backend(
                obj, args.n, args.seed, backend, args.repeats, args.batch or None
            )
            row = {
                "object": name,
                "backend": backend,
                "n": len(tables[0]),
                "success_rate": float(tables[0]["success"].mean()),
                "wall_compile_run_s": walls,
                "repeat": compare(tables[: args.repeats]),
            }
            if args.batch:
                row["batch"] = {"batch_size": args.batch, **compare([tables[0], tables[-1]])}
            shifts = [float(v) for v in args.shift_um.split(",")] if args.shift_um else []
            if shifts:
                moved = [run_shifted(obj, tables[0], backend, um) for um in shifts]
                row["shifted"] = {"shift_um": shifts[0], **compare([tables[0], moved[0]])}
                row["shift_flags_repeat_flips"] = overlap(tables[: args.repeats], moved[0])
                if len(shifts) > 1:  # the first shift's flags against the other shifts' flips
                    row["shift_flags_other_shifts"] = {
                        "shift_um": shifts[1:],
                        **overlap([tables[0], *moved[1:]], moved[0]),
                    }
            report["rows"].append(row)
            print(json.dumps(row), flush=True)
            write_json(Path(args.out), report)
    for backend in args.backends.split(",") if args.calibration_loss else ():
        row = calibration_loss(backend, args.calibration_loss)
        report.setdefault("calibration_loss", []).append(row)
        print(json.dumps(row), flush=True)
        write_json(Path(args.out), report)


if __name__ == "__main__":
    main()
