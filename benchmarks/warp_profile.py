"""Where a MuJoCo Warp physics step spends its time, per kernel group (issue 17).

The project's Warp rollout runs ~7 M slot-steps/s on an H100 (RESULTS.md); this splits
one physics step of the same scene into MuJoCo Warp's own timed scopes (collision,
constraint set-up, solver, smooth dynamics, ...) with Warp's EventTracer, for states
taken from the two phases a pick spends its steps in:

* ``open``: the gripper around the part, pads apart (only the part on the table
  touches anything) -- the approach;
* ``held``: both pads pressed on the part, lifted 20 mm -- closing's end, lift, hold.

The states come from a scripted close and lift of n feasible pick-points on MuJoCo C
(servo targets, not the project's force controller: the contacts, not the control,
set the physics step's cost), tiled over the worlds. Also timed: the same step captured
in a CUDA graph, without the tracer's events (the rate the rollout can reach), and
the rollout's own rate for comparison is in RESULTS.md.

    python benchmarks/warp_profile.py --worlds 32768 --steps 50

Needs a CUDA GPU and warp-lang (``pip install -e '.[gpu]'``).
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

import mjx_pick as mp
from mjx_pick import pickpoints as pp
from mjx_pick.backend_warp import size_buffers


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


def flatten(trace: dict, prefix: str = "") -> list[tuple[str, float, int]]:
    """EventTracer's nested {name: (events ms, sub)} -> [(path, mean ms, calls)]."""
    rows = []
    for name, (events, sub) in trace.items():
        path = f"{prefix}/{name}" if prefix else name
        rows.append((path, float(np.mean(events)), len(events)))
        rows += flatten(sub, path)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="door_opener")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--worlds", type=int, default=32768)
    ap.add_argument("--steps", type=int, default=50, help="traced steps per phase")
    ap.add_argument("--states", type=int, default=256, help="distinct pick-points tiled")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    import warp as wp
    from mujoco.mjx.third_party import mujoco_warp as mjw
    from mujoco.mjx.third_party.mujoco_warp._src import warp_util

    grasp = mp.GraspConfig()
    scene = mp.build_scene(mp.load_object(args.object), mp.load_gripper(args.gripper), grasp=grasp)
    buffers = size_buffers(scene, grasp)
    print(f"buffers: {buffers.contacts} contacts, {buffers.rows} rows per world", flush=True)
    t0 = time.perf_counter()
    states = scripted_states(scene, grasp, args.states, args.seed)
    print(f"states: {args.states} picks scripted on MuJoCo C in {time.perf_counter() - t0:.1f} s")

    m = scene.model
    mw = mjw.put_model(m)
    mw.opt.run_rne_postconstraint = True  # as the rollout (pad forces from cfrc_ext)
    for phase, (qpos, qvel, ctrl) in states.items():
        dw = mjw.make_data(
            m, nworld=args.worlds, naconmax=buffers.naconmax(args.worlds), njmax=buffers.rows
        )
        reps = -(-args.worlds // len(qpos))
        for field, value in (("qpos", qpos), ("qvel", qvel), ("ctrl", ctrl)):
            getattr(dw, field).assign(np.tile(value, (reps, 1))[: args.worlds])
        mjw.step(mw, dw)  # builds the kernels (cached by Warp)
        wp.synchronize()
        with wp.ScopedCapture() as capture:
            for _ in range(10):
                mjw.step(mw, dw)
        wp.capture_launch(capture.graph)
        wp.synchronize()
        t0 = time.perf_counter()
        reps_graph = max(1, args.steps // 10)
        for _ in range(reps_graph):
            wp.capture_launch(capture.graph)
        wp.synchronize()
        per_step = (time.perf_counter() - t0) / (10 * reps_graph)
        nacon = int(dw.nacon.numpy()[0])
        nefc = dw.nefc.numpy()
        print(
            f"\n[{phase}] {len(qpos)} states tiled over {args.worlds} worlds: "
            f"{per_step * 1e3:.3f} ms per step in a CUDA graph = "
            f"{args.worlds / per_step / 1e6:.2f} M world-steps/s; contacts "
            f"{nacon / args.worlds:.2f} per world, constraint rows mean {nefc.mean():.1f} "
            f"max {nefc.max()}",
            flush=True,
        )
        with warp_util.EventTracer() as tracer:
            for _ in range(args.steps):
                mjw.step(mw, dw)
            wp.synchronize()
            rows = flatten(tracer.trace())
        total = next((r[1] for r in rows if r[0] == "step"), None)
        for path, ms, calls in rows:
            share = f"{100 * ms / total:5.1f} %" if total else ""
            print(f"  {path:60s} {ms:8.3f} ms {share}  ({calls} calls)")


if __name__ == "__main__":
    main()
