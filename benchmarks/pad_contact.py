"""Pad-contact measurements behind the soft-finger model (issue 16), on MuJoCo C.

    python benchmarks/pad_contact.py creep        # slip over lift + hold vs pad solimp
    python benchmarks/pad_contact.py convergence  # door-opener labels, dt 1 vs 0.5 ms
    python benchmarks/pad_contact.py torque       # off-centre bar: where it turns
    python benchmarks/pad_contact.py coulomb --backend warp   # tests' Coulomb grid, any backend

Each prints a table; the figures are in benchmarks/RESULTS.md ("Pad contact").
"""

from __future__ import annotations

import argparse
import collections

import numpy as np
from mjx_pick.kernels import grasp as gk
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick import pickpoints as pp
from mjx_pick.engine import Engine
from mjx_pick.grasp import G
from mjx_pick.simulate import make_inputs

FREE = mp.GripperSpec(name="test-gripper", force_min_n=0.01)


def _centred(obj, grasp, y_mm):
    checker = pp.FeasibilityChecker(obj, FREE, grasp=grasp)
    n = len(y_mm)
    return checker.batch(np.arange(n), np.zeros(n), np.asarray(y_mm), np.zeros(n), "user")


def _run(obj, picks, grasp, contact, solver=None, backend="mujoco", **per_pick):
    scene = mp.build_scene(obj, FREE, contact, solver, grasp)
    inputs = make_inputs(scene, grasp, picks, per_pick)
    return Engine(backend, len(picks)).simulate(scene, grasp, inputs).results, scene


def creep() -> None:
    grasp = mp.GraspConfig(close_timeout_s=1.0, lift_height_mm=100.0, hold_s=0.5)
    variants = {"0.9-0.95 (MuJoCo)": (0.9, 0.95), "0.99": (0.99, 0.99)}
    print("mu  mass_kg  F/F_Coulomb(g+a)  slip_mm per pad_solimp:", list(variants))
    for mu in (0.1, 0.5, 1.0):
        for mass, thick in ((0.5, 20.0), (2.0, 60.0)):
            block = mp.object_from_polygon(
                box(-20, -15, 20, 15), thickness_mm=thick, mass_g=mass * 1e3
            )
            need = mass * (G + grasp.lift_accel_mm_s2 * 1e-3) / (2 * mu)
            factors = np.array([1.3, 2.0, 4.0])
            force = np.clip(factors * need, 0.5, 235.0).astype(np.float32)
            picks = _centred(block, grasp, np.zeros(3))
            cols = []
            for dmin, dmax in variants.values():
                contact = mp.ContactParams(pad_friction=mu, pad_solimp=(dmin, dmax, 0.001, 0.5, 2))
                out, _ = _run(block, picks, grasp, contact, force_n=force)
                cols.append(" ".join(f"{s:5.2f}" for s in out["slip_mm"]))
            print(f"{mu:4.2f} {mass:5.2f}  {factors}  " + " | ".join(cols), flush=True)


def convergence() -> None:
    obj, gripper = mp.load_asset("door_opener"), mp.load_gripper("robotiq-2f85")
    grasp = mp.GraspConfig()
    picks = pp.generate_normal(obj, gripper, 256, seed=0, grasp=grasp)
    for label, contact in (
        ("pads 0.99, table 0.9-0.95 (default)", mp.ContactParams()),
        ("pads and table 0.99", mp.ContactParams(table_solimp=(0.99, 0.99, 0.001, 0.5, 2))),
    ):
        outs = []
        for dt in (0.001, 0.0005):
            scene = mp.build_scene(obj, gripper, contact, mp.SolverParams(timestep_s=dt), grasp)
            inputs = make_inputs(scene, grasp, picks)
            outs.append(Engine("mujoco", len(picks)).simulate(scene, grasp, inputs).results)
        a, b = outs
        reasons = collections.Counter(gk.FAILURES[i] for i in a["failure"])
        print(
            f"{label}: success {a['success'].mean():.3f} (dt 1 ms), {b['success'].mean():.3f} "
            f"(0.5 ms); labels changed {np.mean(a['success'] != b['success']):.2%}; "
            f"diverged {int(a['diverged'].sum())}+{int(b['diverged'].sum())}; {dict(reasons)}",
            flush=True,
        )


def torque() -> None:
    mass, force, mu = 0.6, 30.0, 0.5
    grasp = mp.GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.5, grip_force_n=force)
    bar = mp.object_from_polygon(box(-10, -100, 10, 100), thickness_mm=20, mass_g=mass * 1e3)
    d = np.linspace(0.0, 80.0, 33)
    picks = _centred(bar, grasp, d)
    default = mp.build_scene(bar, FREE, mp.ContactParams(pad_friction=mu), None, grasp)
    floor = 2 * default.contact.pad_torsion_m * force  # N m, the soft-finger figure
    for label, torsion in (("soft-finger (default)", None), ("no torsional friction", 0.0)):
        contact = mp.ContactParams(pad_friction=mu, pad_torsion_mm=torsion)
        out, scene = _run(bar, picks, grasp, contact)
        d_floor = floor / (mass * (G + grasp.lift_accel_mm_s2 * 1e-3)) * 1e3
        first_fail = d[np.argmax(~out["success"])] if (~out["success"]).any() else np.nan
        print(
            f"{label}: patch {scene.pad_patch_mm} mm, mu_t {scene.contact.pad_torsion_m * 1e3:.2f}"
            f" mm; soft-finger floor d* = {d_floor:.1f} mm; first failure at d = "
            f"{first_fail:.1f} mm ({first_fail / d_floor:.2f}x)",
            flush=True,
        )


def coulomb(backend: str) -> None:
    """tests/test_physics.py's Coulomb grid on a backend: hold at 1.3x the force against
    m (g + a), fail at 0.8x the force against m g; forces within 0.5-235 N."""
    grasp = mp.GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.3)
    accel = grasp.lift_accel_mm_s2 * 1e-3
    wrong, total = [], 0
    for thick in (3.0, 20.0, 60.0):
        for mass in (0.01, 0.3, 2.0):
            rows = []
            for mu in (0.05, 0.2, 0.5, 1.0):
                for force, holds in (
                    (1.3 * mass * (G + accel) / (2 * mu), True),
                    (0.8 * mass * G / (2 * mu), False),
                ):
                    if 0.5 <= force <= 235.0:
                        rows.append((mu, force, holds))
            block = mp.object_from_polygon(
                box(-25, -15, 25, 15), thickness_mm=thick, mass_g=mass * 1e3
            )
            out, _ = _run(
                block,
                _centred(block, grasp, np.zeros(len(rows))),
                grasp,
                None,
                backend=backend,
                pad_friction=np.array([r[0] for r in rows], np.float32),
                force_n=np.array([r[1] for r in rows], np.float32),
            )
            total += len(rows)
            for r, ok, fail in zip(rows, out["success"], out["failure"], strict=True):
                if bool(ok) != r[2]:
                    wrong.append((thick, mass, *r, gk.FAILURES[int(fail)]))
    print(f"{backend}: {len(wrong)} wrong labels of {total}", flush=True)
    for thick, mass, mu, force, holds, failure in wrong:
        print(f"  {thick:g} mm, {mass:g} kg, mu {mu:g}, F {force:.2f} N, holds? {holds}: {failure}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("creep", "convergence", "torque", "coulomb"))
    ap.add_argument("--backend", default="mujoco", help="coulomb: the backend to test")
    args = ap.parse_args()
    if args.what == "coulomb":
        coulomb(args.backend)
    else:
        {"creep": creep, "convergence": convergence, "torque": torque}[args.what]()


if __name__ == "__main__":
    main()
