"""A second job in the same process: the compiled program kept, or compiled again.

    python benchmarks/probes/second_job.py --backend warp --n 1024 [--object door_opener]

The GUI's worker, a notebook or a script runs one evaluation after another in one
process. Three evaluations of the same part and settings, each its own call of
``mp.evaluate`` (a new runner and backend): the first pays imports and compiles;
before the second the process's compiled programs are dropped
(``mjx_backend.KEPT_PROGRAMS.clear()``), as every new backend had to compile before they were
kept; the third runs with them kept. Prints each job's wall time and the compile and
run times of its summary; ``--out`` writes them as JSON.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import mjx_pick as mp
from mjx_pick.engine import mjx_backend


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="warp", help="warp or mjx (C keeps its tick anyway)")
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--n", type=int, default=1024)
    ap.add_argument("--out", default="")
    args = ap.parse_args()
    obj = mp.load_object(args.object)
    rows = []
    for job, programs in ((1, "first"), (2, "dropped"), (3, "kept")):
        if programs == "dropped":
            mjx_backend.KEPT_PROGRAMS.clear()
        t0 = time.perf_counter()
        ev = mp.evaluate(obj, n=args.n, seed=job, backend=args.backend)
        wall = time.perf_counter() - t0
        s = ev.summary
        row = {
            "job": job,
            "programs": programs,
            "wall_s": round(wall, 2),
            "compile_s": round(s["compile_s"], 2),
            "run_s": round(s["run_s"], 2),
            "success_rate": s.get("success_rate"),
        }
        rows.append(row)
        print(row, flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps({"args": vars(args), "jobs": rows}, indent=1))


if __name__ == "__main__":
    main()
