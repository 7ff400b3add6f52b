"""Where a MuJoCo Warp physics step spends its time: kernel groups, solver iterations,
launches, and what JAX's bridge adds.

MuJoCo Warp (the ``mujoco-warp`` package) steps the project's scene on states from
the two phases a pick spends its steps in:

* ``open``: the gripper around the part, pads apart (only the part on the table
  touches anything) -- the approach;
* ``held``: both pads pressed on the part, lifted 20 mm -- closing's end, lift, hold.

The states come from a scripted close and lift of ``--states`` feasible pick-points on
MuJoCo C (servo targets, not the project's force controller: the contacts set the
physics step's cost), tiled over the worlds. For each physics setting (``--physics``:
``default`` is the project's; ``old`` the solver settings before elliptic cones,
``cone=pyramidal,impratio=1,ls_iterations=8``; or ``key=value,...`` of MuJoCo options)
and phase it reports:

* ms per step and per kernel group, each group captured 10 times in one CUDA graph
  (no launch overhead): collision, the rest of the position stage (kinematics, inertia,
  constraint rows), velocity/actuation/smooth acceleration, the solver with and
  without CUDA graph conditionals (``opt.graph_conditional``: the iteration loop stops
  when every world has converged), the post-constraint RNE that gives cfrc_ext (the
  pad forces), and the integrator;
* the solver's cost per iteration (a slope: the solver at 1 and 8 iterations with the
  tolerance at 0, so that every world runs them all) and its fixed cost;
* solver iterations per world (median, 99th percentile, max, share at the cap), and
  over ``--steps`` consecutive steps the share of steps in which every world converged
  before the cap (where a graph conditional saves anything);
* kernel launches per step (counted at ``wp.launch``), fixed and per solver iteration;
* with ``--mjx-steps``: ms per step through MJX's JAX bridge (``impl='warp'``: vmap and
  scan of ``mjx.step``; MJX runs every iteration, no graph conditionals).

    python benchmarks/warp_profile.py --worlds 32768 --physics default --physics old \
        --json benchmarks/out/warp_profile.json

Needs a CUDA GPU, warp-lang and mujoco-warp.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import platform
import time

import mujoco
import numpy as np

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp

PHYSICS = {
    "default": {},
    "old": {"cone": "pyramidal", "impratio": "1", "ls_iterations": "8"},
}


def scripted_states(scene, grasp, n: int, seed: int) -> dict[str, tuple[np.ndarray, ...]]:
    """(qpos, qvel, ctrl) per phase, each (n, nq) / (n, nv) / (n, nu), by a scripted
    close and lift on MuJoCo C."""
    m, ix = scene.model, scene.index
    picks = pp.generate_normal(scene.object, scene.gripper, n, seed=seed, grasp=grasp)
    q0 = scene.placement(picks).qpos  # grasp_gap_mm: opening less both gaps
    d = mujoco.MjData(m)
    out = {"open": [], "held": []}
    half_stroke = ix.stroke_m / 2
    kp = scene.gripper.drive_stiffness_n_per_mm * 1e3
    squeeze_m = grasp.grip_force_n / kp
    speed, dt = grasp.closing_speed_mm_s * 1e-3, m.opt.timestep
    for i, q in enumerate(q0):
        mujoco.mj_resetData(m, d)
        d.qpos[:] = q
        d.ctrl[:] = 0
        d.ctrl[ix.lift_actuator] = d.qpos[ix.lift_qpos]
        d.ctrl[ix.finger_left_actuator] = d.qpos[ix.finger_left_qpos]
        d.ctrl[ix.finger_right_actuator] = d.qpos[ix.finger_right_qpos]
        mujoco.mj_step(m, d, 20)
        out["open"].append((d.qpos.copy(), d.qvel.copy(), d.ctrl.copy()))
        # close at the procedure's speed: each servo's target moves in until it lies
        # F_d / kp past the point where its pad meets the part, so the pads press with
        # about the grip force
        fingers = (
            (ix.finger_left_actuator, ix.finger_left_qpos, picks.gap_left_mm[i]),
            (ix.finger_right_actuator, ix.finger_right_qpos, picks.gap_right_mm[i]),
        )
        start = [d.qpos[qadr] for _, qadr, _ in fingers]
        gaps = [gap * 1e-3 for _, _, gap in fingers]
        ends = [min(s + g + squeeze_m, half_stroke) for s, g in zip(start, gaps, strict=True)]
        for k in range(int(0.6 / dt) // 5):
            for (act, _, _), s, e in zip(fingers, start, ends, strict=True):
                d.ctrl[act] = min(s + speed * dt * 5 * (k + 1), e)
            mujoco.mj_step(m, d, 5)
        d.ctrl[ix.lift_actuator] = d.qpos[ix.lift_qpos] + 0.02
        mujoco.mj_step(m, d, int(0.3 / dt))
        out["held"].append((d.qpos.copy(), d.qvel.copy(), d.ctrl.copy()))
    states = {k: tuple(np.stack(a) for a in zip(*v, strict=True)) for k, v in out.items()}
    # "held": only the picks whose part went up with the gripper (a scripted servo
    # close, unlike the force controller, misses some parts)
    lifted = states["held"][0][:, 2] > 0.01
    states["held"] = tuple(a[lifted] for a in states["held"])
    return states


# keys of --physics that are the project's contact settings (a scene of their own), not
# MuJoCo options
CONTACT_KEYS = ("pad_collision",)


def parse_physics(text: str) -> tuple[dict, dict]:
    """'default', 'old' or 'key=value,key=value': (MuJoCo options, ContactParams fields)."""
    if text in PHYSICS:
        return dict(PHYSICS[text]), {}
    pairs = dict(kv.split("=", 1) for kv in text.split(","))
    contact = {k: pairs.pop(k) for k in CONTACT_KEYS if k in pairs}
    return pairs, contact


def set_options(model: mujoco.MjModel, options: dict) -> mujoco.MjModel:
    """A copy of model with MuJoCo options set (cone by name: 'pyramidal'/'elliptic')."""
    import copy

    model = copy.copy(model)
    for key, value in options.items():
        if key == "cone":
            model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{value.upper()}")
        else:
            setattr(model.opt, key, type(getattr(model.opt, key))(float(value)))
    return model


@contextlib.contextmanager
def counting_launches():
    """Counts wp.launch / wp.launch_tiled calls (MuJoCo Warp launches through them)."""
    import warp as wp

    counts = {"n": 0}
    originals = {name: getattr(wp, name) for name in ("launch", "launch_tiled")}

    def counted(fn):
        def launch(*args, **kwargs):
            counts["n"] += 1
            return fn(*args, **kwargs)

        return launch

    for name, fn in originals.items():
        setattr(wp, name, counted(fn))
    try:
        yield counts
    finally:
        for name, fn in originals.items():
            setattr(wp, name, fn)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--worlds", type=int, default=32768)
    ap.add_argument("--launches", type=int, default=5, help="timed launches of 10 captured calls")
    ap.add_argument("--states", type=int, default=256, help="distinct pick-points tiled")
    ap.add_argument("--steps", type=int, default=100, help="consecutive steps for convergence")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--physics", action="append", default=None, help="default | old | k=v,...")
    ap.add_argument("--mjx-steps", type=int, default=0, help="also time MJX's bridge (steps)")
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument(
        "--kernels", type=int, default=0, help="also list the N costliest kernels of a step"
    )
    ap.add_argument(
        "--rollout",
        type=int,
        default=0,
        help="instead: the Warp backend's own rollout of this many picks (one pool): ms per "
        "physics step over the picks' time, and the costliest kernels at a few ticks",
    )
    args = ap.parse_args()

    import warp as wp

    wp.config.quiet = True
    import mujoco_warp as mjw
    from mujoco_warp._src import constraint, smooth, solver

    from mjx_pick.engine.warp_buffers import size_buffers

    def graph_ms(fn) -> float:
        """ms per call of fn, captured 10 times in one CUDA graph (no launch overhead;
        on the CPU, for checking this script: called 10 times)."""
        if not wp.get_device().is_cuda:
            t0 = time.perf_counter()
            for _ in range(10):
                fn()
            wp.synchronize()
            return (time.perf_counter() - t0) / 10 * 1e3
        with wp.ScopedCapture() as capture:
            for _ in range(10):
                fn()
        wp.capture_launch(capture.graph)
        wp.synchronize()
        t0 = time.perf_counter()
        for _ in range(args.launches):
            wp.capture_launch(capture.graph)
        wp.synchronize()
        return (time.perf_counter() - t0) / (10 * args.launches) * 1e3

    grasp = mp.GraspConfig()
    obj, gripper = mp.load_object(args.object), mp.load_gripper(args.gripper)
    scene = mp.build_scene(obj, gripper, grasp=grasp)
    if args.rollout:
        rows = rollout_profile(scene, grasp, args.rollout, args.kernels or 25, args.seed)
        if args.json:
            with open(args.json, "w") as f:
                json.dump({"meta": {"device": wp.get_device().name}, "rows": rows}, f, indent=1)
        return
    device = wp.get_device()
    prepared: dict = {}  # per contact variant: its scene, buffers and scripted states

    def prepare(contact: dict):
        key = tuple(sorted(contact.items()))
        if key not in prepared:
            sc = scene
            if contact:
                sc = mp.build_scene(obj, gripper, mp.ContactParams(**contact), grasp=grasp)
            buffers = size_buffers(sc, grasp)
            t0 = time.perf_counter()
            states = scripted_states(sc, grasp, args.states, args.seed)
            print(
                f"{device.name}; warp {wp.__version__}, mujoco_warp {mjw.__version__}; "
                f"contact {contact or 'default'}: buffers {buffers.contacts} contacts, "
                f"{buffers.rows} rows per world, {sc.model.ngeom} geoms, {sc.model.npair} "
                f"pairs; {args.states} picks scripted on MuJoCo C in "
                f"{time.perf_counter() - t0:.1f} s",
                flush=True,
            )
            prepared[key] = (sc, buffers, states)
        return prepared[key]

    rows = []
    for text in args.physics or ["default", "old"]:
        options, contact = parse_physics(text)
        scene_v, buffers, states = prepare(contact)
        base = set_options(scene_v.model, options)

        def put(mjm, conditional: bool, **opt):
            mjm = set_options(mjm, opt)
            mw = mjw.put_model(mjm)
            mw.opt.run_rne_postconstraint = True  # as the rollouts: pad forces from cfrc_ext
            mw.opt.warn_overflow = 0
            mw.opt.graph_conditional = conditional
            return mw

        for phase, (qpos, qvel, ctrl) in states.items():
            dw = mjw.make_data(
                base, nworld=args.worlds, naconmax=buffers.naconmax(args.worlds), njmax=buffers.rows
            )
            reps = -(-args.worlds // len(qpos))

            def load(dw=dw, qpos=qpos, qvel=qvel, ctrl=ctrl, reps=reps):
                for field, value in (("qpos", qpos), ("qvel", qvel), ("ctrl", ctrl)):
                    getattr(dw, field).assign(np.tile(value, (reps, 1))[: args.worlds])

            load()
            row = {"physics": text, "phase": phase, "worlds": args.worlds, "states": len(qpos)}
            mw = put(base, conditional=True)
            t0 = time.perf_counter()
            mjw.step(mw, dw)  # builds the kernels (Warp caches them on disk)
            wp.synchronize()
            row["first_step_s"] = time.perf_counter() - t0
            load()
            mjw.forward(mw, dw)
            niter = dw.solver_niter.numpy()
            cap = base.opt.iterations
            row |= {
                "niter_median": float(np.median(niter)),
                "niter_p99": float(np.percentile(niter, 99)),
                "niter_max": int(niter.max()),
                "at_cap_share": float(np.mean(niter >= cap)),
                "contacts_per_world": float(dw.nacon.numpy()[0]) / args.worlds,
                "rows_mean": float(dw.nefc.numpy().mean()),
                "rows_max": int(dw.nefc.numpy().max()),
            }
            mw_nc = put(base, conditional=False)
            row["step_ms"] = graph_ms(lambda mw=mw, dw=dw: mjw.step(mw, dw))
            row["step_ms_no_conditional"] = graph_ms(lambda mw=mw_nc, dw=dw: mjw.step(mw, dw))
            load()
            row["forward_ms"] = graph_ms(lambda mw=mw, dw=dw: mjw.forward(mw, dw))
            row["position_ms"] = graph_ms(lambda mw=mw, dw=dw: mjw.fwd_position(mw, dw, False))
            row["collision_ms"] = graph_ms(lambda mw=mw, dw=dw: mjw.collision(mw, dw))
            row["constraint_ms"] = graph_ms(lambda mw=mw, dw=dw: constraint.make_constraint(mw, dw))

            def smooth_stage(mw=mw, dw=dw):
                mjw.fwd_velocity(mw, dw)
                mjw.fwd_actuation(mw, dw)
                mjw.fwd_acceleration(mw, dw, factorize=True)

            row["smooth_ms"] = graph_ms(smooth_stage)
            row["solve_ms"] = graph_ms(lambda mw=mw, dw=dw: solver.solve(mw, dw))
            row["solve_ms_no_conditional"] = graph_ms(lambda mw=mw_nc, dw=dw: solver.solve(mw, dw))
            row["rne_post_ms"] = graph_ms(lambda mw=mw, dw=dw: smooth.rne_postconstraint(mw, dw))
            row["integrate_ms"] = row["step_ms"] - row["forward_ms"]
            # the solver's cost per iteration: every world runs k iterations (tolerance 0)
            per_k = {}
            for k in (1, 8):
                mk = put(base, conditional=False, iterations=k, tolerance=0)
                per_k[k] = graph_ms(lambda mw=mk, dw=dw: solver.solve(mw, dw))
            row["solve_iteration_ms"] = (per_k[8] - per_k[1]) / 7
            row["solve_fixed_ms"] = per_k[1] - row["solve_iteration_ms"]
            # launches: fixed and per solver iteration (no conditionals: each counted)
            counted = {}
            for k in (1, 2):
                mk = put(base, conditional=False, iterations=k, tolerance=0)
                with counting_launches() as c:
                    mjw.step(mk, dw)
                counted[k] = c["n"]
            row["launches_per_iteration"] = counted[2] - counted[1]
            row["launches_fixed"] = counted[1] - row["launches_per_iteration"]
            row["launches_per_step_no_conditional"] = (
                row["launches_fixed"] + cap * row["launches_per_iteration"]
            )
            # consecutive steps: is there a step where every world has converged?
            load()
            maxes, p99s = [], []
            for _ in range(args.steps):
                mjw.step(mw_nc, dw)
                n = dw.solver_niter.numpy()
                maxes.append(int(n.max()))
                p99s.append(float(np.percentile(n, 99)))
            maxes = np.asarray(maxes)
            row["steps"] = args.steps
            row["steps_all_converged_share"] = float(np.mean(maxes < cap))
            row["steps_niter_max_median"] = float(np.median(maxes))
            row["steps_niter_p99_median"] = float(np.median(p99s))
            if args.kernels:
                row["kernels"] = kernel_times(lambda mw=mw, dw=dw: mjw.step(mw, dw), args.kernels)
                for name, ms, calls in row["kernels"]:
                    print(f"  {text} {phase}: {ms:8.3f} ms  x{calls:<4d} {name}", flush=True)
            if args.mjx_steps:
                row["mjx_bridge_step_ms"] = mjx_scan_ms(
                    base, buffers, (qpos, qvel, ctrl), args.worlds, args.mjx_steps, 3
                )
            row["world_steps_per_s_m"] = args.worlds / row["step_ms"] / 1e3
            rows.append(row)
            print(json.dumps(row), flush=True)
            del dw
    if args.json:
        meta = {
            "device": device.name,
            "host": platform.node(),
            "warp": wp.__version__,
            "mujoco_warp": mjw.__version__,
            "mujoco": mujoco.__version__,
            "buffers": dataclasses.asdict(buffers),
        }
        with open(args.json, "w") as f:
            json.dump({"meta": meta, "rows": rows}, f, indent=1)


def rollout_profile(scene, grasp, n: int, top: int, seed: int) -> list[dict]:
    """The Warp backend's pool of n slots on n picks, from the start until every pick
    has ended: for each round of the backend's ticks, ms per physics step (graph
    launches, synchronised) and the picks still running, by phase; at the first round
    in which most live picks are closing, lifting and holding, the costliest kernels of
    one control period (eager launches, CUDA activity records)."""
    import warp as wp

    from mjx_pick.engine import warp_direct as wd
    from mjx_pick.engine.backend import make_inputs
    from mjx_pick.kernels import grasp as gk
    from mjx_pick.kernels import grasp_warp as gw

    picks = pp.generate_normal(scene.object, scene.gripper, n, seed=seed, grasp=grasp)
    inputs = make_inputs(scene, grasp, picks)
    backend = wd.WarpBackend(scene, grasp, len(inputs), shrink_levels=0)
    backend.fields = ()
    pool = backend._pool(len(inputs), 0)
    src = wd._device_inputs(inputs, (), gw)
    slot_pick = np.arange(len(inputs), dtype=np.int32)
    backend._refill(pool, src, slot_pick, slot_pick >= 0)
    n_sub, rows, profiled = backend.n_sub, [], set()
    for r in range(-(-grasp.n_ticks() // backend.ticks_per_call)):
        host = pool.ctl.numpy()["phase"]
        live = pool.live.numpy().astype(bool) if r else np.ones(len(inputs), bool)
        counts = {gk.PHASES[p]: int(np.sum((host == p) & live)) for p in range(len(gk.PHASES))}
        main = max(("close", "lift", "hold"), key=lambda k: counts[k])
        if counts[main] > len(inputs) // 2 and main not in profiled:
            profiled.add(main)
            listed = kernel_times(lambda: pool.period(backend), top, steps=2)
            for name, ms, calls in listed:
                print(
                    f"  rollout {main}: {ms / n_sub:8.3f} ms/step x{calls:<4d} {name}", flush=True
                )
            rows.append({"kind": "kernels", "phase": main, "per_period": listed})
        wp.synchronize()
        t0 = time.perf_counter()
        for _ in range(backend.ticks_per_call):
            pool.run_period(backend)
        wp.synchronize()
        ms = (time.perf_counter() - t0) / (backend.ticks_per_call * n_sub) * 1e3
        row = {"kind": "round", "round": r, "ms_per_step": ms, **counts}
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def kernel_times(step, top: int, steps: int = 5) -> list[tuple[str, float, int]]:
    """GPU time per kernel of ``steps`` eager steps (CUDA activity records), summed by
    kernel name over the steps and divided by them: (name, ms per step, launches per
    step), the costliest ``top``."""
    import collections

    import warp as wp

    step()  # warm
    wp.synchronize()
    wp.timing_begin(cuda_filter=wp.TIMING_KERNEL | wp.TIMING_KERNEL_BUILTIN, synchronize=True)
    for _ in range(steps):
        step()
    results = wp.timing_end()
    total = collections.defaultdict(float)
    calls = collections.Counter()
    for r in results:
        total[r.name] += r.elapsed
        calls[r.name] += 1
    rows = sorted(total.items(), key=lambda kv: -kv[1])[:top]
    return [(name, ms / steps, calls[name] // steps) for name, ms in rows]


def mjx_scan_ms(model, buffers, states, worlds: int, steps: int, repeats: int) -> float:
    """ms per physics step of ``worlds`` simulations stepped through MJX's bridge
    (``impl='warp'``, graph mode WARP): ``vmap`` of ``mjx.step`` with per-world
    contact-pair parameters, ``steps`` steps under ``lax.scan`` in one jitted call, as
    the MJX-Warp rollout steps them, without the project's controller or pool."""
    import types

    import jax
    from mujoco import mjx
    from mujoco.mjx.warp import types as mjxw_types

    from mjx_pick.engine.mjx_backend import _slot_axes

    mx = mjx.put_model(model, impl="warp", graph_mode=mjxw_types.GraphMode.WARP)
    opt = mx.opt._impl.replace(run_rne_postconstraint=True, warn_overflow=0)
    mx = mx.replace(opt=mx.opt.replace(_impl=opt))
    d0 = mjx.make_data(model, impl="warp", naconmax=buffers.naconmax(worlds), njmax=buffers.rows)
    axes = _slot_axes(types.SimpleNamespace(impl="warp", data0=d0)).d
    tree = jax.tree.structure(d0)
    qpos, qvel, ctrl = (np.tile(a, (-(-worlds // len(a)), 1))[:worlds] for a in states)
    pair_fields = (model.pair_friction, model.pair_solref, model.pair_solimp)
    pairs = tuple(np.tile(a, (worlds, 1, 1)) for a in pair_fields)

    def start(q, v, c):
        return tuple(tree.flatten_up_to(d0.replace(qpos=q, qvel=v, ctrl=c)))

    def step_one(leaves, friction, solref, solimp):
        mw = mx.replace(pair_friction=friction, pair_solref=solref, pair_solimp=solimp)
        return tuple(tree.flatten_up_to(mjx.step(mw, tree.unflatten(leaves))))

    step = jax.vmap(step_one, in_axes=(axes, 0, 0, 0), out_axes=axes)

    @jax.jit
    def run(leaves, *pair):
        return jax.lax.scan(lambda c, _: (step(c, *pair), None), leaves, None, length=steps)[0]

    leaves = jax.jit(jax.vmap(start, out_axes=axes))(qpos, qvel, ctrl)
    jax.block_until_ready(run(leaves, *pairs))  # compile, and Warp's kernels
    t0 = time.perf_counter()
    for _ in range(repeats):
        jax.block_until_ready(run(leaves, *pairs))
    return (time.perf_counter() - t0) / (repeats * steps) * 1e3


if __name__ == "__main__":
    main()
