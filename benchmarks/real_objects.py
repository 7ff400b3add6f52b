"""Real-object benchmark (issue 16): the shipped YCB meshes grasped by a Robotiq 2F-85.

Per object: success rate with its Wilson 95 % interval, failure reasons, and (with
--mjx) the labels of MuJoCo C against MJX on the same pick-points. Light rigid parts
grasped across by a 2F-85 at 50 N must mostly succeed; every failure class that remains
must be explained physically (benchmarks/RESULTS.md, "Real objects").

    python benchmarks/real_objects.py --n 48 --out benchmarks/results/real_objects.json
    python benchmarks/real_objects.py --n 16 --objects 040_large_marker --mjx
"""

from __future__ import annotations

import argparse
import collections
import time
import tomllib
from importlib import resources

import numpy as np
from mjx_pick.kernels import grasp as gk

import mjx_pick as mp
from mjx_pick.config import write_json
from mjx_pick.metrics import wilson_interval


def ycb_manifest() -> dict:
    folder = resources.files("mjx_pick.assets") / "objects" / "ycb"
    return tomllib.loads((folder / "manifest.toml").read_text())


def run_object(name: str, entry: dict, n: int, seed: int, force_n: float, mjx: bool) -> dict:
    folder = resources.files("mjx_pick.assets") / "objects" / "ycb"
    with resources.as_file(folder / entry["file"]) as path:
        t0 = time.perf_counter()
        obj = mp.load_object(path, unit=entry["unit"], mass_g=entry["mass_g"])
        t_load = time.perf_counter() - t0
    grasp = mp.GraspConfig(grip_force_n=force_n)
    row = {"object": name, "mass_g": entry["mass_g"], "height_mm": round(obj.height_mm, 2)}
    labels = {}
    for backend in ("mujoco", "mjx") if mjx else ("mujoco",):
        ev = mp.evaluate(obj, "robotiq-2f85", n=n, seed=seed, grasp=grasp, backend=backend)
        table = ev.table.to_pandas()
        k, m = int(table["success"].sum()), len(table)
        lo, hi = wilson_interval(k, m)
        labels[backend] = table["success"].to_numpy()
        row[backend] = {
            "n": m,
            "success_rate": k / m,
            "wilson95": [round(lo, 3), round(hi, 3)],
            "failures": dict(collections.Counter(table["failure"])),
            "diverged": int(table["diverged"].sum()),
            "median_slip_mm": float(np.nanmedian(table["slip_mm"])),
            "median_phi_max_deg": float(np.nanmedian(table["phi_max_deg"])),
            "fingertip_height_mm": ev.config["scene"]["fingertip_height_mm"],
            "pad_patch_mm": ev.config["scene"]["pad_patch_mm"],
        }
    if mjx:
        row["labels_agree"] = float(np.mean(labels["mujoco"] == labels["mjx"]))
    row["load_s"] = round(t_load, 1)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=48, help="pick-points per object")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--force-n", type=float, default=50.0, help="F_d, N")
    ap.add_argument("--objects", default="", help="comma-separated names (default: all)")
    ap.add_argument("--mjx", action="store_true", help="also run MJX and compare labels")
    ap.add_argument("--out", default="", help="JSON file for the figures")
    args = ap.parse_args()
    manifest = ycb_manifest()
    names = [s for s in args.objects.split(",") if s] or list(manifest)
    rows = []
    for name in names:
        row = run_object(name, manifest[name], args.n, args.seed, args.force_n, args.mjx)
        rows.append(row)
        c = row["mujoco"]
        print(
            f"{name:24s} {c['success_rate']:6.1%} [{c['wilson95'][0]:.2f}, "
            f"{c['wilson95'][1]:.2f}] {c['failures']}"
            + (f" C-vs-MJX labels {row['labels_agree']:.1%}" if args.mjx else ""),
            flush=True,
        )
    if args.out:
        write_json(args.out, {"args": vars(args), "failure_codes": gk.FAILURES, "rows": rows})


if __name__ == "__main__":
    main()
