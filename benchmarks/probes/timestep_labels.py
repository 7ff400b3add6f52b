"""Which time steps leave the grasp labels as they are at a smaller one.

Evaluates the same N pick-points (seed 0, default procedure, MuJoCo C) at each time step
and counts the success labels that differ from those of the first (smallest) step. The
steps must divide the procedure's control period (5 ms). Sets
``mjx_pick.core.physics.CONVERGED_TIMESTEP_S``, above which a time step is warned about.

  python benchmarks/probes/timestep_labels.py --object door_opener --n 256 \\
      --steps 0.0005,0.001,0.00125,0.0016666666666666668,0.0025,0.005
"""

from __future__ import annotations

import argparse
import time
import warnings

import mjx_pick as mp
from mjx_pick.core.config import PlausibilityWarning
from mjx_pick.core.physics import SolverParams


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--steps", default="0.0005,0.001,0.00125,0.0016666666666666668,0.0025")
    args = ap.parse_args()
    steps = [float(s) for s in args.steps.split(",")]
    tables = {}
    for dt in steps:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PlausibilityWarning)
            solver = SolverParams(timestep_s=dt)
        ev = mp.evaluate(args.object, n=args.n, seed=0, backend="mujoco", solver=solver, n_traces=0)
        tables[dt] = t = ev.table.to_pandas()
        print(
            f"dt={dt:.6g} s: success {t.success.mean():.3f}, diverged {int(t.diverged.sum())}, "
            f"mean score {t.score.mean():.3f} ({time.perf_counter() - t0:.1f} s)",
            flush=True,
        )
    ref = tables[steps[0]]
    for dt in steps[1:]:
        differ = int((tables[dt].success.values != ref.success.values).sum())
        print(f"dt={dt:.6g} s: {differ} of {len(ref)} labels differ from dt={steps[0]:g} s")


if __name__ == "__main__":
    main()
