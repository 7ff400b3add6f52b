"""Benchmark: do MuJoCo C and MuJoCo Warp find the same pad contacts at the same state?

On the YCB meshes Warp's labels are a few points less often "success" than C's, also on
labels a micrometre's shift does not flip (benchmarks/results/history.md, "Time to answer,
seventh session"). Both engines
integrate the same model; they differ most in collision: each has its own convex
collider (C: libccd/native CCD with multi-contact ``multiccd``; Warp: its own GJK/EPA
port with its own multi-contact rules). This compares the contacts themselves, with no
dynamics in between: MuJoCo C simulates the picks with traces; at chosen moments of each
(the first tick of the lift, its middle, the first tick of the hold) the state is rebuilt
from the trace (object pose, lift, finger travel: the default parallel jaw's coordinates)
and both engines run collision detection on it -- C (``mj_fwdPosition``), C with
multi-contact off, and Warp (``fwd_position`` of MuJoCo Warp, one world per state).

Per engine, over the states: contacts per pad (between a finger's geoms and the part's),
the share of pads with none, and the span of each pad's contact points (mm, the largest
distance between two of them: the lever a pad has against the part turning in the grip).

    python benchmarks/probes/contact_sets.py --objects 011_banana,050_medium_clamp --n 64 \\
        --out benchmarks/results/contact_sets_h100.json        # a GPU machine
    python benchmarks/probes/contact_sets.py --engines c,c_no_multiccd --n 16   # a CPU
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: real_objects
from real_objects import load_ycb

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.engine.inputs import addresses, make_inputs
from mjx_pick.engine.runner import Runner
from mjx_pick.kernels import grasp as gk

F = {f: i for i, f in enumerate(gk.TRACE_FIELDS)}


def states(obj, n: int, seed: int, gripper_name: str = "robotiq-2f85", force_n: float = 50.0):
    """(scene, qpos (S, nq), labels (S,) of the pick each state comes from, moments (S,))."""
    gripper = mp.load_gripper(gripper_name)
    grasp = mp.GraspConfig(grip_force_n=force_n)
    table = mp.evaluate(
        obj, gripper, n=n, seed=seed, backend="mujoco", grasp=grasp
    ).table.to_pandas()
    checker = pp.FeasibilityChecker(obj, gripper, grasp=grasp)
    picks = checker.batch(
        np.arange(len(table)), table["x_mm"], table["y_mm"], table["yaw_deg"], "user"
    )
    scene = mp.build_scene(obj, gripper, None, None, grasp)
    ad = addresses(scene)
    if ad.drive is not None:
        raise SystemExit("the state is rebuilt from a parallel jaw's coordinates only")
    inputs = make_inputs(scene, grasp, picks)
    traces = Runner("mujoco", len(table)).simulate(scene, grasp, inputs, record=True).traces
    qs, labels, moments = [], [], []
    for i in range(len(table)):
        phase = traces[i, :, F["phase"]]
        lift = np.flatnonzero(phase == gk.LIFT)
        hold = np.flatnonzero(phase == gk.HOLD)
        ticks = {}
        if len(lift):
            ticks["lift_start"] = lift[0]
            ticks["lift_mid"] = lift[len(lift) // 2]
        if len(hold):
            ticks["hold_start"] = hold[0]
        for moment, k in ticks.items():
            row = traces[i, k]
            q = np.array(inputs.qpos0[i], float)
            o = ad.object_qpos
            q[o : o + 3] = row[[F["object_x_m"], F["object_y_m"], F["object_z_m"]]]
            q[o + 3 : o + 7] = row[[F["object_qw"], F["object_qx"], F["object_qy"], F["object_qz"]]]
            q[ad.lift_qpos] = row[F["lift_m"]]
            q[ad.finger_left_qpos] = row[F["finger_left_m"]]
            q[ad.finger_right_qpos] = row[F["finger_right_m"]]
            qs.append(q)
            labels.append(bool(table["success"].iloc[i]))
            moments.append(moment)
    return scene, np.array(qs), np.array(labels), np.array(moments)


def c_contacts(model: mujoco.MjModel, qs: np.ndarray, multiccd: bool):
    """Per state, a list of (geom1, geom2, dist m, pos (3,) m) from MuJoCo C."""
    m = copy.copy(model) if not multiccd else model
    if not multiccd:
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MULTICCD
    d = mujoco.MjData(m)
    out = []
    for q in qs:
        d.qpos[:] = q
        d.qvel[:] = 0
        mujoco.mj_fwdPosition(m, d)
        out.append([(c.geom1, c.geom2, c.dist, np.array(c.pos)) for c in d.contact[: d.ncon]])
    return out


def warp_contacts(model: mujoco.MjModel, qs: np.ndarray):
    """The same from MuJoCo Warp (one world per state)."""
    import warp as wp
    from mujoco.mjx.third_party import mujoco_warp as mjw

    wp.init()
    mw = mjw.put_model(model)
    d0 = mujoco.MjData(model)
    mujoco.mj_forward(model, d0)
    n = len(qs)
    dw = mjw.put_data(model, d0, nworld=n, nconmax=256, njmax=2048)
    wp.copy(dw.qpos, wp.array(qs.astype(np.float32), dtype=float))
    mjw.fwd_position(mw, dw)
    wp.synchronize()
    nacon = int(dw.nacon.numpy()[0])
    world = dw.contact.worldid.numpy()[:nacon]
    geom = dw.contact.geom.numpy()[:nacon]
    dist = dw.contact.dist.numpy()[:nacon]
    pos = dw.contact.pos.numpy()[:nacon]
    out = [[] for _ in range(n)]
    for w, g, dd, p in zip(world, geom, dist, pos, strict=True):
        out[w].append((int(g[0]), int(g[1]), float(dd), np.array(p)))
    return out


def summarise(model, ad, contacts, labels):
    """Contacts per pad, pads without contact, span of each pad's contact points."""
    body = model.geom_bodyid
    per_pad, spans, depth = [], [], []
    for cs in contacts:
        for finger in (ad.finger_left_body, ad.finger_right_body):
            pts = [
                (dist, pos)
                for g1, g2, dist, pos in cs
                if {body[g1], body[g2]} == {finger, ad.object_body} and dist <= 0
            ]
            per_pad.append(len(pts))
            ps = np.array([p for _, p in pts]) if pts else np.zeros((0, 3))
            span = max(
                (np.linalg.norm(a - b) for i, a in enumerate(ps) for b in ps[i + 1 :]),
                default=0.0,
            )
            spans.append(span * 1e3)
            depth.append(-min((d for d, _ in pts), default=0.0) * 1e3)
    per_pad, spans = np.array(per_pad), np.array(spans)
    return {
        "contacts_per_pad_mean": round(float(per_pad.mean()), 3),
        "pads_without_contact": round(float(np.mean(per_pad == 0)), 4),
        "pads_with_one_contact": round(float(np.mean(per_pad == 1)), 4),
        "span_mm_mean": round(float(spans.mean()), 3),
        "span_mm_median": round(float(np.median(spans)), 3),
        "deepest_mm_mean": round(float(np.mean(depth)), 4),
        "_per_pad": per_pad,
        "_span": spans,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="011_banana,050_medium_clamp,040_large_marker")
    ap.add_argument("--engines", default="c,c_no_multiccd,warp")
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--gripper", default="robotiq-2f85", help="a parallel-jaw preset")
    ap.add_argument("--force-n", type=float, default=50.0, help="F_d, N")
    args = ap.parse_args()
    engines = args.engines.split(",")
    report = {
        "date": time.strftime("%Y-%m-%d"),
        "n": args.n,
        "gripper": args.gripper,
        "force_n": args.force_n,
        "objects": {},
    }
    for name in args.objects.split(","):
        obj = load_ycb(name)
        scene, qs, labels, moments = states(obj, args.n, args.seed, args.gripper, args.force_n)
        ad = addresses(scene)
        found = {}
        for e in engines:
            if e == "warp":
                found[e] = warp_contacts(scene.model, qs)
            else:
                found[e] = c_contacts(scene.model, qs, multiccd=(e == "c"))
        rows = {e: summarise(scene.model, ad, found[e], labels) for e in engines}
        entry = {"states": len(qs), "picks": int(args.n)}
        for e in engines:
            entry[e] = {k: v for k, v in rows[e].items() if not k.startswith("_")}
            if e != "c" and "c" in rows:
                a, b = rows["c"]["_per_pad"], rows[e]["_per_pad"]
                entry[e]["pads_fewer_than_c"] = round(float(np.mean(b < a)), 4)
                entry[e]["pads_more_than_c"] = round(float(np.mean(b > a)), 4)
                entry[e]["span_mm_minus_c_mean"] = round(
                    float(np.mean(rows[e]["_span"] - rows["c"]["_span"])), 3
                )
        for moment in ("lift_start", "lift_mid", "hold_start"):
            sel = np.repeat(moments == moment, 2)  # two pads per state
            entry[f"contacts_per_pad_{moment}"] = {
                e: round(float(rows[e]["_per_pad"][sel].mean()), 3) if sel.any() else None
                for e in engines
            }
        report["objects"][name] = entry
        print(name, json.dumps(entry, indent=1), flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
