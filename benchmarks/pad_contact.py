"""Pad-contact measurements behind the soft-finger model (issue 16), on MuJoCo C.

    python benchmarks/pad_contact.py creep        # slip over lift + hold vs pad solimp
    python benchmarks/pad_contact.py convergence  # door-opener labels, dt 1 vs 0.5 ms
    python benchmarks/pad_contact.py torque       # off-centre bar and rod: where they turn
    python benchmarks/pad_contact.py coulomb --backend warp   # tests' Coulomb grid, any backend

Each prints a table; the figures are in benchmarks/RESULTS.md ("Pad contact").
"""

from __future__ import annotations

import argparse
import collections

import numpy as np
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import G
from mjx_pick.engine.backend import make_inputs
from mjx_pick.engine.runner import Engine
from mjx_pick.kernels import grasp as gk

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
    """Slip over lift and hold of a centred block, by pad impedance and impratio."""
    grasp = mp.GraspConfig(close_timeout_s=1.0, lift_height_mm=100.0, hold_s=0.5)
    variants = {  # (pad solimp dmin, dmax, impratio)
        "solimp 0.9-0.95 (MuJoCo), impratio 1": (0.9, 0.95, 1.0),
        "solimp 0.99, impratio 1": (0.99, 0.99, 1.0),
        "solimp 0.99, impratio 2": (0.99, 0.99, 2.0),
        "solimp 0.99, impratio 3": (0.99, 0.99, 3.0),
    }
    print("mu  mass_kg  F/F_Coulomb(g+a)  slip_mm per variant:", list(variants))
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
            for dmin, dmax, impratio in variants.values():
                contact = mp.ContactParams(pad_friction=mu, pad_solimp=(dmin, dmax, 0.001, 0.5, 2))
                solver = mp.SolverParams(impratio=impratio)
                out, _ = _run(block, picks, grasp, contact, solver, force_n=force)
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


def _lying_rod(mass_kg: float) -> mp.ObjectModel:
    import tempfile
    from pathlib import Path

    import trimesh

    rod = trimesh.creation.cylinder(radius=0.01, height=0.2, sections=24)
    rod.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    rod.apply_translation([0, 0, -rod.bounds[0, 2]])
    with tempfile.TemporaryDirectory() as tmp:
        rod.export(Path(tmp) / "rod.stl")
        return mp.object_from_mesh(Path(tmp) / "rod.stl", unit="m", mass_g=mass_kg * 1e3)


def torque() -> None:
    """Off-centre parts: the lever at which they first turn out of the grasp, against
    the capacity the model states (mjx_pick.core.holding) and a uniform-pressure rubber pad."""
    from mjx_pick.core import holding

    cases = {
        "bar 20x20x200 mm, 0.6 kg, 30 N": (
            mp.object_from_polygon(box(-10, -100, 10, 100), thickness_mm=20, mass_g=600),
            0.6,
            30.0,
        ),
        "rod d20x200 mm lying, 0.3 kg, 20 N": (_lying_rod(0.3), 0.3, 20.0),
    }
    mu = 0.5
    for label, (part, mass, force) in cases.items():
        grasp = mp.GraspConfig(
            close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.5, grip_force_n=force
        )
        weight = mass * (G + grasp.lift_accel_mm_s2 * 1e-3)
        for torsion in (None, 0.0):
            contact = mp.ContactParams(pad_friction=mu, pad_torsion_mm=torsion)
            scene = mp.build_scene(part, FREE, contact, None, grasp)
            points = holding.pad_contacts(scene)
            mu_t = scene.contact.pad_torsion_m
            stated = holding.hold_limit_m(points, force, weight, mu, mu_t, scene.solver.cone)
            w, h = (v * 1e-3 for v in scene.pad_patch_mm)
            rubber = holding.hold_limit_m(
                holding.uniform_patch_points(w, h), force, weight, mu, 0.0, "elliptic"
            )
            factors = np.linspace(0.5, 1.5, 21)
            out, _ = _run(part, _centred(part, grasp, factors * stated * 1e3), grasp, contact)
            ok = out["success"]
            first = factors[np.argmax(~ok)] if (~ok).any() else np.nan
            last = factors[: np.argmax(~ok)][-1] if (~ok).any() and ok[0] else np.nan
            print(
                f"{label}, mu_t {mu_t * 1e3:.2f} mm: {len(points.points_m)} contact points; "
                f"stated d* = {stated * 1e3:.1f} mm; measured threshold in "
                f"({last:.2f}, {first:.2f}] x d*; uniform rubber pad "
                f"{rubber * 1e3:.1f} mm (engine / rubber {stated / rubber:.2f}x); "
                f"held {int(ok.sum())} of {len(ok)}",
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
