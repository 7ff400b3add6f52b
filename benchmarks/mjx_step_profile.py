"""Where MJX-JAX's time goes: one control period of door-opener picks in contact, by
solver setting, with the solver's parts and its forward-mode derivatives.

N picks (``generate_normal``, seed 0) are run at the differentiable physics to control
tick T (closing and lifting: every pad in contact); from those states, for each setting
(``--settings``: names of SETTINGS):

* ``period_ms``: CPU milliseconds of one control period (5 physics steps) of all N
  picks, vmapped and jitted (this process's CPU time, best of 3: robust to other work
  on a shared machine, summed over XLA's threads);
* ``linesearch_ms``, ``constraint_ms``, ``gradient_ms``: one Newton iteration's parts
  (MJX's ``_linesearch``, ``_update_constraint``, ``_update_gradient``: the gradient
  and, with elliptic cones, the cone Hessian), each over the N states;
* ``iterations``: the solver's iterations at the first step (median, max over picks);
* ``jvp_finite``: picks whose ``jax.jvp`` of the state after ``--jvp-periods`` control
  periods with respect to the pads' friction is finite.

Settings marked ``+rewrites`` swap two of MJX's solver pieces for versions with the same
arithmetic that cost less under ``vmap`` (this script's own, not the package's): the
cone Hessian assembled per contact block (MJX builds it as a dense nefc x nefc matrix
and adds every contact's block into it) and the line search as a ``while_loop`` (MJX
runs it as a ``scan`` of ``ls_iterations`` conditional steps, which vmap turns into
every iteration for every world); ``+safe_sqrt`` also makes the line search's
tangential-force square root zero-safe (its derivative at 0 is infinite).

    python benchmarks/mjx_step_profile.py --out benchmarks/results/mjx_step_profile_cpu.json

Figures: benchmarks/RESULTS.md, "mjx_physics.py".
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx
from mujoco.mjx._src import forward, support
from mujoco.mjx._src import solver as S
from mujoco.mjx._src.types import ConeType, SolverType

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.engine import mjx_backend as mb
from mjx_pick.engine.inputs import addresses, make_inputs
from mjx_pick.kernels import grasp as gk

DEFAULT = {}
PYRAMID = {"cone": "pyramidal", "impratio": 1.0}
SETTINGS = {
    "default": DEFAULT,
    "default+rewrites": {**DEFAULT, "+rewrites": True},
    "default+rewrites+safe_sqrt": {**DEFAULT, "+rewrites": True, "+safe_sqrt": True},
    "default_ls8": {"ls_iterations": 8},
    "pyramidal_imp1": PYRAMID,
    "pyramidal_imp1+rewrites": {**PYRAMID, "+rewrites": True},
    "pyramidal_imp1_ls8": {**PYRAMID, "ls_iterations": 8},
    "differentiable": dict(mp.SolverParams.differentiable().__dict__),
}
ORIGINAL = {
    "_while_loop_scan": S._while_loop_scan,
    "_update_gradient": S._update_gradient,
    "create": S._LSPoint.create,
}


def _ls_while(cond, body, init, max_iter):
    """The line search as a while_loop: a batch stops once its last world has."""
    return jax.lax.while_loop(cond, body, init)


def _update_gradient(m, d, ctx):
    """MJX's _update_gradient with the elliptic cone Hessian J' C J summed per contact
    block (k contacts of condim c: J_k' H_k J_k) instead of a dense nefc x nefc C."""
    if not (m.opt.solver == SolverType.NEWTON and m.opt.cone == ConeType.ELLIPTIC):
        return ORIGINAL["_update_gradient"](m, d, ctx)
    grad = ctx.Ma - d.qfrc_smooth - ctx.qfrc_constraint
    jac = d._impl.efc_J
    h = (jac.T * (d._impl.efc_D * ctx.active)) @ jac
    cones = np.asarray(d._impl.contact.dim) > 1
    address = np.asarray(d._impl.contact.efc_address)[cones]
    dim = np.asarray(d._impl.contact.dim)[cones]
    for c in np.unique(dim):
        sel = np.nonzero(dim == c)[0]
        rows = jac[address[sel][:, None] + np.arange(c)]  # (k, c, nv)
        h = h + jnp.einsum("kin,kij,kjm->nm", rows, ctx.h[sel, :c, :c], rows)
    h = support.full_m(m, d) + h
    factor = jax.scipy.linalg.cho_factor((h + h.T) * 0.5)
    return ctx.replace(grad=grad, Mgrad=jax.scipy.linalg.cho_solve(factor, grad))


def _safe_sqrt_point(cls, m, d, ctx, alpha, jv, quad, quad_gauss, uu, v0, uv, vv):
    """MJX's _LSPoint.create with a zero-safe square root of the tangential force."""
    if m.opt.cone != ConeType.ELLIPTIC:
        return ORIGINAL["create"](m, d, ctx, alpha, jv, quad, quad_gauss, uu, v0, uv, vv)
    # the same point, its tangential-force norm through a square root whose derivative
    # is 0, not infinite, where the norm is 0: MJX's own code with jnp.sqrt replaced
    # (tsqr > 0 rows are unchanged, so is the value everywhere)
    real_sqrt = jnp.sqrt

    def safe(x):
        pos = x > 0
        return jnp.where(pos, real_sqrt(jnp.where(pos, x, 1.0)), 0.0)

    S.jp.sqrt = safe
    try:
        return ORIGINAL["create"](m, d, ctx, alpha, jv, quad, quad_gauss, uu, v0, uv, vv)
    finally:
        S.jp.sqrt = real_sqrt


def use(rewrites: bool, safe_sqrt: bool) -> None:
    S._while_loop_scan = _ls_while if rewrites else ORIGINAL["_while_loop_scan"]
    S._update_gradient = _update_gradient if rewrites else ORIGINAL["_update_gradient"]
    S._LSPoint.create = classmethod(_safe_sqrt_point) if safe_sqrt else ORIGINAL["create"]


def solver_iterations(m, d):
    """MJX's solve loop, returning its iteration count (solver.solve discards it)."""

    def cond(ctx):
        improvement = S._rescale(m, d, ctx.prev_cost - ctx.cost)
        gradient = S._rescale(m, d, S.math.norm(ctx.grad))
        done = ctx.solver_niter >= m.opt.iterations
        return ~(done | (improvement < m.opt.tolerance) | (gradient < m.opt.tolerance))

    def body(ctx):
        ctx = S._linesearch(m, d, ctx)
        ctx = S._update_gradient(m, d, S._update_constraint(m, d, ctx))
        return ctx.replace(search=-ctx.Mgrad, solver_niter=ctx.solver_niter + 1)

    warm = S.Context.create(m, d.replace(qacc=d.qacc_warmstart), grad=False)
    smooth = S.Context.create(m, d.replace(qacc=d.qacc_smooth), grad=False)
    qacc = jnp.where(warm.cost < smooth.cost, d.qacc_warmstart, d.qacc_smooth)
    return jax.lax.while_loop(cond, body, S.Context.create(m, d.replace(qacc=qacc))).solver_niter


def cpu_ms(fn, *args, reps: int = 3) -> float:
    """Best-of-reps CPU milliseconds of fn(*args) (compiled before)."""
    jax.block_until_ready(fn(*args))
    best = np.inf
    for _ in range(reps):
        t0 = time.process_time()
        jax.block_until_ready(fn(*args))
        best = min(best, time.process_time() - t0)
    return 1e3 * best


def states_at(obj, gripper, grasp, picks, tick: int):
    """(qpos, qvel, ctrl) of each pick at control tick `tick` of the default procedure,
    run at the differentiable physics, and the count of picks in each phase."""
    contact, solver = mp.ContactParams.differentiable(), mp.SolverParams.differentiable()
    scene = mp.build_scene(obj, gripper, contact, solver, grasp)
    inputs = make_inputs(scene, grasp, picks)
    phys, ad = mb.jax_physics(scene), addresses(scene)
    n_sub, o = grasp.substeps(scene.solver), ad.object_qpos

    def one(qpos0, params, fr, ref, imp):
        m, d, s, a, diag = mb._initial(phys, ad, qpos0, params, fr, ref, imp, {})
        pos0, quat0 = qpos0[o : o + 3], qpos0[o + 3 : o + 7]

        def period(carry, _):
            d, s, a, g = carry
            s, a, ctrl, _ = gk.tick(params, ad, s, a, d.qpos, d.qvel, d._impl.cfrc_ext, pos0, quat0)
            d, g = mb._physics_steps(phys, m, d.replace(ctrl=ctrl), g, n_sub)
            return (d, s, a, g), None

        (d, s, _, _), _ = jax.lax.scan(period, (d, s, a, diag), None, length=tick)
        return d.qpos, d.qvel, d.ctrl, s.phase

    args = (
        inputs.qpos0,
        inputs.params,
        inputs.pair_friction,
        inputs.pair_solref,
        inputs.pair_solimp,
    )
    with jax.default_matmul_precision("highest"):
        qpos, qvel, ctrl, phase = jax.jit(jax.vmap(one))(*jax.tree.map(jnp.asarray, args))
    phases = np.bincount(np.asarray(phase), minlength=len(gk.PHASES)).tolist()
    return (qpos, qvel, ctrl), dict(zip(gk.PHASES, phases, strict=True))


def profile(name, fields, obj, gripper, grasp, picks, state, jvp_periods: int) -> dict:
    rewrites, safe_sqrt = fields.get("+rewrites", False), fields.get("+safe_sqrt", False)
    use(rewrites, safe_sqrt)
    solver = mp.SolverParams(**{k: v for k, v in fields.items() if not k.startswith("+")})
    # the settings' own model with the pads' margin left out (jax_model: MJX's collider
    # has none), whatever the backend would accept
    scene = mp.build_scene(obj, gripper, mp.ContactParams.differentiable(), solver, grasp)
    mx = mb.jax_model(scene.model)
    d0 = mjx.make_data(mx)
    inputs = make_inputs(scene, grasp, picks)
    pairs = tuple(
        jnp.asarray(x) for x in (inputs.pair_friction, inputs.pair_solref, inputs.pair_solimp)
    )
    pad = np.zeros(inputs.pair_friction.shape[1:], np.float32)
    pad[list(scene.index.pad_pairs), :2] = 1.0

    def model_data(fr, ref, imp, qpos, qvel, ctrl):
        m = mx.replace(pair_friction=fr, pair_solref=ref, pair_solimp=imp)
        return m, d0.replace(qpos=qpos, qvel=qvel, ctrl=ctrl)

    def period(fr, ref, imp, qpos, qvel, ctrl, mu=0.0, steps=5):
        m, d = model_data(fr + mu * pad, ref, imp, qpos, qvel, ctrl)
        d, _ = jax.lax.scan(lambda d, _: (mjx.step(m, d), None), d, None, length=steps)
        return d.qpos

    def before_solve(*a):
        m, d = model_data(*a)
        for stage in (forward.fwd_position, forward.fwd_velocity, forward.fwd_actuation):
            d = stage(m, d)
        return m, forward.fwd_acceleration(m, d)

    def context(*a):
        m, d = before_solve(*a)
        return m, d, S.Context.create(m, d)

    parts = {
        "context": lambda *a: context(*a)[2].cost,
        "linesearch": lambda *a: S._linesearch(*context(*a)).qacc,
        "constraint": lambda *a: S._update_constraint(*context(*a)).cost,
        "gradient": lambda *a: S._update_gradient(*context(*a)).Mgrad,
    }
    args = pairs + tuple(state)
    row = {"setting": name, "fields": fields, "n": len(picks), "nefc": None}
    t0 = time.perf_counter()
    with jax.default_matmul_precision("highest"):
        row["period_ms"] = round(cpu_ms(jax.jit(jax.vmap(period)), *args), 1)
        row["period_compile_wall_s"] = round(time.perf_counter() - t0, 1)
        base = cpu_ms(jax.jit(jax.vmap(parts["context"])), *args)
        for part in ("linesearch", "constraint", "gradient"):
            extra = cpu_ms(jax.jit(jax.vmap(parts[part])), *args) - base
            row[f"{part}_ms"] = round(max(extra, 0.0), 1)
        its = np.asarray(jax.jit(jax.vmap(lambda *a: solver_iterations(*before_solve(*a))))(*args))
        row["iterations"] = [int(np.median(its)), int(its.max())]
        row["nefc"] = int(jax.eval_shape(jax.vmap(before_solve), *args)[1]._impl.efc_J.shape[-2])
        if jvp_periods:

            def moved(mu):
                run = lambda *a: period(*a, mu=mu, steps=5 * jvp_periods)  # noqa: E731
                return jax.vmap(run)(*args)

            fn = jax.jit(lambda mu: jax.jvp(moved, (mu,), (jnp.float32(1.0),))[1])
            tangent = np.asarray(fn(jnp.float32(0.0)))
            row["jvp_periods"] = jvp_periods
            row["jvp_finite"] = int(np.isfinite(tangent).all(axis=-1).sum())
            row["jvp_max_abs"] = float(np.nanmax(np.abs(tangent)))
    use(False, False)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--n", type=int, default=16, help="picks (worlds of the vmapped programs)")
    ap.add_argument("--tick", type=int, default=100, help="control tick of the profiled states")
    ap.add_argument("--settings", default=",".join(SETTINGS), help="names of SETTINGS")
    ap.add_argument("--jvp-periods", type=int, default=40, help="0: no derivatives")
    ap.add_argument("--out", default="benchmarks/out/mjx_step_profile.json")
    args = ap.parse_args()
    obj, gripper, grasp = (
        mp.load_asset(args.object),
        mp.load_gripper(args.gripper),
        mp.GraspConfig(),
    )
    picks = pp.generate_normal(obj, gripper, args.n, seed=0)
    state, phases = states_at(obj, gripper, grasp, picks, args.tick)
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    report = {"args": vars(args), "commit": commit, "date": time.strftime("%Y-%m-%d"),
              "cpus": os.cpu_count(), "phases_at_tick": phases, "rows": []}  # fmt: skip
    for name in args.settings.split(","):
        row = profile(name, SETTINGS[name], obj, gripper, grasp, picks, state, args.jvp_periods)
        row["load_avg"] = round(os.getloadavg()[0], 1)
        report["rows"].append(row)
        print(json.dumps(row), flush=True)
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".tmp").write_text(json.dumps(report, indent=1))
        out.with_suffix(".tmp").replace(out)


if __name__ == "__main__":
    main()
