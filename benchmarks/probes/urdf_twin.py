"""The Robotiq 2F-85 from its URDF against its MJCF twin (MuJoCo Menagerie's linkage):
measured geometry, then the labels of the same pick-points on MuJoCo C.

    python benchmarks/probes/urdf_twin.py --objects door_opener,block --n 200 \\
        --out benchmarks/results/urdf_twin.json

Writes one JSON: each gripper's measured stroke, pad size and pad descent, and per
object the success rates (Wilson 95 % intervals), the label agreement on the shared
pick-points and the pick-points whose labels differ (with both failure classes).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import mjx_pick as mp
from mjx_pick.core import mjcf_gripper
from mjx_pick.core.config import write_json
from mjx_pick.core.metrics import wilson_interval

GRIPPERS = ("robotiq-2f85-urdf", "robotiq-2f85-linkage")


def geometry(name: str) -> dict:
    g = mp.load_gripper(name)
    k = mjcf_gripper.characterise(g.mjcf)
    return {
        "stroke_mm": g.stroke_mm,
        "pad_width_mm": g.finger_width_mm,
        "pad_depth_mm": g.finger_depth_mm,
        "pad_height_mm": g.pad_height_mm,
        "pad_descent_mm": round(1e3 * float(k.pad_centre_z[0] - k.pad_centre_z.min()), 3),
        "force_limit_min_n": round(float(k.force_limit_n.min()), 1),
    }


def compare(obj: str, n: int, seed: int, folder: Path) -> dict:
    tables, seconds = {}, {}
    for name in GRIPPERS:
        t0 = time.perf_counter()
        ev = mp.evaluate(obj, name, n=n, seed=seed, out=folder / f"{obj}-{name}")
        seconds[name] = round(time.perf_counter() - t0, 1)
        tables[name] = ev.table.to_pandas().set_index("pick_id")
    a, b = (tables[g] for g in GRIPPERS)
    shared = a.index.intersection(b.index)
    same = a.loc[shared, "success"] == b.loc[shared, "success"]
    differ = shared[~same.to_numpy()]
    rates = {}
    for g in GRIPPERS:
        s = int(tables[g]["success"].sum())
        rates[g] = {"successes": s, "n": len(tables[g]), "ci": wilson_interval(s, len(tables[g]))}
    return {
        "object": obj,
        "success": rates,
        "shared_picks": len(shared),
        "label_agreement": float(same.mean()),
        "agreement_ci": wilson_interval(int(same.sum()), len(shared)),
        "score_mean_abs_diff": float(
            np.abs(a.loc[shared, "score"] - b.loc[shared, "score"]).mean()
        ),
        "differing": [
            {"pick_id": int(p), **{g: tables[g].loc[p, "failure"] for g in GRIPPERS}}
            for p in differ
        ],
        "seconds": seconds,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="door_opener")
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rows = [compare(o, args.n, args.seed, Path(tmp)) for o in args.objects.split(",")]
    result = {"geometry": {g: geometry(g) for g in GRIPPERS}, "objects": rows}
    write_json(args.out, result)
    for r in rows:
        print(
            f"{r['object']}: agreement {r['label_agreement']:.3f} on {r['shared_picks']} picks; "
            + ", ".join(f"{g} {v['successes']}/{v['n']}" for g, v in r["success"].items())
        )


if __name__ == "__main__":
    main()
