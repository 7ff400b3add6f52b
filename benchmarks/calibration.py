"""Benchmark: calibration estimators against baselines at equal budgets.

Synthetic ground truth on a 1 kg 40 x 20 x 20 mm block (a light gripper, 1 N minimum):
outcomes, lift times and traces (pad force, object lift and rotation, with Gaussian
noise added) simulated with hidden parameters, then fitted from the paper's defaults
by every estimator with the same budget of pick-point simulations:

* 1 hidden parameter: pad friction;
* 3: + the gripper's force offset and table friction;
* 5: + pad torsional friction and pad stiffness.

With ``--gradients``, also forward-mode derivatives through MJX against finite
differences (MJX compiles for minutes on a CPU).

The trace residual: ``--replicates`` K simulations per traced row and a
``--trace-window-s`` moving average (docs/calibration.md; ``--replicates 1
--trace-window-s 0`` is the former per-sample RMS). The budget counts simulations, so
K = 3 leaves a third as many parameter vectors.

Estimators: ``smoothed`` (Gauss-Hermite smoothed gradient + Adam),
``random`` (uniform search), ``cma`` (CMA-ES, the ``cma`` package; the default), ``lsq``
(Levenberg-Marquardt on the residuals, ``mujoco.sysid``). Per fit: the best loss
against simulations and wall time; simulations and wall time to reach the target loss
(90 % of the way from the start's loss to the hidden parameters' loss); each
parameter's relative error, interval and identifiability; held-out accuracy before and
after. Rows go to a JSON file; ``--table`` prints the estimators' table from it.

  JAX_PLATFORMS=cpu python benchmarks/calibration.py \
      --out benchmarks/results/calibration_estimators.json
  python benchmarks/calibration.py --table benchmarks/results/calibration_estimators.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import time
from pathlib import Path

import numpy as np
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.studies import calibration as cal

HIDDEN = {
    "pad_friction": 0.62,
    "force_offset_n": 1.5,
    "table_friction": 0.3,
    "pad_torsion_mm": 1.5,
    "pad_stiffness_n_per_mm": 60.0,
}
SETS = {1: list(HIDDEN)[:1], 3: list(HIDDEN)[:3], 5: list(HIDDEN)}
NOISE = {"force_n": 0.3, "lift_mm": 0.5, "rotation_deg": 1.0}
ESTIMATORS = ("smoothed", "random", "cma", "lsq")


def setup(rows: int, seed: int, names: list[str], backend: str = "mujoco"):
    """Training and held-out outcomes simulated with names hidden at HIDDEN and every
    other parameter at its default (what the fit starts from): exactly P unknowns."""
    obj = mp.object_from_polygon(box(-20, -10, 20, 10), thickness_mm=20, mass_g=1000, name="heavy")
    gripper = mp.GripperSpec(name="light-gripper", force_min_n=1.0)
    grasp = GraspConfig(close_timeout_s=0.6, lift_height_mm=30.0, hold_s=0.1)
    base = mp.Settings(gripper=gripper, grasp=grasp)
    contact = {k: HIDDEN[k] for k in names if k != "force_offset_n"}
    hidden = mp.Settings(gripper, mp.ContactParams(**contact), grasp=grasp)
    offset = HIDDEN["force_offset_n"] if "force_offset_n" in names else 0.0
    rng = np.random.default_rng(seed)

    def draw(n, lo, hi):
        # off-centre along the pads (y) so that the pad's torsion matters
        f = np.linspace(lo, hi, n)
        return rng.uniform(-3, 3, n), rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), f

    kw = dict(
        traces=True,
        lift_times=True,
        force_offset_n=offset,
        trace_noise=NOISE,
        backend=backend,
    )
    train = cal.synthetic_outcomes(obj, hidden, *draw(rows, 5.0, 14.0), seed=seed, **kw)
    held = cal.synthetic_outcomes(
        obj, hidden, *draw(rows, 5.5, 13.5), force_offset_n=offset, backend=backend
    )
    return obj, base, train, held


def fit(
    obj,
    base,
    train,
    held,
    names,
    estimator,
    budget,
    seed,
    replicates=3,
    window_s=0.05,
    backend="mujoco",
):
    noise = cal.Noise(trace_window_s=window_s)
    problem = cal.Problem(
        obj, train, names, base, backend=backend, replicates=replicates, noise=noise
    )
    holdout = cal.Problem(obj, held, names, base, backend=backend)
    truth = problem.space.theta([HIDDEN[n] for n in names])
    # a bounded parameter can be clipped by theta(): the truth's own loss, on its theta
    l_true = float(problem.loss(truth[None])[0])
    l_start = float(problem.loss(problem.start_theta()[None])[0])
    target = l_true + 0.1 * (l_start - l_true)
    spent0 = problem.rollouts
    t0 = time.perf_counter()
    rows = len(problem.row_of)  # simulations per parameter vector (replicas included)
    before = holdout.accuracy(problem.start_theta())["correct"]
    if estimator == "lsq":
        res = cal.least_squares(problem, max_iters=10_000, budget=budget, holdout=holdout)
    else:
        per_step = {
            "smoothed": 1 + 2 * 2 * len(names),
            "random": 16,
            "cma": max(8, 4 + int(3 * np.log(len(names)))),
        }[estimator]
        steps = max(1, budget // (per_step * rows))
        res = cal.calibrate(
            problem, estimator=estimator, steps=steps, budget=budget, seed=seed, holdout=holdout
        )
    wall = time.perf_counter() - t0
    reached = next((h for h in res.history if h["best_loss"] <= target), None)
    ident = res.identifiability or {}
    return {
        "estimator": estimator,
        "hidden_parameters": len(names),
        "names": names,
        "budget": budget,
        "rows": len(train),
        "simulations_per_vector": rows,
        "loss_start": l_start,
        "loss_hidden": l_true,
        "target": target,
        "best_loss": min(h["best_loss"] for h in res.history),
        "final_loss": float(
            problem.loss(problem.space.theta([res.optimum[n] for n in names])[None])[0]
        ),
        "rollouts_to_target": reached["rollouts"] if reached else None,
        "wall_s_to_target": reached["wall_s"] if reached else None,
        "rollouts": problem.rollouts - spent0,
        "wall_s": wall,
        "optimum": res.optimum,
        "relative_error": {n: abs(res.optimum[n] - HIDDEN[n]) / abs(HIDDEN[n]) for n in names},
        "interval": {n: ident.get(n, {}).get("interval") for n in names},
        "identified": {n: ident.get(n, {}).get("identified") for n in names},
        "identification": {n: _verdicts(ident.get(n)) for n in names},
        "identify_rollouts": ident.get("rollouts"),
        "profile_rollouts": ident.get("profile_rollouts"),
        "identify_wall_s": ident.get("wall_s"),
        "held_out_before": before,
        "held_out_after": res.accuracy_after["correct"] if res.accuracy_after else None,
        "held_out_rows": len(held),
        "curve": [(h["rollouts"], h["best_loss"], h["wall_s"]) for h in res.history],
    }


def _verdicts(info: dict | None) -> dict | None:
    """One parameter's verdict and interval by each stage of identify.py: the slice
    (local tests + slice), + the empirical profile (the fit's own vectors), + the refit
    profile (the final one); the profile points kept."""
    if not info:
        return None
    prof = info.get("profile") or {}
    emp, refit = prof.get("empirical"), prof.get("refit")
    res = {
        "slice": {"identified": info["slice_identified"], "interval": info["slice_interval"]},
        "empirical": {
            "identified": info["slice_identified"] and (emp is None or emp["passed"]),
            "interval": emp["interval"] if emp else info["slice_interval"],
        },
        "refit": {"identified": info["identified"], "interval": info["interval"]},
    }
    if refit:
        res["refit"].update(
            open=refit["open"],
            narrow_after_widening=bool(refit["passed"] or refit["open"]),
            points=[
                {k: q[k] for k in ("scale", "value", "nll_rise", "others", "kept")}
                for q in refit["points"]
            ],
        )
    if emp:
        res["empirical"].update(vectors=emp["vectors"], kept=emp["kept"])
    return res


def identify_counts(fits: list[dict]) -> dict:
    """Per stage: parameters called identified, and how many of their intervals hold
    the hidden value (fits run with the profile check)."""
    counts = {}
    for stage in ("slice", "empirical", "refit"):
        called = inside = 0
        for f in fits:
            for n, v in (f.get("identification") or {}).items():
                if v and v[stage]["identified"]:
                    called += 1
                    lo, hi = v[stage]["interval"]
                    inside += lo <= HIDDEN[n] <= hi
        counts[stage] = {"identified": called, "hidden_inside": inside}
    return counts


def differentiable(settings: mp.Settings) -> mp.Settings:
    """settings at the physics MJX-JAX runs (the differentiable physics; it refuses others)."""
    return dataclasses.replace(
        settings,
        contact=mp.ContactParams.differentiable(settings.contact),
        solver=mp.SolverParams.differentiable(settings.solver),
    )


def gradient_quality(obj, base, train) -> dict:
    """Forward-mode derivatives through MJX (estimator 'jvp') against central finite
    differences of the same jitted loss, two step sizes, three parameters."""
    names = ["pad_friction", "table_friction", "pad_stiffness_n_per_mm"]
    sub = train.take(np.arange(0, len(train), 3))
    problem = cal.Problem(obj, sub, names, differentiable(base), backend="mjx")
    theta = problem.space.theta([0.62, 0.2, problem.space.hi[2] / 2])
    t0 = time.perf_counter()
    loss, grad = problem.mjx_loss_and_grad(theta)
    out = {
        "names": names,
        "rows": len(sub),
        "loss": loss,
        "jvp": grad.tolist(),
        "jvp_first_call_s": time.perf_counter() - t0,
        "fd": {},
    }
    f = problem._jvp
    for h in (0.03, 0.1):
        fd = []
        for i in range(len(names)):
            e = np.zeros(len(names), np.float32)
            e[i] = h
            fd.append((float(f(theta + e)[0]) - float(f(theta - e)[0])) / (2 * h))
        rel = [abs(a - b) / max(abs(b), 1e-9) for a, b in zip(grad, fd, strict=True)]
        out["fd"][str(h)] = {"grad": fd, "relative_error": rel}
    return out


def gradient_check_tiny() -> dict:
    """Forward-mode derivatives through MJX against central finite differences on a
    tiny problem: the 1 kg block, two rows (F_d 14 N holds, 6 N slips), the short test
    procedure, theta = (pad friction, force offset) at (0.86, 0). Quantities per row:
    the mean pad force over the last 10 control ticks (N) and the final lift (mm); and
    the calibration loss of the two rows with a force trace (one simulation per row)."""
    import jax
    import jax.numpy as jnp

    from mjx_pick.engine.simulator import differentiable_rollout
    from mjx_pick.kernels.grasp import TRACE_FIELDS
    from mjx_pick.studies.calibration.parameters import contact_arrays_jnp

    obj = mp.object_from_polygon(box(-20, -10, 20, 10), thickness_mm=20, mass_g=1000, name="heavy")
    gripper = mp.GripperSpec(name="light-gripper", force_min_n=1.0)
    grasp = GraspConfig(close_timeout_s=0.4, lift_height_mm=20.0, hold_s=0.05)
    base = differentiable(mp.Settings(gripper=gripper, grasp=grasp))
    names = ["pad_friction", "force_offset_n"]
    data = cal.synthetic_outcomes(
        obj, base, [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [14.0, 6.0], traces=("force_n",)
    )
    problem = cal.Problem(obj, data, names, base, backend="mjx", replicates=1)
    theta = problem.space.theta([0.86, 0.0])
    roll = differentiable_rollout(problem.scene, grasp, True)
    inp = problem.inputs
    fl, fr_ = TRACE_FIELDS.index("force_left_n"), TRACE_FIELDS.index("force_right_n")

    def quantities(th):
        values = problem.space.values(th)
        fr, ref, force = contact_arrays_jnp(names, values, inp, problem.scene, base, obj.mass_kg)
        params = inp.params._replace(grip_force_n=force)
        out, rows = roll(inp.qpos0, params, fr, ref, inp.pair_solimp)
        hold = 0.5 * (rows[:, -10:, fl] + rows[:, -10:, fr_]).mean(axis=-1)
        return jnp.concatenate([hold, out["lift_height_mm"]])  # (4,)

    f = jax.jit(quantities)
    jac_f = jax.jit(jax.jacfwd(quantities))
    t0 = time.perf_counter()
    value = np.asarray(f(jnp.asarray(theta)))
    t_value = time.perf_counter() - t0
    t0 = time.perf_counter()
    jac = np.asarray(jac_f(jnp.asarray(theta)))  # (4, 2)
    t_jac = time.perf_counter() - t0
    labels = ["hold force 14 N row", "hold force 6 N row", "lift 14 N row", "lift 6 N row"]
    res = {
        "names": names,
        "quantities": labels,
        "value": value.tolist(),
        "jvp": jac.tolist(),
        "first_call_s": {"value": t_value, "jacfwd": t_jac},
        "fd": {},
    }
    for h in (0.1, 0.03, 0.01):
        cols = []
        for i in range(len(names)):
            e = np.zeros(len(names), np.float32)
            e[i] = h
            hi = np.asarray(f(jnp.asarray(theta + e)))
            lo = np.asarray(f(jnp.asarray(theta - e)))
            cols.append((hi - lo) / (2 * h))
        res["fd"][str(h)] = np.stack(cols, axis=1).tolist()  # (4, 2)
    t0 = time.perf_counter()
    loss, grad = problem.mjx_loss_and_grad(theta)
    res["loss"] = {"value": loss, "jvp": grad.tolist(), "first_call_s": time.perf_counter() - t0}
    res["loss"]["fd"] = {}
    for h in (0.1, 0.03, 0.01):
        g = []
        for i in range(len(names)):
            e = np.zeros(len(names), np.float32)
            e[i] = h
            g.append(
                (problem.mjx_loss_and_grad(theta + e)[0] - problem.mjx_loss_and_grad(theta - e)[0])
                / (2 * h)
            )
        res["loss"]["fd"][str(h)] = g
    # d theta / d value, to read the derivatives per unit of each parameter
    res["dvalue_dtheta"] = (
        np.asarray(jax.jacfwd(problem.space.values)(jnp.asarray(theta))).diagonal().tolist()
    )
    return res


def to_target(fits: list[dict]) -> None:
    """Per fit, simulations and wall time until its best loss came within 10 % of the
    way from the start's loss to the best loss ANY estimator found on that problem
    (the hidden parameters' own loss is no reachable target: benchmarks/results/history.md)."""
    for p in sorted({f["hidden_parameters"] for f in fits}):
        group = [f for f in fits if f["hidden_parameters"] == p]
        best = min(f["best_loss"] for f in group)
        target = best + 0.1 * (group[0]["loss_start"] - best)
        for f in group:
            hit = next((c for c in f["curve"] if c[1] <= target), None)
            f["common_target"] = target
            f["sims_to_common_target"] = hit[0] if hit else None
            f["wall_s_to_common_target"] = hit[2] if hit else None


def table(path: str) -> None:
    report = json.loads(Path(path).read_text())
    to_target(report["fits"])
    print(
        "| P | estimator | sims (wall s) to the common target | best loss (start; at hidden) "
        "| relative error per parameter (n.i.: not identified) | held-out before -> after |"
    )
    print("|---|---|---|---|---|---|")
    for r in report["fits"]:
        to = (
            f"{r['sims_to_common_target']} ({r['wall_s_to_common_target']:.0f} s)"
            if r["sims_to_common_target"] is not None
            else f"not in {r['rollouts']} ({r['wall_s']:.0f} s)"
        )
        err = ", ".join(
            f"{SHORT[n]} {100 * r['relative_error'][n]:.1f} %"
            f"{'' if r['identified'][n] else ' (n.i.)'}"
            for n in r["names"]
        )
        held = f"{r['held_out_before']} -> {r['held_out_after']} / {r['held_out_rows']}"
        print(
            f"| {r['hidden_parameters']} | {r['estimator']} | {to} | {r['best_loss']:.2f} "
            f"({r['loss_start']:.1f}; {r['loss_hidden']:.2f}) | {err} | {held} |"
        )


def reidentify(path: str, out: str, backend: str = "mujoco") -> None:
    """Identifiability (local tests, the global slice and the refit profile,
    ``identify.py``) at every fit's optimum in a results JSON, on the same problems:
    which parameters each test passes and whether the hidden value lies in the reported
    intervals (no fit here: no empirical profile)."""
    report = json.loads(Path(path).read_text())
    k, window = report.get("replicates", 1), report.get("trace_window_s", 0.0)
    rows, cache = [], {}
    for f in report["fits"]:
        names, p = f["names"], f["hidden_parameters"]
        if p not in cache:
            obj, base, train, _ = setup(report["rows"], report.get("seed", 0), names, backend)
            noise = cal.Noise(trace_window_s=window)
            cache[p] = cal.Problem(
                obj, train, names, base, backend=backend, replicates=k, noise=noise
            )
        problem = cache[p]
        theta = problem.space.theta([f["optimum"][n] for n in names])
        t0 = time.perf_counter()
        ident = cal.identifiability(problem, theta)
        row = {"estimator": f["estimator"], "hidden_parameters": p, "params": {}}
        for n in names:
            i = ident[n]
            lo, hi = i["interval"]
            glo, ghi = i["global"]["interval"]
            llo, lhi = i["local_interval"]
            row["params"][n] = {
                "local": i["local"],
                "global": i["global"]["passed"],
                "identified": i["identified"],
                "local_interval": [llo, lhi],
                "interval": [lo, hi],
                "global_interval": [glo, ghi],
                "hidden_in_local_interval": llo <= HIDDEN[n] <= lhi,
                "hidden_in_interval": lo <= HIDDEN[n] <= hi,
                "hidden_in_global": glo <= HIDDEN[n] <= ghi,
            }
        # no fit here, so no empirical profile: the slice against slice + refit
        row["identification"] = {n: _verdicts(ident[n]) for n in names}
        row["profile_rollouts"] = ident["profile_rollouts"]
        row["wall_s"] = time.perf_counter() - t0
        rows.append(row)
        print(json.dumps(row), flush=True)
        Path(out).write_text(json.dumps({"source": path, "fits": rows}, indent=1))
    for test, iv in (("local", "hidden_in_local_interval"), ("identified", "hidden_in_interval")):
        flagged = [q for r in rows for q in r["params"].values() if q[test]]
        inside = sum(q[iv] for q in flagged)
        print(f"{test}: {len(flagged)} parameters pass; hidden value inside the interval: {inside}")
    print(json.dumps(identify_counts(rows)))


SHORT = {
    "pad_friction": "mu_pad",
    "force_offset_n": "offset",
    "table_friction": "mu_table",
    "pad_torsion_mm": "torsion",
    "pad_stiffness_n_per_mm": "k_pad",
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=16, help="training rows (held-out: as many)")
    ap.add_argument(
        "--budget",
        type=int,
        default=150,
        help="parameter vectors per fit for 1 parameter; +60 per extra parameter; "
        "times the rows = the simulations",
    )
    ap.add_argument("--params", default="1,3,5")
    ap.add_argument("--estimators", default=",".join(ESTIMATORS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--replicates",
        type=int,
        default=3,
        help="simulations per traced row (the trace residual's replicas; 1: the former "
        "per-sample RMS)",
    )
    ap.add_argument(
        "--trace-window-s",
        type=float,
        default=0.05,
        help="moving average of the traces before they are compared (0: tick by tick)",
    )
    ap.add_argument(
        "--backend",
        default="mujoco",
        choices=("mujoco", "warp", "mjx"),
        help="the engine of the ground truth and of every fit (warp: a GPU)",
    )
    ap.add_argument("--out", default="benchmarks/out/calibration_estimators.json")
    ap.add_argument("--table", help="print the estimators' table of this JSON and stop")
    ap.add_argument(
        "--gradients-tiny",
        action="store_true",
        help="only: forward-mode (MJX) derivatives against finite differences on a tiny "
        "problem (two rows, short procedure), into --out",
    )
    ap.add_argument(
        "--reidentify",
        help="identifiability (local and global) at every optimum of this JSON, into --out",
    )
    ap.add_argument(
        "--gradients",
        action="store_true",
        help="also: forward-mode (MJX) gradients against finite differences",
    )
    args = ap.parse_args()
    if args.table:
        table(args.table)
        return
    if args.gradients_tiny:
        res = gradient_check_tiny()
        print(json.dumps(res, indent=1))
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(res, indent=1))
        return
    if args.reidentify:
        reidentify(args.reidentify, args.out, args.backend)
        return
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    report = {
        "date": time.strftime("%Y-%m-%d"),
        "commit": commit,
        "backend": args.backend,
        "hidden": HIDDEN,
        "trace_noise": NOISE,
        "rows": args.rows,
        "seed": args.seed,
        "replicates": args.replicates,
        "trace_window_s": args.trace_window_s,
        "fits": [],
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.gradients:
        obj, base, train, _ = setup(args.rows, args.seed, SETS[1], args.backend)
        report["gradient_quality"] = gradient_quality(obj, base, train)
        print(json.dumps(report["gradient_quality"]), flush=True)
    for p in (int(x) for x in args.params.split(",")):
        obj, base, train, held = setup(args.rows, args.seed, SETS[p], args.backend)
        budget = (args.budget + 60 * (p - 1)) * len(train)
        report[f"train_successes_{p}"] = int(train.successes.sum())
        for est in args.estimators.split(","):
            row = fit(
                obj,
                base,
                train,
                held,
                SETS[p],
                est,
                budget,
                args.seed,
                args.replicates,
                args.trace_window_s,
                args.backend,
            )
            report["fits"].append(row)
            print(
                json.dumps({k: v for k, v in row.items() if k != "curve"}, default=float),
                flush=True,
            )
            report["identify_counts"] = identify_counts(report["fits"])
            out.write_text(json.dumps(report, indent=1, default=float))
    print(json.dumps(report["identify_counts"]), flush=True)


if __name__ == "__main__":
    main()
