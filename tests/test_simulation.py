"""Physics must be trustworthy: Coulomb's law, time-step convergence, known grasps,
force regulation, metrics on hand-made traces, and no recompiles."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.backend import make_backend
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.kernels import grasp as gk

# a short procedure for tests: lift 30 mm, hold 0.3 s
FAST = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.3)
LIGHT_GRIPPER = mp.GripperSpec(name="test-gripper", force_min_n=1.0)


def single_picks(obj, gripper, x, y, yaw):
    checker = pp.FeasibilityChecker(obj, gripper)
    x, y, yaw = (np.atleast_1d(np.asarray(v, float)) for v in (x, y, yaw))
    return checker.batch(np.arange(len(x)), x, y, yaw, mode="user")


def run(obj, gripper, picks, grasp=FAST, solver=None, contact=None, record=False, **overrides):
    scene = mp.build_scene(obj, gripper, contact, solver)
    backend = make_backend("mujoco", scene, grasp, batch_size=max(len(picks), 1))
    return backend.run(make_inputs(scene, grasp, picks, overrides), record=record)


def test_coulomb_minimum_force_matches_theory():
    # a heavy block grasped at its centre with pad friction mu lifts and holds iff
    # 2 mu F_d >= m (g + a_lift): sweep F_d around that in one batch
    mu, mass, accel = 0.5, 2.0, 2.0
    block = mp.object_from_polygon(
        box(-20, -10, 20, 10), thickness_mm=20, mass_g=mass * 1e3, name="heavy_block"
    )
    grasp = dataclasses.replace(
        FAST, lift_accel_mm_s2=accel * 1e3, lift_height_mm=100.0, hold_s=0.5
    )
    theory = mass * (9.81 + accel) / (2 * mu)
    factors = np.linspace(0.7, 1.4, 15)
    picks = single_picks(block, LIGHT_GRIPPER, np.zeros(15), np.zeros(15), np.zeros(15))
    out, _ = run(
        block,
        LIGHT_GRIPPER,
        picks,
        grasp,
        contact=mp.ContactParams(pad_friction=mu),
        grip_force_n=factors * theory,
    )
    ok = out["success"]
    assert ok[factors >= 1.1 - 1e-9].all(), (factors.round(2), ok)
    assert not ok[factors <= 0.9 + 1e-9].any(), (factors.round(2), ok)
    smallest = factors[np.argmax(ok)] * theory
    assert smallest == pytest.approx(theory, rel=0.10)


def test_centred_block_grasp_is_clean(block):
    picks = single_picks(block, mp.GripperSpec(), 0.0, 0.0, 0.0)
    out, traces = run(block, mp.GripperSpec(), picks, record=True)
    assert out["success"][0] and not out["diverged"][0]
    assert out["phi_max_deg"][0] < 2.0
    assert out["score"][0] > 0.9
    # force regulation during the hold: both pads within +-10% of F_d
    phase = traces[0, :, gk.TRACE_FIELDS.index("phase")]
    hold = phase == gk.HOLD
    assert hold.sum() > 20
    for name in ("force_left_n", "force_right_n"):
        f = traces[0, hold, gk.TRACE_FIELDS.index(name)]
        assert np.all(np.abs(f - FAST.grip_force_n) <= 0.1 * FAST.grip_force_n), (
            name,
            f.min(),
            f.max(),
        )


def test_off_centre_bar_with_low_friction_rotates_and_scores_lower():
    # friction torque of the pads' contact patches (~2 mu F r, r ~ 8 mm) is ~0.06 N m;
    # gravity's torque 45 mm from the centre of mass is ~0.13 N m: the bar swings
    bar = mp.object_from_polygon(box(-60, -5, 60, 5), thickness_mm=10, mass_g=300, name="bar")
    gripper = mp.GripperSpec()
    # yaw 90: the bar lies across the closing axis; y = 45 grips it 45 mm from its centre
    picks = single_picks(bar, gripper, [0.0, 0.0], [0.0, 45.0], [90.0, 90.0])
    assert len(picks) == 2
    grasp = dataclasses.replace(FAST, grip_force_n=20.0)
    out, _ = run(bar, gripper, picks, grasp, contact=mp.ContactParams(pad_friction=0.2))
    assert out["phi_max_deg"][1] > 10 * max(out["phi_max_deg"][0], 0.5)
    assert out["score"][1] < out["score"][0]


def test_timestep_convergence_on_door_opener(door_opener):
    # halving the time step (same contact, time constant fixed in seconds) may change
    # at most 2% of the success labels
    gripper = mp.load_gripper("robotiq-2f85")
    picks = pp.generate_normal(door_opener, gripper, 256, seed=0)
    base = mp.SolverParams()
    a, _ = run(door_opener, gripper, picks, GraspConfig(), solver=base)
    b, _ = run(
        door_opener,
        gripper,
        picks,
        GraspConfig(),
        solver=dataclasses.replace(base, timestep_s=base.timestep_s / 2),
    )
    changed = np.mean(a["success"] != b["success"])
    assert changed <= 0.02, f"{changed:.3%} of labels changed"
    assert not a["diverged"].any() and not b["diverged"].any()


def test_gripper_settings_out_of_range():
    g = mp.GripperSpec()
    with pytest.raises(mp.ConfigError, match="grip_force_n = 300 is out of range"):
        GraspConfig(grip_force_n=300).check_gripper(g)
    with pytest.raises(mp.ConfigError, match="kp_mm_s_per_n = -1"):
        GraspConfig(kp_mm_s_per_n=-1)
    with pytest.raises(mp.ConfigError, match="lift_height_mm = 0"):
        GraspConfig(lift_height_mm=0)
    with pytest.raises(mp.ConfigError, match="whole multiple"):
        GraspConfig(control_period_s=0.0045).substeps(mp.SolverParams())


# ------------------------------------------------------------------ metrics by hand


def _params(**kw):
    base = GraspConfig(
        lift_height_mm=100, lift_speed_mm_s=200, lift_accel_mm_s2=2000, hold_s=0.4, grip_force_n=50
    )
    obj = mp.object_from_polygon(box(0, 0, 10, 10), thickness_mm=5, mass_g=10)
    p = base.params(obj, mp.GripperSpec())
    return p._replace(**{k: jnp.float32(v) for k, v in kw.items()})


def _replay(p, phases, forces, table, z, quats):
    """Feed hand-made per-tick measurements through accumulate; phases drive s/s_next."""
    a = gk.initial_accumulators(jnp.float32(0))
    pos0, quat0 = jnp.zeros(3), jnp.array([1.0, 0, 0, 0])
    for k in range(len(phases) - 1):
        s = gk.initial_state(jnp.float32(0))._replace(phase=jnp.int32(phases[k]))
        s_next = s._replace(phase=jnp.int32(phases[k + 1]))
        m = gk.Measurement(
            force_left=jnp.float32(forces[k][0]),
            force_right=jnp.float32(forces[k][1]),
            force_table=jnp.float32(table[k]),
            finger_left=jnp.float32(0.01),
            finger_right=jnp.float32(0.01),
            object_pos=jnp.array([0.0, 0.0, z[k]]),
            object_quat=jnp.asarray(quats[k], jnp.float32),
            lift=jnp.float32(z[k]),
            speed_max=jnp.float32(0.0),
            finite=jnp.bool_(True),
        )
        a = gk.accumulate(p, a, s, s_next, m, pos0, quat0)
    return {k: np.asarray(v) for k, v in gk.finalize(p, a).items()}


def test_metrics_on_a_hand_made_success():
    p = _params()
    dt = float(p.dt)
    window = float(gk.lift_duration(p)) + 0.4  # 0.6 s lift + 0.4 s hold
    n_close, n_lift, n_hold = 10, int(round(0.6 / dt)), int(round(0.4 / dt))
    phases = [gk.CLOSE] * n_close + [gk.LIFT] * n_lift + [gk.HOLD] * n_hold + [gk.DONE]
    forces = [(50.0, 50.0)] * len(phases)
    # on the table for the first 0.1 s of the lift, then off; yaw turns by 10 deg
    table = [0.1] * (n_close + 20) + [0.0] * (len(phases) - n_close - 20)
    z = [0.0] * n_close + list(np.linspace(0, 0.1, n_lift)) + [0.1] * (n_hold + 1)
    yaw = np.deg2rad(10.0)
    quats = [[1, 0, 0, 0]] * n_close + [[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]] * (
        len(phases) - n_close
    )
    out = _replay(p, phases, forces, table, z, quats)
    # the window runs from the first LIFT tick to the last HOLD tick: held throughout,
    # off the table for all but its first 20 ticks
    t_grasp = (n_lift + n_hold) * dt / window
    t_nc = (n_lift + n_hold - 20) * dt / window
    assert t_grasp == pytest.approx(1.0) and t_nc == pytest.approx(0.9)
    assert out["t_grasp"] == pytest.approx(t_grasp, abs=1e-4)
    assert out["t_grasp_nc"] == pytest.approx(t_nc, abs=1e-4)
    assert out["phi_max_deg"] == pytest.approx(10.0, abs=1e-3)
    assert out["score"] == pytest.approx((t_grasp + 170 / 180 + t_nc) / 3, abs=1e-4)
    assert bool(out["success"]) and gk.FAILURES[int(out["failure"])] == "success"
    # lifted the whole 100 mm (height margin 1) and turned 10 of the 45 deg allowed
    assert out["rotation_final_deg"] == pytest.approx(10.0, abs=1e-3)
    assert out["label_margin"] == pytest.approx(35 / 45, abs=1e-4)


def test_label_margin_has_the_labels_sign_and_measures_the_closer_threshold():
    """Where a label is judged (force reached, hold ended, no blow-up), success is
    exactly label_margin >= 0, the thresholds themselves included; each margin is its
    quantity's distance from the threshold over the tolerance (10 mm of a 100 mm lift at
    the 0.9 default, 45 deg)."""
    p = _params()
    high, max_rot = 0.09, float(p.max_rotation_rad)
    a0 = gk.initial_accumulators(jnp.float32(0))._replace(
        reached=jnp.bool_(True), finished=jnp.bool_(True), table_final=jnp.bool_(False)
    )
    cases = [  # (final lift m, final rotation rad, table at the end, margin)
        (0.1, 0.0, False, 1.0),
        (0.095, 0.0, False, 0.5),
        (high, 0.0, False, 0.0),
        (0.08, 0.0, False, -1.0),
        (0.1, max_rot, False, 0.0),
        (0.1, 0.5 * max_rot, False, 0.5),
        (0.099, 0.5 * max_rot, False, 0.5),  # the rotation decides: 0.5 < 0.9
        (0.1, 1.5 * max_rot, False, -0.5),
        (0.1, 0.0, True, -9.0),  # still on the table: not lifted
    ]
    for lift, rot, table, want in cases:
        a = a0._replace(
            lift_final=jnp.float32(lift),
            rot_final=jnp.float32(rot),
            table_final=jnp.bool_(table),
        )
        out = gk.finalize(p, a)
        margin = float(out["label_margin"])
        assert margin == pytest.approx(want, abs=2e-3), (lift, rot, table)
        assert bool(out["success"]) == (margin >= 0), (lift, rot, table, margin)
    # no judgement where the force was never reached, the hold never ended, or it blew up
    for unjudged in (
        a0._replace(reached=jnp.bool_(False)),
        a0._replace(finished=jnp.bool_(False)),
        a0._replace(diverged=jnp.bool_(True)),
    ):
        assert np.isnan(float(gk.finalize(p, unjudged)["label_margin"]))


def test_metrics_on_hand_made_failures():
    p = _params()
    # never reaches F_d, never touches: no_contact; touches below F_d: force_not_reached
    out = _replay(
        p,
        [gk.CLOSE] * 50 + [gk.DONE],
        [(0.0, 0.0)] * 51,
        [0.1] * 51,
        [0.0] * 51,
        [[1, 0, 0, 0]] * 51,
    )
    assert gk.FAILURES[int(out["failure"])] == "no_contact" and out["t_grasp"] == 0
    out = _replay(
        p,
        [gk.CLOSE] * 50 + [gk.DONE],
        [(10.0, 12.0)] * 51,
        [0.1] * 51,
        [0.0] * 51,
        [[1, 0, 0, 0]] * 51,
    )
    assert gk.FAILURES[int(out["failure"])] == "force_not_reached"
    # grip lost halfway through the hold and the object falls back: dropped_in_hold
    phases = [gk.CLOSE] * 5 + [gk.LIFT] * 120 + [gk.HOLD] * 80 + [gk.DONE]
    forces = [(50.0, 50.0)] * 165 + [(0.0, 0.0)] * 41
    z = [0.0] * 5 + list(np.linspace(0, 0.1, 120)) + [0.1] * 40 + [0.0] * 41
    table = [0.1] * 5 + [0.0] * 160 + [0.1] * 41
    out = _replay(p, phases, forces, table, z, [[1, 0, 0, 0]] * 206)
    assert gk.FAILURES[int(out["failure"])] == "dropped_in_hold"
    assert out["label_margin"] == pytest.approx(-9.0)  # back on the table: 90 mm short
    assert out["t_grasp"] == pytest.approx(160 * 0.005 / 1.0, abs=1e-4)  # held 160 ticks
    # a NaN state is flagged diverged and never scored
    a = gk.initial_accumulators(jnp.float32(0))
    s = gk.initial_state(jnp.float32(0))._replace(phase=jnp.int32(gk.CLOSE))
    m = gk.Measurement(
        *[jnp.float32(0)] * 5,
        jnp.zeros(3),
        jnp.array([1.0, 0, 0, 0]),
        jnp.float32(0),
        jnp.float32(0),
        jnp.bool_(False),
    )
    a = gk.accumulate(p, a, s, s, m, jnp.zeros(3), jnp.array([1.0, 0, 0, 0]))
    out = gk.finalize(p, a)
    assert bool(out["diverged"]) and np.isnan(float(out["score"]))
    assert gk.FAILURES[int(out["failure"])] == "diverged" and not bool(out["success"])


# --------------------------------------------------------------------- no recompiles


def test_second_batch_of_same_shape_does_not_compile(block, count_compiles):
    # the C backend here; the sharded MJX backend in tests/test_scale.py
    gripper = mp.GripperSpec()
    grasp = dataclasses.replace(FAST, close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)
    scene = mp.build_scene(block, gripper)
    backend = make_backend("mujoco", scene, grasp, batch_size=4)
    picks = pp.generate_normal(block, gripper, 8, seed=0)
    first, second = picks.take(slice(0, 4)), picks.take(slice(4, 8))
    backend.run(make_inputs(scene, grasp, first))
    n = count_compiles(lambda: backend.run(make_inputs(scene, grasp, second)))
    assert n == 0, f"{n} compilations on the second batch"
