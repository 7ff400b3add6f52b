"""Benchmark: contact calibration -- gradient quality, synthetic recovery, baseline.

1. Gradient quality: forward-mode derivatives through the MJX rollout (``jvp``) of the
   calibration loss against central finite differences (two step sizes), for three
   parameters (pad friction, table friction, pad stiffness).
2. Synthetic recovery: outcomes simulated with hidden pad friction on a 1 kg block
   over a range of grip forces; fit from the paper's 0.86 with each estimator;
   parameter error and held-out accuracy (correct / total) before and after.
3. Stiffness: how much a 3x softer pad contact changes the simulated force trace (is
   it identifiable at all?).
4. Baseline: uniform random search in the same bounds until it reaches the gradient
   fit's loss: rollouts and wall time.

  python benchmarks/calibration.py --steps 40 --out benchmarks/results/calibration.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import time

import numpy as np
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.calibrate import Problem, calibrate, random_search, synthetic_outcomes
from mjx_pick.grasp import GraspConfig

HIDDEN_MU = 0.62


def setup(rows_per_yaw: int, seed: int):
    obj = mp.object_from_polygon(
        box(-20, -10, 20, 10), thickness_mm=20, mass_g=1000, name="heavy_block"
    )
    gripper = mp.GripperSpec(name="light-gripper", force_min_n=1.0)
    base = mp.Settings(gripper=gripper, grasp=GraspConfig(close_timeout_s=0.6, hold_s=0.1))
    hidden = dataclasses.replace(base, contact=mp.ContactParams(pad_friction=HIDDEN_MU))
    rng = np.random.default_rng(seed)

    def rows(n_per_yaw, lo, hi):
        f = np.tile(np.linspace(lo, hi, n_per_yaw), 2)
        n = len(f)
        yaw = np.where(np.arange(n) < n_per_yaw, 0.0, 180.0) + rng.uniform(-3, 3, n)
        return rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), yaw, f

    train = synthetic_outcomes(obj, hidden, *rows(rows_per_yaw, 6.0, 14.0))
    held = synthetic_outcomes(obj, hidden, *rows(rows_per_yaw // 2, 6.3, 13.7))
    return obj, base, hidden, train, held


def gradient_quality(obj, base, train) -> dict:
    names = ["pad_friction", "table_friction", "pad_stiffness_n_per_mm"]
    sub = train.take(np.arange(0, len(train), 3))
    problem = Problem(obj, sub, names, base, backend="mjx")
    theta = problem.space.theta([0.62, 0.2, problem.space.hi[2] / 2])
    t0 = time.perf_counter()
    loss, grad = problem.mjx_loss_and_grad(theta)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    problem.mjx_loss_and_grad(theta)
    again = time.perf_counter() - t0
    out = {
        "rows": len(sub),
        "loss": loss,
        "jvp": grad.tolist(),
        "jvp_first_call_s": first,
        "jvp_s": again,
        "fd": {},
    }
    f = problem._rollout
    for h in (0.03, 0.1):
        fd = []
        for i in range(len(names)):
            e = np.zeros(len(names), np.float32)
            e[i] = h
            lp = float(f(theta + e)[0])
            lm = float(f(theta - e)[0])
            fd.append((lp - lm) / (2 * h))
        rel = [abs(a - b) / max(abs(b), 1e-9) for a, b in zip(grad, fd, strict=True)]
        out["fd"][str(h)] = {"grad": fd, "relative_error": rel}
    out["names"] = names
    return out


def stiffness_sensitivity(base) -> dict:
    obj = mp.load_asset("block")
    grasp = GraspConfig(close_timeout_s=0.6, hold_s=0.1, lift_height_mm=30)
    s = dataclasses.replace(base, gripper=mp.GripperSpec(), grasp=grasp)
    space = mp.calibrate.param_space(["pad_stiffness_n_per_mm"], s, obj.mass_kg)
    traces = {}
    for label, k in (("stiffest_stable", space.hi[0]), ("third", space.hi[0] / 3)):
        hid = dataclasses.replace(s, contact=mp.ContactParams(pad_stiffness_n_per_mm=float(k)))
        o = synthetic_outcomes(obj, hid, [0.0], [0.0], [0.0], [20.0], traces=True)
        traces[label] = o.force_traces[0][:, 1]
    diff = np.abs(traces["stiffest_stable"] - traces["third"])
    return {
        "object": "block (43 g)",
        "grip_force_n": 20.0,
        "stiffness_n_per_mm": [float(space.hi[0]), float(space.hi[0] / 3)],
        "max_force_difference_n": float(diff.max()),
        "rms_force_difference_n": float(np.sqrt(np.mean(diff**2))),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--rows", type=int, default=16, help="training rows per yaw (x2)")
    ap.add_argument("--estimators", default="smoothed,jvp")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-gradients", action="store_true")
    ap.add_argument("--out", default="benchmarks/out/calibration.json")
    args = ap.parse_args()
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    obj, base, hidden, train, held = setup(args.rows, args.seed)
    report = {
        "date": time.strftime("%Y-%m-%d"),
        "commit": commit,
        "hidden_pad_friction": HIDDEN_MU,
        "train_rows": len(train),
        "held_out_rows": len(held),
        "train_successes": int(train.successes.sum()),
    }
    if not args.skip_gradients:
        report["gradient_quality"] = gradient_quality(obj, base, train)
        print(json.dumps(report["gradient_quality"], indent=1), flush=True)
    report["stiffness"] = stiffness_sensitivity(base)
    print(report["stiffness"], flush=True)
    report["fits"] = {}
    for est in args.estimators.split(","):
        problem = Problem(
            obj, train, ["pad_friction"], base, backend="mjx" if est == "jvp" else "mujoco"
        )
        holdout = Problem(obj, held, ["pad_friction"], base, backend="mujoco")
        t0 = time.perf_counter()
        res = calibrate(problem, steps=args.steps, estimator=est, holdout=holdout)
        wall = time.perf_counter() - t0
        mu = res.values["pad_friction"]
        final = float(problem.loss(problem.space.theta([mu])[None])[0])
        report["fits"][est] = {
            "fitted_pad_friction": mu,
            "relative_error": abs(mu - HIDDEN_MU) / HIDDEN_MU,
            "final_loss": final,
            "initial_loss": res.history[0]["loss"],
            "held_out_before": res.accuracy_before,
            "held_out_after": res.accuracy_after,
            "rollouts": problem.rollouts,
            "wall_s": wall,
            "losses": [h["loss"] for h in res.history],
            "values": [h["values"]["pad_friction"] for h in res.history],
        }
        print(
            est,
            {k: v for k, v in report["fits"][est].items() if k not in ("losses", "values")},
            flush=True,
        )
    best = min(f["final_loss"] for f in report["fits"].values())
    problem = Problem(obj, train, ["pad_friction"], base, backend="mujoco")
    base_res = random_search(problem, evaluations=400, batch=16, seed=args.seed, target=best)
    report["random_search"] = {k: base_res[k] for k in ("values", "loss", "rollouts", "wall_s")}
    report["random_search"]["reached_target"] = base_res["loss"] <= best
    print("random search", report["random_search"], flush=True)
    from pathlib import Path

    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=1, default=float))


if __name__ == "__main__":
    main()
