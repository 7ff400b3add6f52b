"""Benchmark: how many success labels change with fewer solver iterations (C engine).

256 door-opener pick-points (seed 0), default procedure, against the default solver
(iterations 10, ls_iterations 8): labels changed, diverged count, median score change.

  python benchmarks/probes/solver_iterations.py
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.engine.runner import Runner

VARIANTS = {
    "default (10/8)": {},
    "6/6": {"iterations": 6, "ls_iterations": 6},
    "4/4": {"iterations": 4, "ls_iterations": 4},
    "2/4": {"iterations": 2, "ls_iterations": 4},
}


def main() -> None:
    obj, gripper, grasp = (
        mp.load_asset("door_opener"),
        mp.load_gripper("robotiq-2f85"),
        GraspConfig(),
    )
    picks = pp.generate_normal(obj, gripper, 256, seed=0)
    base = None
    for label, kw in VARIANTS.items():
        scene = mp.build_scene(obj, gripper, solver=dataclasses.replace(mp.SolverParams(), **kw))
        runner = Runner("mujoco", len(picks))
        backend = runner.make(scene, grasp)
        t0 = time.perf_counter()
        out = runner.run(backend, make_inputs(scene, grasp, picks)).results
        base = base or out
        print(
            f"{label:15s} {time.perf_counter() - t0:6.2f} s  success {out['success'].mean():.3f}  "
            f"diverged {int(out['diverged'].sum()):3d}  labels changed "
            f"{np.mean(out['success'] != base['success']):.4f}  median |d score| "
            f"{np.nanmedian(np.abs(out['score'] - base['score'])):.4f}"
        )


if __name__ == "__main__":
    main()
