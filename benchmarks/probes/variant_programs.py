"""How many compiled programs a study's gripper variants need (``engine.variants``).

Builds the scene of every variant a study would run -- a sweep of 8 finger widths, and
``design`` with its defaults (12 Latin-hypercube variants + the base gripper) within
bounds on finger width, finger depth and stroke -- and counts the distinct
``program_key``s per backend: one backend (one compile on MJX and Warp) per key. Nothing
is simulated; the answer takes seconds on any machine.

  python benchmarks/probes/variant_programs.py --object door_opener
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import mjx_pick as mp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.variants import carried_fields, program_key, varying_fields
from mjx_pick.studies.comparison import sample_variants

WIDTHS = (10, 14, 18, 22, 26, 30, 34, 38)  # mm, as benchmarks/time_to_answer.py
BOUNDS = {
    "finger_width_mm": (10.0, 40.0),
    "finger_depth_mm": (5.0, 12.0),
    "stroke_mm": (60.0, 100.0),
}


def count(obj, settings: list[mp.Settings]) -> dict:
    """Per backend: programs (distinct keys), and the model fields the largest carries."""
    scenes = [mp.build_scene(obj, s.gripper, s.contact, s.solver, s.grasp) for s in settings]
    out = {"scenes": len(scenes)}
    for backend in ("mujoco", "mjx", "warp"):
        groups: dict = {}
        for s, scene in zip(settings, scenes, strict=True):
            groups.setdefault(program_key(scene, s.grasp, backend), []).append(scene)
        biggest = max(groups.values(), key=len)
        fields = varying_fields(
            biggest[0].model, [m.model for m in biggest], carried_fields(backend)
        )
        out[backend] = {"programs": len(groups), "largest": len(biggest), "fields": list(fields)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    args = ap.parse_args()
    obj = mp.load_asset(args.object)
    base = mp.Settings(grasp=GraspConfig())
    sweep = [
        dataclasses.replace(
            base, gripper=dataclasses.replace(base.gripper, finger_width_mm=float(w))
        )
        for w in WIDTHS
    ]
    pool = sample_variants(base.gripper, BOUNDS, 12, seed=0) + [base.gripper]
    design = [base.on_gripper(g)[0] for g in pool]
    report = {
        "object": args.object,
        "sweep_8_widths": count(obj, sweep),
        "design_defaults": count(obj, design),
    }
    report["design_bounds"] = {k: list(v) for k, v in BOUNDS.items()}
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
