"""Where a MuJoCo Warp physics step spends its time, per kernel group (issue 17).

The project's Warp rollout runs ~7 M slot-steps/s on an H100 (RESULTS.md); this splits
one physics step of the same scene into its main parts (collision, position stage,
constraint solver), for states taken from the two phases a pick spends its steps in:

* ``open``: the gripper around the part, pads apart (only the part on the table
  touches anything) -- the approach;
* ``held``: both pads pressed on the part, lifted 20 mm -- closing's end, lift, hold.

The states come from a scripted close and lift of n feasible pick-points on MuJoCo C
(servo targets, not the project's force controller: the contacts, not the control,
set the physics step's cost), tiled over the worlds. Each part is timed on its own,
ten calls captured in one CUDA graph (Warp's EventTracer launches kernel by kernel,
and its launch overhead swamped the GPU time: 49 ms per traced step against 4.2 ms per
graphed one at 32,768 worlds), for the scene as shipped and for variants of it.

    python benchmarks/warp_profile.py --worlds 32768 --variant default \
        --variant ccd_iterations=16 --variant ccd_tolerance=1e-4

Needs a CUDA GPU and warp-lang (``pip install -e '.[gpu]'``).
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.engine.warp_backend import size_buffers


def scripted_states(scene, grasp, n: int, seed: int) -> dict[str, tuple[np.ndarray, ...]]:
    """(qpos, qvel, ctrl) per phase, each (n, nq) / (n, nv) / (n, nu), by a scripted
    close and lift on MuJoCo C."""
    m, ix = scene.model, scene.index
    picks = pp.generate_normal(scene.object, scene.gripper, n, seed=seed, grasp=grasp)
    q0 = scene.initial_qpos(
        picks.x_mm * 1e-3,
        picks.y_mm * 1e-3,
        np.deg2rad(picks.yaw_deg),
        picks.opening_mm * 1e-3,
        grasp_gap_m=(picks.opening_mm - picks.gap_left_mm - picks.gap_right_mm) * 1e-3,
    )
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
        # F_d / kp past the point where its pad meets the part (the pick's gap), so the
        # pads press with about the grip force
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


def build(args, variant: dict):
    """The scene for one variant: MuJoCo options (``ccd_iterations``, ...) set on the
    model as built; keys ``warp.NAME`` are left for :func:`warp_options`."""
    grasp = mp.GraspConfig()
    scene = mp.build_scene(mp.load_object(args.object), mp.load_gripper(args.gripper), grasp=grasp)
    for key, value in variant.items():
        if not key.startswith("warp."):
            setattr(scene.model.opt, key, type(getattr(scene.model.opt, key))(value))
    return scene, grasp


def warp_options(mw, variant: dict) -> None:
    """MuJoCo Warp's own options on the put model: as the rollout sets them, then the
    variant's ``warp.NAME=VALUE`` (e.g. ``warp.run_rne_postconstraint=0``: what the
    post-constraint RNE pass that gives cfrc_ext -- the pad forces -- costs)."""
    mw.opt.run_rne_postconstraint = True  # as the rollout (pad forces from cfrc_ext)
    mw.opt.warn_overflow = 0  # overflow is read back below, not printed per step
    for key, value in variant.items():
        if key.startswith("warp."):
            name = key[len("warp.") :]
            setattr(mw.opt, name, type(getattr(mw.opt, name))(int(float(value))))


def parse_variant(text: str) -> dict:
    """'default' or 'key=value,key=value' (ccd_iterations=16,ccd_tolerance=1e-4)."""
    if text == "default":
        return {}
    return dict(kv.split("=", 1) for kv in text.split(","))


def mjx_scan_ms(scene, buffers, states, worlds: int, steps: int, repeats: int) -> float:
    """ms per physics step of ``worlds`` simulations stepped through MJX (``impl='warp'``,
    graph mode WARP), as the rollout steps them -- ``vmap`` of ``mjx.step`` with per-world
    contact-pair parameters, ``steps`` steps under ``lax.scan`` in one jitted call -- but
    without the project's controller, metrics or pool. Set against the bare Warp step
    (CUDA graphs, above), it is what MJX's JAX wrapper adds; set against the rollout's
    rate (benchmarks/throughput.py), what the project's own per-step work adds."""
    import types

    import jax
    from mujoco import mjx
    from mujoco.mjx.warp import types as mjxw_types

    from mjx_pick.engine.mjx_backend import _slot_axes

    m = scene.model
    mx = mjx.put_model(m, impl="warp", graph_mode=mjxw_types.GraphMode.WARP)
    opt = mx.opt._impl.replace(run_rne_postconstraint=True, warn_overflow=0)
    mx = mx.replace(opt=mx.opt.replace(_impl=opt))
    d0 = mjx.make_data(m, impl="warp", naconmax=buffers.naconmax(worlds), njmax=buffers.rows)
    axes = _slot_axes(types.SimpleNamespace(impl="warp", data0=d0)).d
    tree = jax.tree.structure(d0)
    qpos, qvel, ctrl = (np.tile(a, (-(-worlds // len(a)), 1))[:worlds] for a in states)
    pairs = tuple(
        np.tile(a, (worlds, 1, 1)) for a in (m.pair_friction, m.pair_solref, m.pair_solimp)
    )

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--worlds", type=int, default=32768)
    ap.add_argument("--launches", type=int, default=5, help="timed launches of 10 captured calls")
    ap.add_argument("--states", type=int, default=256, help="distinct pick-points tiled")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--variant",
        action="append",
        default=None,
        help="'default' or key=value[,key=value]: MuJoCo options (ccd_iterations, "
        "ccd_tolerance, ...) or MuJoCo Warp's (warp.run_rne_postconstraint=0) (repeatable)",
    )
    ap.add_argument(
        "--mjx-steps",
        type=int,
        default=0,
        help="also time this many steps through MJX's wrapper (vmap + scan of mjx.step)",
    )
    args = ap.parse_args()

    import warp as wp
    from mujoco.mjx.third_party import mujoco_warp as mjw
    from mujoco.mjx.third_party.mujoco_warp._src import solver

    def graph_ms(fn) -> float:
        """ms per call of fn, captured 10 times in one CUDA graph (no launch overhead)."""
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

    base, grasp = build(args, {})
    buffers = size_buffers(base, grasp)
    t0 = time.perf_counter()
    states = scripted_states(base, grasp, args.states, args.seed)
    print(
        f"buffers {buffers.contacts} contacts, {buffers.rows} rows per world; states: "
        f"{args.states} picks scripted on MuJoCo C in {time.perf_counter() - t0:.1f} s",
        flush=True,
    )
    print(
        "variant | phase | states | step ms | M world-steps/s | collision ms | "
        "fwd_position ms | solve ms | contacts/world | rows mean / max"
    )
    for text in args.variant or ["default"]:
        variant = parse_variant(text)
        scene, _ = build(args, variant)
        m = scene.model
        mw = mjw.put_model(m)
        warp_options(mw, variant)
        for phase, (qpos, qvel, ctrl) in states.items():
            dw = mjw.make_data(
                m, nworld=args.worlds, naconmax=buffers.naconmax(args.worlds), njmax=buffers.rows
            )
            reps = -(-args.worlds // len(qpos))
            for field, value in (("qpos", qpos), ("qvel", qvel), ("ctrl", ctrl)):
                getattr(dw, field).assign(np.tile(value, (reps, 1))[: args.worlds])
            t0 = time.perf_counter()
            mjw.step(mw, dw)  # builds the kernels (cached by Warp)
            wp.synchronize()
            build_s = time.perf_counter() - t0
            step = graph_ms(lambda mw=mw, dw=dw: mjw.step(mw, dw))
            coll = graph_ms(lambda mw=mw, dw=dw: mjw.collision(mw, dw))
            pos = graph_ms(lambda mw=mw, dw=dw: mjw.fwd_position(mw, dw))
            mjw.forward(mw, dw)
            solve = graph_ms(lambda mw=mw, dw=dw: solver.solve(mw, dw))
            nacon = int(dw.nacon.numpy()[0])
            nefc = dw.nefc.numpy()
            print(
                f"{text} | {phase} | {len(qpos)} | {step:.3f} | {args.worlds / step / 1e3:.2f} | "
                f"{coll:.3f} | {pos:.3f} | {solve:.3f} | {nacon / args.worlds:.2f} | "
                f"{nefc.mean():.1f} / {nefc.max()}  (first step {build_s:.1f} s)",
                flush=True,
            )
            if args.mjx_steps:
                del dw
                ms = mjx_scan_ms(scene, buffers, (qpos, qvel, ctrl), args.worlds, args.mjx_steps, 3)
                print(
                    f"{text} | {phase} | through MJX (vmap + scan of mjx.step) | {ms:.3f} ms | "
                    f"{args.worlds / ms / 1e3:.2f} M world-steps/s",
                    flush=True,
                )


if __name__ == "__main__":
    main()
