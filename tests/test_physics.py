"""Physics properties that cannot pass by accident (issue 16): Coulomb's law over a
grid of friction, mass and thickness on both engines, the torque a pad holds, force
tracking on stiff and soft contacts, and the grasp-height rule.

Thresholds are theory's (eq. 1 with the lift acceleration), not fitted to the runs.
"""

import itertools
import os

import numpy as np
import pytest
import trimesh
from shapely.geometry import box
from test_preset_physics import PAD_FORCE_MARGIN  # the margin stated for the presets

import mjx_pick as mp
from mjx_pick.core import holding, physics
from mjx_pick.core import pickpoints as pp
from mjx_pick.core import scene as scene_mod
from mjx_pick.core.procedure import G, GraspConfig, fingertip_height_mm
from mjx_pick.engine.backend import make_backend
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.kernels import grasp as gk

# lift 30 mm at the default 2 m/s^2, hold 0.3 s
PROC = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.3)
ACCEL = PROC.lift_accel_mm_s2 * 1e-3
# a test gripper without the 2F-85's 20 N floor, so light parts get their own force
FREE = mp.GripperSpec(name="test-gripper", force_min_n=0.01)


def centred(obj, n, gripper=FREE, grasp=PROC, y_mm=None):
    checker = pp.FeasibilityChecker(obj, gripper, grasp=grasp)
    y = np.zeros(n) if y_mm is None else np.asarray(y_mm, float)
    picks = checker.batch(np.arange(n), np.zeros(n), y, np.zeros(n), mode="user")
    assert len(picks) == n, picks.rejected
    return picks


# the engine the C-engine tests run on; MJX_PICK_TEST_BACKEND=warp runs them on MuJoCo
# Warp on a GPU machine (issue 16: the same properties on every backend)
BACKEND = os.environ.get("MJX_PICK_TEST_BACKEND", "mujoco")


def simulate(
    obj, picks, backend=BACKEND, contact=None, grasp=PROC, record=False, solver=None, **per_pick
):
    scene = mp.build_scene(obj, FREE, contact, solver, grasp)
    runner = make_backend(backend, scene, grasp, batch_size=len(picks))
    out, traces = runner.run(make_inputs(scene, grasp, picks, per_pick), record=record)
    return out, traces, scene


def coulomb_cases(masses, mus):
    """Per pick: friction and F_d at 1.3x the force that holds against m (g + a), and at
    0.8x the force that holds against m g alone (so no force-loop overshoot within
    10 % can hold it), both within a real gripper's reach (0.5-235 N)."""
    rows = []
    for mass, mu in itertools.product(masses, mus):
        need_lift = mass * (G + ACCEL) / (2 * mu)
        need_static = mass * G / (2 * mu)
        for factor, force, holds in ((1.3, 1.3 * need_lift, True), (0.8, 0.8 * need_static, False)):
            if 0.5 <= force <= 235.0:
                rows.append((mass, mu, factor, force, holds))
    return rows


@pytest.mark.parametrize("thickness_mm", [3.0, 20.0, 60.0])
def test_coulomb_grid_on_the_c_engine(thickness_mm):
    masses, mus = (0.01, 0.3, 2.0), (0.05, 0.2, 0.5, 1.0)
    cases = coulomb_cases(masses, mus)
    wrong = []
    for mass in masses:
        rows = [r for r in cases if r[0] == mass]
        block = mp.object_from_polygon(
            box(-25, -15, 25, 15), thickness_mm=thickness_mm, mass_g=mass * 1e3, name="block"
        )
        out, _, _ = simulate(
            block,
            centred(block, len(rows)),
            pad_friction=np.array([r[1] for r in rows], np.float32),
            grip_force_n=np.array([r[3] for r in rows], np.float32),
        )
        for r, ok, fail in zip(rows, out["success"], out["failure"], strict=True):
            if bool(ok) != r[4]:
                wrong.append((r, gk.FAILURES[int(fail)]))
    assert not wrong, wrong


@pytest.mark.mjx
@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="MJX's JAX implementation lets the pads chatter on a part at low pad friction "
    "(0.1: forces alternate 0 / 10-57 N between pads, the block tips over) where MuJoCo C "
    "holds it. Upstream cause (benchmarks/results/history.md, 'Why MJX chatters at low friction'; "
    "benchmarks/probes/mjx_contact_repro.py): MJX-JAX's convex collider makes one edge contact "
    "instead of four on a flat pad, and drops points shallower than 1e-6 m, which is "
    "where a low-friction pyramidal contact settles.",
)
def test_coulomb_on_mjx():
    # MJX (the JAX implementation, the differentiable backend) on one block: friction
    # and force are per-pick data, so the set is one compile. Only the friction that
    # shows the failure above (0.1: the case that must hold and the one that must
    # slip), the smallest run that fails for that reason. Once MJX holds it, strict
    # xfail reports the pass as a failure: then drop the mark and test frictions 0.1,
    # 0.5 and 1.0 again (the set this test ran before it was cut to CI size)
    block = mp.object_from_polygon(box(-25, -15, 25, 15), thickness_mm=20, mass_g=300, name="b")
    rows = coulomb_cases((0.3,), (0.1,))
    out, _, _ = simulate(
        block,
        centred(block, len(rows)),
        backend="mjx",
        contact=mp.ContactParams.differentiable(),  # the physics MJX runs
        solver=mp.SolverParams.differentiable(),
        pad_friction=np.array([r[1] for r in rows], np.float32),
        grip_force_n=np.array([r[3] for r in rows], np.float32),
    )
    got = [(r[1], r[2], bool(s)) for r, s in zip(rows, out["success"], strict=True)]
    assert all(s == r[4] for r, s in zip(rows, out["success"], strict=True)), got
    assert not out["diverged"].any()


def lying_rod(tmp_path, mass_kg):
    """A 200 mm rod of 20 mm diameter lying along y: the pads touch it along a line."""
    rod = trimesh.creation.cylinder(radius=0.01, height=0.2, sections=24)
    rod.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    rod.apply_translation([0, 0, -rod.bounds[0, 2]])
    rod.export(tmp_path / "rod.stl")
    return mp.object_from_mesh(tmp_path / "rod.stl", unit="m", mass_g=mass_kg * 1e3, name="rod")


def torque_case(shape, tmp_path, pad_collision):
    """A 200 mm part, its grasp and its scene: the bar (flat faces) or the lying rod."""
    mass, force, mu = (0.6, 30.0, 0.5) if shape == "bar" else (0.3, 20.0, 0.5)
    if shape == "bar":
        part = mp.object_from_polygon(box(-10, -100, 10, 100), thickness_mm=20, mass_g=mass * 1e3)
    else:
        part = lying_rod(tmp_path, mass)
    grasp = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.5, grip_force_n=force)
    contact = mp.ContactParams(pad_friction=mu, pad_collision=pad_collision)
    scene = mp.build_scene(part, FREE, contact, None, grasp)
    return part, grasp, contact, scene, mass * (G + ACCEL), force, mu


@pytest.mark.parametrize("shape", ["bar", "rod"])
def test_torque_threshold_is_the_capacity_the_model_states(shape, tmp_path):
    # a 200 mm part gripped at distance d from its centre of mass along its length:
    # gravity turns it about the grip axis with m (g + a) d. The model states its
    # capacity before simulating (mjx_pick.core.holding: Coulomb's law at the contact points
    # the collider makes -- four corners on the bar's flat side, two line ends on the
    # rod -- with soft-finger torsion). It must hold at 0.85x that lever and turn out
    # of the grasp at 1.15x: the threshold within 15 % of the stated capacity. With the
    # whole pad colliding (the default) that capacity is 1.5-1.9x a rubber pad's
    # (benchmarks/results/history.md, "Torque"; the rubber pad's test is the next one)
    part, grasp, contact, scene, weight, force, mu = torque_case(shape, tmp_path, "pad")
    points = holding.pad_contacts(scene)
    assert len(points.points_m) == (8 if shape == "bar" else 4)
    d_star = holding.hold_limit_m(
        points, force, weight, mu, scene.contact.pad_torsion_m, scene.solver.cone
    )
    assert 0 < d_star < 0.1  # within the part's half-length
    d = np.array([0.85, 1.15]) * d_star * 1e3  # mm
    out, _, _ = simulate(part, centred(part, 2, grasp=grasp, y_mm=d), contact=contact, grasp=grasp)
    assert out["success"][0], (d, out["phi_max_deg"])
    assert not out["success"][1], (d, out["phi_max_deg"])
    # the torsional coefficient is mu times the contact patch's mean radius
    assert scene.contact.pad_torsion_m == pytest.approx(
        mu * physics.patch_mean_radius_mm(*scene.pad_patch_mm) * 1e-3, rel=1e-6
    )


@pytest.mark.parametrize("shape", ["bar", "rod"])
def test_torque_threshold_is_a_rubber_pads_with_the_default_pad(shape, tmp_path):
    # the same parts with the default pad_collision "rimmed" (each pad collides through a
    # box whose corners sit at the patch's mean radius, the whole pad recessed behind it,
    # out of reach of a flat face or a straight line). The reference is a rubber pad
    # pressed uniformly over the contact patch with isotropic Coulomb friction
    # (mjx_pick.core.holding over a grid of the patch: the limit surface of Goyal, Ruina
    # and Papadopoulos 1991; in pure torsion mu F r_mean). It must hold at 0.8x that
    # pad's lever and turn out of the grasp at 1.2x: the simulated threshold within
    # +-20 % of the rubber pad's; the capacity the model states within 20 % too.
    part, grasp, contact, scene, weight, force, mu = torque_case(shape, tmp_path, "rimmed")
    w, h = (v * 1e-3 for v in scene.pad_patch_mm)
    rubber = holding.hold_limit_m(
        holding.uniform_patch_points(w, h), force, weight, mu, 0.0, "elliptic"
    )
    assert 0 < rubber < 0.1  # within the part's half-length
    points = holding.pad_contacts(scene)
    assert len(points.points_m) == (8 if shape == "bar" else 4)
    d_star = holding.hold_limit_m(
        points, force, weight, mu, scene.contact.pad_torsion_m, scene.solver.cone
    )
    assert d_star == pytest.approx(rubber, rel=0.2)
    d = np.array([0.8, 1.2]) * rubber * 1e3  # mm
    out, _, _ = simulate(part, centred(part, 2, grasp=grasp, y_mm=d), contact=contact, grasp=grasp)
    assert out["success"][0], (d, out["phi_max_deg"])
    assert not out["success"][1], (d, out["phi_max_deg"])


def test_the_rim_grips_a_part_the_pad_box_misses():
    # the shipped 40 x 20 mm block gripped across a corner, 7.5 mm off centre at 23 deg:
    # the pads meet it only under their outer region, where the real 22 mm pad grips it.
    # The box alone (9 mm wide here) barely touches the corner and never reaches the
    # force; the default's rim meets it and holds it as the whole pad does
    block = mp.load_asset("block")
    checker = pp.FeasibilityChecker(block, FREE, grasp=PROC)
    picks = checker.batch(np.arange(1), [0.47], [7.45], [23.2], mode="user")
    assert len(picks) == 1, picks.rejected
    labels = {}
    for pad_collision in ("pad", "mean_radius", "rimmed"):
        contact = mp.ContactParams(pad_friction=0.9, pad_collision=pad_collision)
        out, _, _ = simulate(block, picks, contact=contact)
        labels[pad_collision] = gk.FAILURES[int(out["failure"][0])]
    assert labels["pad"] == "success", labels
    assert labels["mean_radius"] in ("no_contact", "force_not_reached"), labels
    assert labels["rimmed"] == "success", labels


def test_hold_limit_against_closed_forms():
    # one point per pad at the grip axis, no torsion: holds a centred part iff
    # 2 mu F >= W (eq. 1), with no lever at all
    one = holding.PadContacts(np.array([[-0.01, 0, 0], [0.01, 0, 0]]), np.array([0, 1]))
    assert holding.hold_limit_m(one, 10.0, 9.9, 0.5, 0.0) == pytest.approx(0.0, abs=1e-9)
    assert holding.hold_limit_m(one, 10.0, 10.1, 0.5, 0.0) == 0.0  # infeasible
    # with torsion only (soft finger): lever = 2 mu_t F (1 - W / (2 mu F)) / W under the
    # pyramid's shared budget
    mu, mu_t, f, w = 0.5, 0.004, 20.0, 5.0
    expect = 2 * mu_t * f * (1 - w / (2 * mu * f)) / w
    assert holding.hold_limit_m(one, f, w, mu, mu_t) == pytest.approx(expect, rel=1e-6)
    # two points per pad at +-a along y (a line contact) without torsion: the points at
    # +a lift with all their friction (mu F in all), those at -a carry the rest of W
    # (W - mu F): torque a mu F - a (W - mu F) = a (2 mu F - W)
    a = 0.01
    line = holding.PadContacts(
        np.array([[-0.01, -a, 0], [-0.01, a, 0], [0.01, -a, 0], [0.01, a, 0]]),
        np.array([0, 0, 1, 1]),
    )
    got = holding.hold_limit_m(line, f, w, mu, 0.0)
    assert got * w == pytest.approx(a * (2 * mu * f - w), rel=1e-6)
    # the elliptic cone holds more than the pyramid it contains
    assert holding.hold_limit_m(one, f, w, mu, mu_t, "elliptic") > expect


def test_patch_mean_radius_matches_closed_forms():
    r = physics.patch_mean_radius_mm
    assert r(10.0, 0.0) == pytest.approx(2.5, rel=1e-3)  # a line of length L: L / 4
    # a square of side s: s (sqrt(2) + asinh(1)) / 6 = 0.3826 s
    assert r(10.0, 10.0) == pytest.approx(10 * (np.sqrt(2) + np.arcsinh(1)) / 6, rel=1e-3)
    # a w x h rectangle (half sides a, b, half diagonal d): the mean of |r| over it is
    # (d + a^2 / (2 b) ln((b + d) / a) + b^2 / (2 a) ln((a + d) / b)) / 3
    a, b = 11.0, 9.0
    d = np.hypot(a, b)
    closed = (d + a**2 / (2 * b) * np.log((b + d) / a) + b**2 / (2 * a) * np.log((a + d) / b)) / 3
    assert r(2 * a, 2 * b) == pytest.approx(closed, rel=1e-3)


@pytest.mark.parametrize("stiffness", [1e5, 2.0])  # Table 1 (clamped), and a soft pad
def test_force_tracking_while_held(stiffness):
    # held without slipping: the pad force stays within +15 % of F_d, its mean over the
    # hold within +-5 %; never above the gripper's maximum
    block = mp.load_asset("block")
    grasp = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.5)
    contact = mp.ContactParams(pad_stiffness_n_per_mm=stiffness)
    out, traces, _ = simulate(
        block, centred(block, 1, grasp=grasp), contact=contact, grasp=grasp, record=True
    )
    assert out["success"][0] and out["slip_mm"][0] < 2.0
    f = gk.TRACE_FIELDS
    phase = traces[0, :, f.index("phase")]
    grip = (phase == gk.LIFT) | (phase == gk.HOLD)
    hold = phase == gk.HOLD
    for name in ("force_left_n", "force_right_n"):
        force = traces[0, :, f.index(name)]
        assert force[grip].max() <= 1.15 * grasp.grip_force_n, (name, force[grip].max())
        assert abs(force[hold].mean() / grasp.grip_force_n - 1) <= 0.05, force[hold].mean()
    assert max(out["max_force_left_n"][0], out["max_force_right_n"][0]) <= FREE.force_max_n


def test_pad_force_stays_below_the_gripper_maximum_while_a_part_slips():
    # a 4 kg block at pad friction 0.08 slides through the pads at F_d = 200 N (it
    # needs 245 N): before the drive limit, the integrated speed command wound the
    # servo up while the part slid and the pads hit 1.6-3.2x F_d (above 235 N) for
    # as long as it slid. At a time step that resolves the pads' contact transients
    # (0.5 ms) the pad force never passes the maximum. At the default 1 ms one control
    # sample, as the block leaves the pads, reads above it (274 N: the pads' contacts
    # pressed deep for a step reach the rim, as they reach the whole pad; 224 N at
    # 0.5 ms with or without the rim): no sustained excess (the wind-up), and within
    # the margin stated for the presets
    block = mp.object_from_polygon(box(-20, -10, 20, 10), thickness_mm=20, mass_g=4000)
    picks = centred(block, 1)
    contact = mp.ContactParams(pad_friction=0.08)
    f = gk.TRACE_FIELDS
    for solver in (mp.SolverParams(timestep_s=0.0005), mp.SolverParams()):
        scene = mp.build_scene(block, FREE, contact, solver, PROC)
        runner = make_backend(BACKEND, scene, PROC, batch_size=1)
        inputs = make_inputs(scene, PROC, picks, {"grip_force_n": np.float32(200.0)})
        out, traces = runner.run(inputs, record=True)
        assert not out["success"][0]
        peak = max(out["max_force_left_n"][0], out["max_force_right_n"][0])
        if solver.timestep_s < physics.SolverParams().timestep_s:
            assert peak <= FREE.force_max_n, peak
            continue
        assert peak <= (1 + PAD_FORCE_MARGIN) * FREE.force_max_n, peak
        for name in ("force_left_n", "force_right_n"):
            over = traces[0, :, f.index(name)] > FREE.force_max_n
            assert not np.any(over[1:] & over[:-1]), (name, np.flatnonzero(over))


def test_drive_command_never_leads_the_fingers_beyond_the_force_limit():
    # the kernel itself: a pad that reads zero force for a tick while holding (bouncing
    # off a sliding part) must not let the target run ahead of the fingers
    base = GraspConfig(grip_force_n=50.0)
    p = base.params(mp.load_asset("block"), FREE)
    s = gk.initial_state(np.float32(0.02))._replace(phase=np.int32(gk.HOLD))
    m = gk.Measurement(
        force_left=np.float32(0.0),
        force_right=np.float32(0.0),
        force_table=np.float32(0.0),
        finger_left=np.float32(0.02),
        finger_right=np.float32(0.021),
        object_pos=np.zeros(3, np.float32),
        object_quat=np.array([1, 0, 0, 0], np.float32),
        lift=np.float32(0.05),
        speed_max=np.float32(0.0),
        finite=np.bool_(True),
    )
    for _ in range(60):  # 0.3 s at full closing speed would be 15 mm
        s = gk.control_step(p, s, m)
    lead_n = float(s.finger_target - 0.02) * FREE.drive_stiffness_n_per_mm * 1e3
    assert lead_n == pytest.approx(base.force_limit_fraction * 50.0, rel=1e-4)


def test_grasp_height_rule():
    gripper = mp.GripperSpec()  # 38 mm pads
    thin = mp.object_from_polygon(box(0, 0, 30, 30), thickness_mm=5, mass_g=10)
    thick = mp.object_from_polygon(box(0, 0, 30, 30), thickness_mm=60, mass_g=10)
    rule = GraspConfig()
    # pads centred on mid-height where they fit; fingertips near the table otherwise
    assert fingertip_height_mm(thick, gripper, rule) == pytest.approx(30 - 19)
    assert fingertip_height_mm(thin, gripper, rule) == pytest.approx(1.25)  # h / 4 < 2 mm
    paper = GraspConfig(grasp_height="fingertip_mid")
    assert fingertip_height_mm(thin, gripper, paper) == pytest.approx(2.5)
    fixed = mp.object_from_polygon(box(0, 0, 30, 30), thickness_mm=5, mass_g=10, pick_height_mm=4)
    assert fingertip_height_mm(fixed, gripper, rule) == pytest.approx(4.0)
    scene = mp.build_scene(thick, gripper, grasp=rule)
    assert scene.index.pad_bottom_z0_m == pytest.approx(0.011)
    with pytest.raises(mp.ConfigError, match="grasp_height"):
        GraspConfig(grasp_height="top")


def test_checks_see_only_what_is_above_the_fingertips(tmp_path):
    # an L-part standing on its edge: a 60 x 5 mm foot on the table, a 10 x 40 mm leg
    # up, 20 mm deep. Fingertips at half height (the paper's rule) are above the foot:
    # the checks must not offer pick-points on the foot, whose pads would touch nothing
    import trimesh
    from shapely.geometry import Polygon

    ell = Polygon([(0, 0), (60, 0), (60, 5), (10, 5), (10, 40), (0, 40)])
    mesh = trimesh.creation.extrude_polygon(ell, 20.0)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    path = tmp_path / "ell.stl"
    mesh.export(path)
    obj = mp.load_object(path, unit="mm", mass_g=30)
    assert obj.height_mm == pytest.approx(40.0, abs=0.01)
    assert obj.polygon.area == pytest.approx(60 * 20, rel=0.02)  # the whole shadow
    paper = GraspConfig(
        grasp_height="fingertip_mid", close_timeout_s=1.0, lift_height_mm=30, hold_s=0.2
    )
    gripper = mp.GripperSpec()
    checker = pp.FeasibilityChecker(obj, gripper, grasp=paper)
    assert checker.silhouette.area == pytest.approx(10 * 20, rel=0.05)  # the leg only
    picks = pp.generate_normal(obj, gripper, 6, seed=0, grasp=paper)
    scene = mp.build_scene(obj, gripper, grasp=paper)
    out, _ = make_backend("mujoco", scene, paper, 6).run(make_inputs(scene, paper, picks))
    assert not np.any(out["failure"] == gk.FAILURES.index("no_contact")), out["failure"]


def test_noslip_setting_reaches_the_model_and_is_refused_where_unsupported():
    block = mp.object_from_polygon(box(-25, -15, 25, 15), thickness_mm=20, mass_g=300)
    scene = mp.build_scene(block, FREE, None, mp.SolverParams(noslip_iterations=5), PROC)
    assert scene.model.opt.noslip_iterations == 5
    with pytest.raises(mp.ConfigError, match="noslip_iterations"):
        mp.SolverParams(noslip_iterations=-1)
    # MJX has no no-slip solver: the 'mjx' backend refuses it with the rest of what
    # differs from the differentiable physics it runs
    with pytest.raises(mp.ConfigError, match="solver.noslip_iterations = 5"):
        make_backend("mjx", scene, PROC, batch_size=1)


@pytest.mark.parametrize("pad_collision", ["mean_radius", "rimmed"])
def test_pad_box_reaches_the_model_and_is_checked(pad_collision):
    block = mp.object_from_polygon(box(-25, -15, 25, 15), thickness_mm=20, mass_g=300)
    contact = mp.ContactParams(pad_collision=pad_collision)
    assert mp.ContactParams().pad_collision == "rimmed"  # the default
    pyramid = mp.SolverParams(cone="pyramidal", impratio=1.0)
    for solver in (pyramid, mp.SolverParams()):  # the default: elliptic cones
        scene = mp.build_scene(block, FREE, contact, solver, PROC)
        m = scene.model
        half_w, half_h, dz = scene_mod.pad_collision_box_mm(block, FREE, PROC, solver.cone)
        r = physics.patch_mean_radius_mm(*scene.pad_patch_mm)
        mu_t = scene.contact.pad_friction * r * 1e-3
        if solver.cone == "pyramidal":
            # corners at the patch's mean radius in the pyramid's norm, max(|a|, |b|);
            # each point keeps the rubber pad's torsion mu r_mean
            assert (half_w, half_h) == pytest.approx((r, r))
            assert scene.contact.pad_torsion_m == pytest.approx(mu_t, rel=1e-6)
        else:
            # elliptic cones: corners at Euclidean r_mean cos(theta), and each point keeps
            # mu r_mean sin(theta): in pure torsion sqrt(cos^2 + sin^2) mu N r_mean
            share = physics.ELLIPTIC_TORSION_SHARE
            assert np.hypot(half_w, half_h) == pytest.approx(r * np.sqrt(1 - share**2))
            assert scene.contact.pad_torsion_m == pytest.approx(share * mu_t, rel=1e-6)
        assert m.geom("pad_left").size[1:] * 1e3 == pytest.approx([half_w, half_h])
        assert m.geom("pad_left").pos[2] * 1e3 == pytest.approx(dz)
        # the pad as built keeps the gripper's size and the finger's mass, colliding with
        # nothing
        visual = m.geom("pad_left_visual")
        assert visual.size[1:] * 1e3 == pytest.approx(
            [FREE.finger_width_mm / 2, FREE.pad_height_mm / 2]
        )
        assert visual.contype[0] == 0 and visual.conaffinity[0] == 0
        # "rimmed": the whole pad, its face recessed behind the box's, pairs with the part
        # as the box does; "mean_radius": the box alone
        rims = [m.geom(g).name for g in range(m.ngeom) if m.geom(g).name.endswith("_rim")]
        pairs = [m.pair(i).name for i in scene.index.pad_pairs]
        if pad_collision == "rimmed":
            assert rims == ["pad_left_rim", "pad_right_rim"]
            rim = m.geom("pad_left_rim")
            recess = visual.size[0] - rim.size[0]
            assert recess * 1e3 == pytest.approx(physics.PAD_RIM_RECESS_MM)
            assert rim.size[1:] == pytest.approx(visual.size[1:])
            assert sorted(pairs) == sorted(
                f"pad_{side}{rim}_piece0" for side in ("left", "right") for rim in ("", "_rim")
            )
        else:
            assert rims == [] and sorted(pairs) == ["pad_left_piece0", "pad_right_piece0"]
    # "pad": the whole pad collides, with the full torsion on every cone
    whole_contact = mp.ContactParams(pad_collision="pad")
    whole = mp.build_scene(block, FREE, whole_contact, None, PROC)
    assert whole.model.geom("pad_left").size[1:] * 1e3 == pytest.approx(
        [FREE.finger_width_mm / 2, FREE.pad_height_mm / 2]
    )
    r = physics.patch_mean_radius_mm(*whole.pad_patch_mm)
    assert whole.contact.pad_torsion_m == pytest.approx(
        whole.contact.pad_friction * r * 1e-3, rel=1e-6
    )
    with pytest.raises(mp.ConfigError, match="pad_collision"):
        mp.ContactParams(pad_collision="disc")
