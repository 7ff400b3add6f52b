"""CoACD's settings against the labels they give, on the shipped YCB parts.

Each variant of ``objects.COACD_SETTINGS`` prepares every part afresh (the convex
collision pieces; the outline, hence the pick-points, does not depend on them), and the
same pick-points are simulated on MuJoCo C. Labels are compared pick by pick with the
first variant's. A variant that only changes CoACD's seed gives the noise floor: another
decomposition, as valid as the first, moves labels by that much.

    python benchmarks/coacd_labels.py --n 256 \
        --variants 'seed=0;seed=1;mcts_max_depth=2,mcts_iterations=60' \
        --out benchmarks/results/coacd_labels.json

Per part and variant: CoACD's CPU seconds (the process's, all its threads) and wall
seconds, the pieces, the success rate, and the picks whose label differs from the
first variant's.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import tempfile
import time
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

import mjx_pick as mp
from mjx_pick.core import objects


def variant(text: str) -> dict:
    """'mcts_max_depth=2,mcts_iterations=60' -> the settings it changes (ints)."""
    out = {}
    for item in filter(None, (t.strip() for t in text.split(","))):
        key, _, value = item.partition("=")
        if key not in objects.COACD_SETTINGS:
            raise SystemExit(f"{key!r} is not one of {sorted(objects.COACD_SETTINGS)}")
        out[key] = type(objects.COACD_SETTINGS[key])(value)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=256, help="pick-points per part")
    ap.add_argument("--objects", default="", help="YCB names, comma-separated (default: all)")
    ap.add_argument("--variants", default="seed=0;seed=1", help="';'-separated settings")
    ap.add_argument("--out", default="benchmarks/results/coacd_labels.json")
    args = ap.parse_args()

    folder = resources.files("mjx_pick") / "assets" / "objects" / "ycb"
    manifest = tomllib.loads((folder / "manifest.toml").read_text())
    names = [n for n in args.objects.split(",") if n] or sorted(manifest)
    variants = [variant(v) for v in args.variants.split(";")]
    default = dict(objects.COACD_SETTINGS)
    os.environ["MJX_PICK_CACHE_DIR"] = tempfile.mkdtemp(prefix="coacd_labels.")
    record = {
        "date": datetime.date.today().isoformat(),
        "device": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
        "commit": subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip(),
        "n": args.n,
        "defaults": default,
        "variants": variants,
        "parts": {},
    }
    for name in names:
        entry = manifest[name]
        rows, first = [], None
        for changes in variants:
            objects.COACD_SETTINGS.clear()
            objects.COACD_SETTINGS.update({**default, **changes})
            t0, c0 = time.perf_counter(), time.process_time()
            obj = mp.load_object(
                str(folder / entry["file"]), unit=entry["unit"], mass_g=entry["mass_g"]
            )
            prep = {"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
            ev = mp.evaluate(obj, n=args.n, seed=0, backend="mujoco", n_traces=0)
            table = ev.table
            picks = np.stack([table[c].to_numpy() for c in ("x_mm", "y_mm", "yaw_deg")])
            success = table["success"].to_numpy(zero_copy_only=False)
            if first is None:
                first = (picks, success)
            assert np.array_equal(picks, first[0]), "the pick-points moved with the pieces"
            row = {
                "changes": changes,
                "prepare_cpu_s": round(prep["cpu_s"], 2),
                "prepare_wall_s": round(prep["wall_s"], 2),
                "pieces": len(obj.pieces),
                "success_rate": round(float(success.mean()), 4),
                "differ": int((success != first[1]).sum()),
            }
            rows.append(row)
            print(name, json.dumps(row), flush=True)
        record["parts"][name] = rows
    objects.COACD_SETTINGS.clear()
    objects.COACD_SETTINGS.update(default)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(record, indent=2) + "\n")
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
