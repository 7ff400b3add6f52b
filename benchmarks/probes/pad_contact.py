"""Pad-contact measurements behind the soft-finger model (issue 16), on MuJoCo C.

    cd benchmarks/probes
    python pad_contact.py creep        # slip over lift + hold vs pad solimp
    python pad_contact.py convergence  # door-opener labels, the step vs half of it
    python pad_contact.py torque       # off-centre bar and rod: where they turn
    python pad_contact.py coulomb --backend warp   # tests' Coulomb grid, any backend
    python pad_contact.py rubber --variants corners,square  # levers vs a rubber pad
    python pad_contact.py torsion --variants corners,square # pure torsion vs rubber
    python pad_contact.py torsion --variants rimmed --grippers robotiq-2f85-linkage
        # a tilting pad: also against rubber pads tilted as much (tilted_rubber_torque)

rubber and torsion compare pad-contact candidates (the "--variants" below: corners,
centre, shrunk, square, guarded, tiles; "corners" is the library's default pad_contact "pad",
"square" its "mean_radius") with a uniformly pressed rubber pad.

Each prints a table; the figures are in benchmarks/results/history.md ("Pad contact", "Torsion
like rubber").
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import sys
from pathlib import Path

import numpy as np
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import G
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.engine.runner import Runner
from mjx_pick.kernels import grasp as gk
from mjx_pick.studies.evaluation import half_step

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: real_objects

FREE = mp.GripperSpec(name="test-gripper", force_min_n=0.01)
# rubber and torsion: the solver settings (--solver TOML; None: the defaults)
SOLVER = None
# rubber and torsion: contact settings the candidates start from (--contact TOML)
CONTACT = None


def _centred(obj, grasp, y_mm, gripper=FREE):
    checker = pp.FeasibilityChecker(obj, gripper, grasp=grasp)
    n = len(y_mm)
    return checker.batch(np.arange(n), np.zeros(n), np.asarray(y_mm), np.zeros(n), "user")


def _run(obj, picks, grasp, contact, solver=None, backend="mujoco", **per_pick):
    scene = mp.build_scene(obj, FREE, contact, solver, grasp)
    inputs = make_inputs(scene, grasp, picks, per_pick)
    return Runner(backend, len(picks)).simulate(scene, grasp, inputs).results, scene


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
                out, _ = _run(block, picks, grasp, contact, solver, grip_force_n=force)
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
        full = SOLVER or mp.SolverParams()
        for solver in (full, half_step(full)):
            scene = mp.build_scene(obj, gripper, contact, solver, grasp)
            inputs = make_inputs(scene, grasp, picks)
            outs.append(Runner("mujoco", len(picks)).simulate(scene, grasp, inputs).results)
        a, b = outs
        reasons = collections.Counter(gk.FAILURES[i] for i in a["failure"])
        print(
            f"{label}: success {a['success'].mean():.3f} (dt {full.timestep_s * 1e3:g} ms), "
            f"{b['success'].mean():.3f} (half); "
            f"labels changed {np.mean(a['success'] != b['success']):.2%}; "
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


# --- pad-contact candidates for torsion like rubber (issue 32, item 5) ---------------
# Each candidate rewrites the MJCF text of a scene built with pad_collision "mean_radius"
# (the benchmark's own patch, never the library's): "corners" the whole pad collides
# (MuJoCo's multi-point collider: four overlap corners per pad on a flat face; the
# library's default, pad_contact "pad"), "centre" one contact per pad and object piece
# (MuJoCo's multiccd off: the collider's single point, near the overlap's centre) with
# torsion mu r_mean, "shrunk" the corners with the pad's collision box narrowed to
# 2 r_mean, "square" the library's "mean_radius" box (mjx_pick.core.scene.
# pad_collision_box_mm: 2 r_mean wide and, on a wall taller than that, 2 r_mean tall,
# centred on the wall), "guarded" that box and the whole pad recessed 0.1 mm as a
# frictionless guard, "tiles" a 3 x 3 grid of collision boxes over each pad face with
# one contact each (multiccd off).


def _pad(contact, variant: str):
    """The contact a candidate's scene is built with: the library's "rimmed" pad for the
    "rimmed" candidate, else the "mean_radius" box the XML patches start from."""
    return dataclasses.replace(
        contact, pad_collision="rimmed" if variant == "rimmed" else "mean_radius"
    )


def _xml_with(xml: str, variant: str, mu_t_tile_m=0.0, r_mean_m=0.0) -> str:
    import re

    from real_objects import pad_visual_size, without_multiccd

    if variant in ("square", "rimmed"):  # the library's own "mean_radius" / "rimmed"
        return xml
    if variant == "guarded":
        # the "mean_radius" box, and the whole pad recessed 0.1 mm behind its face as a
        # frictionless guard (condim 1): it meets only a part turned in the grip
        visual = pad_visual_size(xml)
        for side, dx in (("left", -1e-4), ("right", 1e-4)):
            xml = xml.replace(
                f'<geom name="pad_{side}" type="box"',
                f'<geom name="pad_{side}_guard" type="box" size="{visual}" pos="{dx:.9g} 0 0" '
                f'mass="0" group="3"/>\n        <geom name="pad_{side}" type="box"',
                1,
            )
        pair = re.compile(r'<pair name="(pad_left|pad_right)_piece(\d+)" geom1="(\S+)" (.*?)/>')

        def guard(m):
            rest = m[4].replace('condim="4"', 'condim="1"')
            return (
                m[0] + f'\n    <pair name="{m[1]}_guard_piece{m[2]}" geom1="{m[3]}_guard" {rest}/>'
            )

        return pair.sub(guard, xml)
    visual = pad_visual_size(xml)
    hx, hy, hz = (float(v) for v in visual.split())
    pad = re.compile(r'<geom name="(pad_left|pad_right)" type="box" size="([^"]+)" pos="([^"]+)"')

    def whole(m):
        return f'<geom name="{m[1]}" type="box" size="{visual}" pos="0 0 0"'

    xml = pad.sub(whole, xml)
    if variant == "corners":
        return xml
    if variant == "centre":
        return without_multiccd(xml)
    if variant == "shrunk":

        def narrow(m):
            size = f"{hx:.9g} {r_mean_m:.9g} {hz:.9g}"
            return f'<geom name="{m[1]}" type="box" size="{size}" pos="0 0 0"'

        return pad.sub(narrow, xml)
    if variant == "tiles":

        def tile(m):
            return (
                "\n".join(
                    f'<geom name="{m[1]}_t{k}" type="box" '
                    f'size="{hx:.9g} {hy / 3:.9g} {hz / 3:.9g}" '
                    f'pos="0 {2 * jy * hy / 3:.9g} {2 * jz * hz / 3:.9g}" mass="0"/>'
                    for k, (jy, jz) in enumerate((a, b) for a in (-1, 0, 1) for b in (-1, 0, 1))
                )
                + f'\n<geom name="{m[1]}" type="box" size="{m[2]}" pos="0 0 0" contype="0"'
            )

        xml = pad.sub(tile, xml)
        pair = re.compile(
            r'<pair name="(pad_left|pad_right)_piece(\d+)" geom1="(pad_left|pad_right)" (.*?)/>'
        )

        def pairs(m):
            rest = re.sub(
                r'friction="(\S+) (\S+) (\S+) ',
                lambda f: f'friction="{f[1]} {f[2]} {mu_t_tile_m:.9g} ',
                m[4],
            )
            return "\n    ".join(
                f'<pair name="{m[1]}_t{k}_piece{m[2]}" geom1="{m[3]}_t{k}" {rest}/>'
                for k in range(9)
            )

        return without_multiccd(pair.sub(pairs, xml))
    raise ValueError(variant)


def _rod_mesh_part(length_mm, diameter_mm, mass_kg):
    import tempfile
    from pathlib import Path

    import trimesh

    rod = trimesh.creation.cylinder(radius=diameter_mm / 2e3, height=length_mm / 1e3, sections=24)
    rod.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    rod.apply_translation([0, 0, -rod.bounds[0, 2]])
    with tempfile.TemporaryDirectory() as tmp:
        rod.export(Path(tmp) / "rod.stl")
        return mp.object_from_mesh(Path(tmp) / "rod.stl", unit="m", mass_g=mass_kg * 1e3)


def rubber(variants, loads, cases_wanted=None) -> None:
    """Off-centre parts against a uniform-pressure rubber pad: the lever at which each
    part first turns out of the grasp, as a multiple of the rubber pad's lever d_r
    (mjx_pick.core.holding over a uniform patch), per pad-contact candidate and load
    x = m (g + a) / (2 mu F)."""
    from unittest import mock

    from mjx_pick.core import holding, physics
    from mjx_pick.core import scene as scene_mod

    mu = 0.5
    cases = {
        "bar 20x20x200": lambda m: mp.object_from_polygon(
            box(-10, -100, 10, 100), thickness_mm=20, mass_g=m * 1e3
        ),
        "bar 20x40x200": lambda m: mp.object_from_polygon(
            box(-10, -100, 10, 100), thickness_mm=40, mass_g=m * 1e3
        ),
        "plate 20x3x200": lambda m: mp.object_from_polygon(
            box(-10, -100, 10, 100), thickness_mm=3, mass_g=m * 1e3
        ),
        "rod d20x200 lying": lambda m: _rod_mesh_part(200, 20, m),
    }
    mass = {
        "bar 20x20x200": 0.6,
        "bar 20x40x200": 0.6,
        "plate 20x3x200": 0.1,
        "rod d20x200 lying": 0.3,
    }
    factors = np.linspace(0.5, 1.5, 21)
    original = scene_mod.scene_xml
    for label, make in cases.items():
        if cases_wanted and not any(c in label for c in cases_wanted):
            continue
        part = make(mass[label])
        for x in loads:
            grasp0 = mp.GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.5)
            weight = mass[label] * (G + grasp0.lift_accel_mm_s2 * 1e-3)
            force = weight / (2 * mu * x)
            grasp = dataclasses.replace(grasp0, grip_force_n=force)
            contact = dataclasses.replace(
                CONTACT or mp.ContactParams(), pad_friction=mu, pad_collision="mean_radius"
            )
            base = mp.build_scene(part, FREE, contact, SOLVER, grasp)
            w, h = (v * 1e-3 for v in base.pad_patch_mm)
            d_r = holding.hold_limit_m(
                holding.uniform_patch_points(w, h), force, weight, mu, 0.0, "elliptic"
            )
            r_mean = physics.patch_mean_radius_mm(w * 1e3, h * 1e3) * 1e-3
            pad_h = FREE.pad_height_mm * 1e-3
            mu_t_tile = (
                mu * physics.patch_mean_radius_mm(w * 1e3 / 3, min(h, pad_h / 3) * 1e3) * 1e-3
            )
            row = []
            for variant in variants:

                def patched(*a, _v=variant, _t=mu_t_tile, _r=r_mean, **k):
                    return _xml_with(original(*a, **k), _v, _t, _r)

                with mock.patch.object(scene_mod, "scene_xml", patched):
                    picks = _centred(part, grasp, factors * d_r * 1e3)
                    out, scene = _run(part, picks, grasp, _pad(contact, variant), SOLVER)
                ok = out["success"]
                first = factors[np.argmax(~ok)] if (~ok).any() else np.nan
                last = factors[: np.argmax(~ok)][-1] if (~ok).any() and ok[0] else np.nan
                row.append(f"{variant} ({last:.2f}, {first:.2f}] div {int(out['diverged'].sum())}")
            print(
                f"{label}, {mass[label]} kg, x {x:.2f} (F {force:.1f} N), patch "
                f"{w * 1e3:.1f}x{h * 1e3:.1f} mm, d_r {d_r * 1e3:.1f} mm: " + "; ".join(row),
                flush=True,
            )


def _pad_turns(scene, d) -> list[tuple[list[int], np.ndarray, np.ndarray, float]]:
    """Per pad side (the geoms named pad_left*, pad_right*) at the state d: its geoms,
    its main box's centre in its body, the turn (body frame) that would lay the box
    parallel to the gripper's axes, and that turn's angle, deg. The linkage's pads tilt
    as they close; a parametric jaw's stay parallel (0)."""
    import mujoco

    m = scene.model
    grip = d.xmat[scene.index.gripper_body].reshape(3, 3)
    out = []
    for side in ("pad_left", "pad_right"):
        geoms = [g for g in range(m.ngeom) if m.geom(g).name.startswith(side)]
        if side not in {m.geom(g).name for g in geoms}:
            continue  # a pad built otherwise (no main box by that name)
        main = m.geom(side).id
        body = int(m.geom_bodyid[main])
        want = d.xmat[body].reshape(3, 3).T @ grip  # box axes = the gripper's, in the body
        have = np.zeros(9)
        mujoco.mju_quat2Mat(have, m.geom_quat[main])
        turn = want @ have.reshape(3, 3).T  # body frame: have -> want
        angle = np.degrees(np.arccos(np.clip((np.trace(turn) - 1) / 2, -1, 1)))
        out.append((geoms, m.geom_pos[main].copy(), turn, float(angle)))
    return out


def _level_pads(scene, d) -> float:
    """Turn every pad box of an MJCF gripper's scene about its side's main box centre
    so that it lies parallel to the gripper's axes at the state d (the pads closed on
    the part). Changes scene.model; returns the largest tilt removed, deg."""
    import mujoco

    m = scene.model
    turns = _pad_turns(scene, d)
    for geoms, centre, turn, _ in turns:
        for g in geoms:
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, m.geom_quat[g])
            mujoco.mju_mat2Quat(m.geom_quat[g], (turn @ rot.reshape(3, 3)).flatten())
            m.geom_pos[g] = centre + turn @ (m.geom_pos[g] - centre)
    return max((t[3] for t in turns), default=0.0)


# rubber layers for the tilted reference: (Young's modulus Pa, thickness mm), soft to
# hard NBR/silicone pads of 2-4 mm (the 2F-85's own pad is not specified)
RUBBER_LAYERS = ((3e6, 4.0), (6e6, 3.0), (10e6, 2.0))


def tilted_rubber_torque(
    width_mm: float,
    height_mm: float,
    force_n: float,
    tilt_deg: float,
    modulus_pa: float,
    thickness_mm: float,
    mu: float,
    cells: int = 200,
) -> float:
    """Torque (N m) one rubber pad holds about the grip axis when its face is tilted by
    tilt_deg about its width axis against a flat patch of width_mm x height_mm, pressed
    with force_n.

    The layer is a Winkler foundation (the "simple elastic foundation" model of
    non-Hertzian contact, Johnson, Contact Mechanics, 1985, ch. 5): pressure p = K
    max(0, delta - theta s) with K = E / t and s the height above the leading edge;
    delta so that the pressure sums to force_n. The tilt given is a pad's whole turn
    from parallel (the linkage's is about the pad's width axis). The part turns about
    the point c of the patch's centre line where the friction forces cancel, which is
    where mu int p |r - c| dA is least (pure torsion, Coulomb friction sliding
    everywhere). At tilt 0 this is the uniform pad's mu F r_mean. A bonded thin layer
    is stiffer than E / t (Poisson confinement), which narrows the strip further: the
    range of RUBBER_LAYERS spans that."""
    from scipy.optimize import brentq, minimize_scalar

    w, h = width_mm * 1e-3, height_mm * 1e-3
    k = modulus_pa / (thickness_mm * 1e-3)
    theta = np.radians(tilt_deg)
    y = (np.arange(cells) + 0.5) / cells * w - w / 2
    z = (np.arange(cells) + 0.5) / cells * h - h / 2
    yy, zz = np.meshgrid(y, z)
    cell = (w / cells) * (h / cells)
    drop = theta * (zz + h / 2)

    def pressure(delta: float) -> np.ndarray:
        return k * np.clip(delta - drop, 0.0, None)

    delta = brentq(lambda dl: pressure(dl).sum() * cell - force_n, 0.0, 1.0)
    p = pressure(delta)
    best = minimize_scalar(
        lambda zc: (p * np.hypot(yy, zz - zc)).sum() * cell,
        bounds=(-h / 2, h / 2),
        method="bounded",
    )
    return float(mu * best.fun)


def _torsion_capacity(
    scene, picks, force_n: float, gravity: bool, rate: float, level: int = 0
) -> tuple[float, float, list[float]]:
    """(torque N m, mean pad normal force N, each pad's tilt deg before the torque) at
    which a part squeezed by both pads
    starts to turn about the grip axis: the fingers' servos drive to the closed end of
    their range, limited to force_n at the pads; the part (at the one pick of picks)
    hangs clear of the table; a torque about the world x axis (the grip axis) ramps at
    rate N m/s until the part has turned 2 deg (fast enough that the soft contacts'
    creep turns it by much less before it slips). The pads' normal force is read from
    the contacts: the median over the last 0.1 s in which the part had turned less than
    1 deg. An MJCF gripper's one actuator gets the force limit that gives force_n at
    each pad at the part's width (its Kinematics.force_limit_n). level: that many times
    first close on the part, turn the pad boxes parallel to the gripper there
    (:func:`_level_pads`; the pads tilt again under the new contact) and start again."""
    import mujoco

    m, ix, kin = scene.model, scene.index, scene.kinematics
    d = mujoco.MjData(m)
    if not gravity:
        m.opt.gravity[:] = 0.0
    gap_m = 1e-3 * (picks.opening_mm - picks.gap_left_mm - picks.gap_right_mm)
    d.qpos[:] = scene.placement(picks).qpos[0]  # grasp_gap_mm: opening less both gaps
    # the part and the gripper start 5 mm up together, the part clear of the table: a
    # gripper still rising while its pads close would press a curved part's lower flank
    # and wedge it up out of the pad box (onto the rim), which no pick does
    d.qpos[ix.object_qpos + 2] += 0.005
    d.qpos[ix.lift_qpos] += 0.005
    ranges = m.actuator_forcerange.copy()
    for act in {ix.finger_left_actuator, ix.finger_right_actuator}:
        lo, hi = m.actuator_ctrlrange[act]
        if kin is None:
            limit, closed = force_n, hi
        else:
            travel = kin.travel_at_opening(gap_m[0])
            per_pad = np.interp(travel, kin.travel, kin.force_limit_n)
            limit = force_n * np.max(np.abs(m.actuator_forcerange[act])) / per_pad
            ctrl_closed = kin.ctrl_at_zero_length + kin.ctrl_per_length * kin.length[-1]
            ctrl_open = kin.ctrl_at_zero_length + kin.ctrl_per_length * kin.length[0]
            closed = hi if ctrl_closed > ctrl_open else lo
        m.actuator_forcerange[act] = (-limit, limit)
        d.ctrl[act] = closed
    d.ctrl[ix.lift_actuator] = d.qpos[ix.lift_qpos]
    body = ix.object_body
    # the pad side of the pad pairs (the other side is an object piece), less the
    # "guarded" candidate's own geom
    pads = {
        int(g)
        for p in ix.pad_pairs
        for g in (m.pair_geom1[p], m.pair_geom2[p])
        if not m.geom(int(g)).name.startswith("piece")
        and not m.geom(int(g)).name.endswith("_guard")
    }

    def pad_normal_n() -> float:
        f6, total = np.zeros(6), 0.0
        for i, c in enumerate(d.contact[: d.ncon]):
            if int(c.geom[0]) in pads or int(c.geom[1]) in pads:
                mujoco.mj_contactForce(m, d, i, f6)
                total += f6[0]
        return total / 2

    for _ in range(int(0.5 / m.opt.timestep)):  # close and settle
        mujoco.mj_step(m, d)
    if level:
        print(f"  levelled: pads turned by {_level_pads(scene, d):.2f} deg", flush=True)
        m.actuator_forcerange[:] = ranges  # the limits are set again from the originals
        return _torsion_capacity(scene, picks, force_n, gravity, rate, level - 1)
    tilts = [t[3] for t in _pad_turns(scene, d)]
    q0 = d.xquat[body].copy()
    q0_inv = np.array([q0[0], -q0[1], -q0[2], -q0[3]])
    dq = np.zeros(4)
    # the normal force while the part still holds, the median over the last 0.1 s with
    # less than 1 deg of turn: as it breaks loose the pads' forces jump for a few steps
    holding_n = collections.deque([pad_normal_n()], maxlen=int(0.1 / m.opt.timestep))
    for k in range(int(20.0 / m.opt.timestep)):
        d.xfrc_applied[body, 3] = rate * k * m.opt.timestep
        mujoco.mj_step(m, d)
        mujoco.mju_mulQuat(dq, d.xquat[body], q0_inv)
        turn_deg = 2 * np.degrees(np.arccos(min(1.0, abs(dq[0]))))
        if turn_deg > 2.0:
            return float(d.xfrc_applied[body, 3]), float(np.median(holding_n)), tilts
        if turn_deg < 1.0:
            holding_n.append(pad_normal_n())
    return float("nan"), float(np.median(holding_n)), tilts


def torsion(
    variants, ramp_s: float = 0.25, forces=(10.0, 30.0, 100.0), grippers=(FREE.name,)
) -> None:
    """The torque the pads transmit about the grip axis before the part turns, against a
    uniformly pressed rubber pad's 2 mu N r_mean (two pads, each pressed with N, read
    from the contacts; r_mean the patch's mean radius), with no gravity (pure torsion),
    per gripper (the test gripper, or presets with their own pad sizes; forces outside
    a preset's range are left out), pad-contact candidate and force."""
    from mjx_pick.core import scene as scene_mod

    mu = 0.5
    parts = {
        "bar 20x20x200": mp.object_from_polygon(
            box(-10, -100, 10, 100), thickness_mm=20, mass_g=300
        ),
        "bar 20x40x200": mp.object_from_polygon(
            box(-10, -100, 10, 100), thickness_mm=40, mass_g=300
        ),
        "plate 20x3x200": mp.object_from_polygon(
            box(-10, -100, 10, 100), thickness_mm=3, mass_g=50
        ),
        "block 50x30x60": mp.object_from_polygon(
            box(-25, -15, 25, 15), thickness_mm=60, mass_g=300
        ),
        "rod d20x200 lying": _rod_mesh_part(200, 20, 0.3),
    }
    original = scene_mod.scene_xml
    for name in grippers:
        gripper = FREE if name == FREE.name else mp.load_gripper(name)
        for label, part in parts.items():
            for force in forces:
                if not gripper.force_min_n <= force <= gripper.force_max_n:
                    continue  # a force the gripper cannot be set to
                _torsion_row(gripper, label, part, force, variants, ramp_s, mu, original)


def _torsion_row(gripper, label, part, force, variants, ramp_s, mu, original) -> None:
    """One line of :func:`torsion`: one gripper, part and grip force, every variant."""
    from unittest import mock

    from mjx_pick.core import physics
    from mjx_pick.core import scene as scene_mod

    grasp = mp.GraspConfig(grip_force_n=force)
    picks = _centred(part, grasp, [0.0], gripper)
    contact = dataclasses.replace(
        CONTACT or mp.ContactParams(), pad_friction=mu, pad_collision="mean_radius"
    )
    w, h = mp.build_scene(part, gripper, contact, SOLVER, grasp).pad_patch_mm
    r_mean = physics.patch_mean_radius_mm(w, h) * 1e-3
    pad_h = gripper.pad_height_mm
    mu_t_tile = mu * physics.patch_mean_radius_mm(w / 3, min(h, pad_h / 3)) * 1e-3
    ref = 2 * mu * force * r_mean
    row = []
    for variant in variants:
        if gripper.mjcf is not None:
            # an MJCF gripper's pads are built in the scene, not patched in its XML: the
            # library's own choices only ("corners": the gripper's own pad geoms)
            # "levelled": rimmed, the pad boxes turned parallel to the gripper where they
            # close on the part (four passes: the pads tilt again under the new contact)
            mjcf_pads = {
                "corners": "pad",
                "square": "mean_radius",
                "rimmed": "rimmed",
                "levelled": "rimmed",
            }
            if variant not in mjcf_pads:
                row.append(f"{variant} (not for an MJCF gripper)")
                continue
            own = dataclasses.replace(contact, pad_collision=mjcf_pads[variant])
            scene = mp.build_scene(part, gripper, own, SOLVER, grasp)
        else:

            def patched(*a, _v=variant, _t=mu_t_tile, _r=r_mean, **k):
                return _xml_with(original(*a, **k), _v, _t, _r)

            with mock.patch.object(scene_mod, "scene_xml", patched):
                scene = mp.build_scene(part, gripper, _pad(contact, variant), SOLVER, grasp)
        # the rubber pad's torque in ramp_s
        torque, normal, tilts = _torsion_capacity(
            scene, picks, force, False, ref / ramp_s, level=4 if variant == "levelled" else 0
        )
        if normal <= 0:
            row.append(f"{variant} not gripped (no pad force)")
            continue
        cell = f"{variant} {torque / (2 * mu * normal * r_mean):.2f} (N {normal:.1f})"
        if max(tilts, default=0.0) >= 0.005:
            # against rubber pads tilted as these pads are: each pad's torque summed
            tilted = [
                sum(tilted_rubber_torque(w, h, normal, t, e, th, mu) for t in tilts)
                for e, th in RUBBER_LAYERS
            ]
            cell += (
                f" [tilt {'/'.join(f'{t:.2f}' for t in tilts)} deg; against tilted rubber "
                f"{torque / max(tilted):.2f}-{torque / min(tilted):.2f}]"
            )
        row.append(cell)
    print(
        f"{gripper.name}, {label}, F {force:g} N, patch {w:.1f}x{h:.1f} mm, rubber 2 mu F "
        f"r_mean {ref:.3f} N m; engine / rubber: " + ", ".join(row),
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
                grip_force_n=np.array([r[1] for r in rows], np.float32),
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
    ap.add_argument(
        "what", choices=("creep", "convergence", "torque", "coulomb", "rubber", "torsion")
    )
    ap.add_argument("--backend", default="mujoco", help="coulomb: the backend to test")
    ap.add_argument("--variants", default="corners,centre", help="rubber: pad-contact candidates")
    ap.add_argument("--loads", default="0.1,0.25,0.5", help="rubber: loads m (g + a) / (2 mu F)")
    ap.add_argument("--cases", default="", help="rubber: parts whose label contains one of these")
    ap.add_argument("--solver", help="rubber, torsion, convergence: SolverParams TOML")
    ap.add_argument(
        "--ramp-s",
        type=float,
        default=0.25,
        help="torsion: seconds the torque takes to reach the rubber pad's (the slip is read "
        "at 2 deg, so a fast ramp overshoots the static capacity)",
    )
    ap.add_argument("--forces", default="10,30,100", help="torsion: grip forces, N")
    ap.add_argument(
        "--grippers",
        default=FREE.name,
        help=f"torsion: {FREE.name} (the 2F-85's pad on an unlimited drive) or presets",
    )
    ap.add_argument("--contact", help="rubber, torsion: ContactParams TOML to start from")
    args = ap.parse_args()
    if args.solver:
        from mjx_pick.core.config import load_toml

        global SOLVER
        SOLVER = load_toml(mp.SolverParams, args.solver)
    if args.contact:
        from mjx_pick.core.physics import load_contact

        global CONTACT
        CONTACT = load_contact(args.contact)[0]
    if args.what == "coulomb":
        coulomb(args.backend)
    elif args.what == "torsion":
        forces = tuple(float(f) for f in args.forces.split(","))
        torsion(args.variants.split(","), args.ramp_s, forces, args.grippers.split(","))
    elif args.what == "rubber":
        rubber(
            args.variants.split(","),
            [float(v) for v in args.loads.split(",")],
            [c for c in args.cases.split(",") if c],
        )
    else:
        {"creep": creep, "convergence": convergence, "torque": torque}[args.what]()


if __name__ == "__main__":
    main()
