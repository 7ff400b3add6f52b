"""Benchmark: does Warp's deterministic mode make MuJoCo Warp's labels repeat, and at what
cost? One process per mode (the mode must be set before Warp builds its modules):

    python benchmarks/probes/warp_deterministic.py --mode run_to_run --n 4096 --repeats 2
    python benchmarks/probes/warp_deterministic.py --mode not_guaranteed --n 4096 --repeats 2

Prints one JSON line: per repeat the wall time of the evaluate call, and the share of
labels (success) and failure reasons that differ from the first repeat.
"""

import argparse
import json
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mode", choices=("not_guaranteed", "run_to_run", "gpu_to_gpu"))
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--n", type=int, default=4096)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    import warp as wp

    wp.config.deterministic = getattr(wp.DeterministicMode, args.mode.upper())
    import mjx_pick as mp

    runs = []
    for _ in range(args.repeats + 1):  # the first compiles
        t0 = time.perf_counter()
        table = mp.evaluate(args.object, n=args.n, seed=0, backend="warp").table
        runs.append((time.perf_counter() - t0, table))
    first = runs[1][1]
    out = {"mode": args.mode, "object": args.object, "n": args.n, "repeats": []}
    for wall, t in runs[1:]:
        out["repeats"].append(
            {
                "wall_s": round(wall, 2),
                "success": float(np.mean(np.asarray(t["success"]))),
                "labels_differ": float(
                    np.mean(np.asarray(t["success"]) != np.asarray(first["success"]))
                ),
                "reasons_differ": float(
                    np.mean(np.asarray(t["failure"]) != np.asarray(first["failure"]))
                ),
            }
        )
    out["first_call_s"] = round(runs[0][0], 2)
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
