"""Agreement of the MJX and MuJoCo C backends on the same pick-points.

Runs N pick-points on both backends and reports the fraction of equal success labels,
the Spearman correlation of the scores, and, for every disagreement, whether it is a
marginal pick-point: its C-engine label flips under sub-millimetre perturbations of the
pose (0.2 mm, 0.2 deg; M perturbed copies). The same perturbation test on an equal
number of agreeing pick-points is the control.

  python benchmarks/agreement.py --object door_opener --n 512 --out benchmarks/out
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import time
from pathlib import Path

import jax
import numpy as np
from scipy.stats import spearmanr

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.engine.runner import Runner
from mjx_pick.kernels import grasp as gk


def perturbed_success(scene, grasp, picks: pp.GraspBatch, copies: int, seed: int) -> np.ndarray:
    """Fraction of `copies` sub-mm perturbations of each pick that succeed (C engine)."""
    rng = np.random.default_rng(seed)
    n = len(picks)
    idx = np.repeat(np.arange(n), copies)
    rep = picks.take(idx)
    rep = dataclasses.replace(
        rep,
        x_mm=rep.x_mm + rng.normal(0, 0.2, len(idx)),
        y_mm=rep.y_mm + rng.normal(0, 0.2, len(idx)),
        yaw_deg=rep.yaw_deg + rng.normal(0, 0.2, len(idx)),
    )
    out = Runner("mujoco", 256).simulate(scene, grasp, make_inputs(scene, grasp, rep)).results
    return out["success"].reshape(n, copies).mean(axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--copies", type=int, default=8)
    ap.add_argument("--mjx-batch", type=int, default=512)
    ap.add_argument("--grasp", help="GraspConfig TOML")
    ap.add_argument("--out", default="benchmarks/out")
    args = ap.parse_args()
    from mjx_pick.core.config import load_toml

    grasp = load_toml(GraspConfig, args.grasp) if args.grasp else GraspConfig()
    obj = mp.load_object(args.object)
    gripper = mp.load_gripper(args.gripper)
    # both engines at the physics MJX-JAX runs (it refuses others); its labels against
    # C's at the default physics: benchmarks/mjx_physics.py
    contact, solver = mp.ContactParams.differentiable(), mp.SolverParams.differentiable()
    scene = mp.build_scene(obj, gripper, contact, solver)
    picks = pp.generate_normal(obj, gripper, args.n, seed=args.seed)
    inputs = make_inputs(scene, grasp, picks)
    res = {}
    timing = {}
    for name, batch in (("mujoco", 256), ("mjx", args.mjx_batch)):
        runner = Runner(name, batch)
        backend = runner.make(scene, grasp)
        t0 = time.perf_counter()
        res[name] = runner.run(backend, inputs).results
        timing[name] = {
            "wall_s": round(time.perf_counter() - t0, 2),
            "compile_s": round(backend.stats.compile_s, 2),
            "run_s": round(backend.stats.run_s, 2),
            "device": backend.device,
        }
    a, b = res["mujoco"], res["mjx"]
    agree = a["success"] == b["success"]
    valid = ~np.isnan(a["score"]) & ~np.isnan(b["score"])
    rho = float(spearmanr(a["score"][valid], b["score"][valid]).statistic)
    dis = np.flatnonzero(~agree)
    rng = np.random.default_rng(1)
    ctrl = rng.choice(
        np.flatnonzero(agree), size=min(len(dis) or 8, int(agree.sum())), replace=False
    )
    frac_dis = (
        perturbed_success(scene, grasp, picks.take(dis), args.copies, 2)
        if len(dis)
        else np.zeros(0)
    )
    frac_ctrl = perturbed_success(scene, grasp, picks.take(ctrl), args.copies, 3)
    marginal = lambda f: (f > 0) & (f < 1)  # noqa: E731
    rows = []
    for j, i in enumerate(dis):
        rows.append(
            {
                "pick_id": int(picks.pick_id[i]),
                "mujoco": gk.FAILURES[int(a["failure"][i])],
                "mjx": gk.FAILURES[int(b["failure"][i])],
                "lift_mm": [float(a["lift_height_mm"][i]), float(b["lift_height_mm"][i])],
                "phi_max_deg": [float(a["phi_max_deg"][i]), float(b["phi_max_deg"][i])],
                "perturbed_success_fraction": float(frac_dis[j]),
            }
        )
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    summary = {
        "date": time.strftime("%Y-%m-%d"),
        "commit": commit,
        "device": f"{jax.devices()[0].device_kind}",
        "object": args.object,
        "n": args.n,
        "label_agreement": float(agree.mean()),
        "score_spearman": rho,
        "success_rate": {"mujoco": float(a["success"].mean()), "mjx": float(b["success"].mean())},
        "diverged": {"mujoco": int(a["diverged"].sum()), "mjx": int(b["diverged"].sum())},
        "disagreements": len(dis),
        "disagreements_marginal": int(marginal(frac_dis).sum()),
        "control_marginal": f"{int(marginal(frac_ctrl).sum())} of {len(ctrl)}",
        "timing": timing,
        "disagreement_rows": rows,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"agreement_{args.object}_{args.n}.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps({k: v for k, v in summary.items() if k != "disagreement_rows"}, indent=2))


if __name__ == "__main__":
    main()
