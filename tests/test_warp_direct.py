"""The MuJoCo Warp backend on Warp's CPU device: its controller kernels against the JAX
reference (kernels.grasp), the pool's bookkeeping, and a few picks end to end against
the C engine.

The GPU figures (throughput, labels against MuJoCo C at scale) come from
benchmarks/throughput.py and benchmarks/real_objects.py; here the same code runs on the
CPU, kernel by kernel (no CUDA graphs).
"""

import jax
import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.backend import addresses, make_inputs
from mjx_pick.kernels import grasp as gk

wp = pytest.importorskip("warp")
pytest.importorskip("mujoco_warp")

from mjx_pick.engine import warp_direct as wd  # noqa: E402
from mjx_pick.engine import warp_kernels  # noqa: E402
from mjx_pick.kernels import grasp_warp as gw  # noqa: E402

SHORT = GraspConfig(close_timeout_s=0.6, lift_height_mm=10.0, hold_s=0.1)
# float32 arithmetic in another order (XLA's fused kernels, Warp's LLVM build): a few
# units in the last place of each quantity, more where a difference of close numbers is
# divided (the force-controller step) -- far below anything a label depends on
RTOL, ATOL = 1e-5, 1e-6
# angles from acos near 1 (a quaternion's rotation, a tilt): d acos / dc = -1/sqrt(1-c^2)
# turns one float32 step of c into up to ~1e-5 rad at the small angles of a held part
ANGLE_ATOL = 3e-5
ANGLES = {
    "phi_max",
    "yaw_max",
    "tilt_max",
    "rot_final",
    "phi_max_deg",
    "yaw_max_deg",
    "tilt_max_deg",
    "rotation_final_deg",
    "score",
    "label_margin",
}


@pytest.fixture(autouse=True)
def warp_on_cpu(monkeypatch):
    monkeypatch.setenv(wd.ALLOW_CPU_ENV, "1")


@pytest.fixture(scope="module")
def block_scene():
    return mp.build_scene(mp.load_object("block"), mp.GripperSpec(), grasp=SHORT)


@pytest.fixture(scope="module")
def linkage_scene():
    return mp.build_scene(
        mp.load_object("block"), mp.load_gripper("robotiq-2f85-linkage"), grasp=SHORT
    )


def _random_states(scene, n: int, seed: int):
    """n random controller states, accumulators and measurements around a pick's
    phases (every phase, touching and not, reached and not), as the JAX NamedTuples."""
    rng = np.random.default_rng(seed)
    m = scene.model
    f32 = np.float32
    picks = pp.generate_normal(scene.object, scene.gripper, n, seed=seed, grasp=SHORT)
    inputs = make_inputs(scene, SHORT, picks)
    params = inputs.params._replace(
        reach_settle_s=rng.choice([0.0, 0.02], n).astype(f32),
        dwell_s=rng.choice([0.0, 0.01], n).astype(f32),
    )
    qpos = inputs.qpos0 + rng.normal(0, 2e-3, (n, m.nq)).astype(f32)
    qvel = rng.normal(0, 0.05, (n, m.nv)).astype(f32)
    qvel[::17, 0] = 1e3  # a blow-up now and then
    qpos[::23, 1] = np.nan
    fg = float(inputs.params.grip_force_n[0])
    cfrc = rng.normal(0, 1, (n, m.nbody, 6)).astype(f32)
    ad = addresses(scene)
    cfrc[:, ad.finger_left_body, 3] = -rng.uniform(0, 1.5 * fg, n)
    cfrc[:, ad.finger_right_body, 3] = rng.uniform(0, 1.5 * fg, n)
    s, a = jax.vmap(lambda q: gk.initial(ad, q))(inputs.qpos0)
    s = jax.tree.map(np.asarray, s)
    a = jax.tree.map(np.asarray, a)
    phase = rng.integers(0, 6, n).astype(np.int32)
    s = s._replace(
        phase=phase,
        t_phase=rng.uniform(0, 0.7, n).astype(f32),
        lift_target=(s.lift_start + rng.uniform(0, 0.012, n)).astype(f32),
        lift_velocity=rng.uniform(0, 0.05, n).astype(f32),
        t_steady=rng.uniform(0, 0.03, n).astype(f32),
    )
    bools = lambda: rng.random(n) < 0.5
    a = a._replace(
        contact_seen=bools(),
        reached=bools(),
        held=bools(),
        touch_left=bools(),
        touch_right=bools(),
        lost_left=bools(),
        lost_right=bools(),
        finished=bools(),
        t=rng.uniform(0, 1, n).astype(f32),
        held_time=rng.uniform(0, 0.3, n).astype(f32),
        off_table_time=rng.uniform(0, 0.3, n).astype(f32),
        phi_max=rng.uniform(0, 0.5, n).astype(f32),
        lift_after_lift=rng.uniform(0, 0.012, n).astype(f32),
        table_after_lift=bools(),
        lift_final=rng.uniform(0, 0.012, n).astype(f32),
        table_final=bools(),
        rot_final=rng.uniform(0, 0.5, n).astype(f32),
        chatter=rng.integers(0, 3, n).astype(f32),
    )
    return inputs, params, s, a, qpos, qvel, cfrc


def _compare(name, ref, got):
    ref = np.asarray(ref)
    got = np.asarray(got)
    if ref.dtype == bool or got.dtype == bool or ref.dtype.kind == "i":
        np.testing.assert_array_equal(got.astype(ref.dtype), ref, err_msg=name)
        return
    atol = ATOL
    if name.split(".")[-1] in ANGLES:
        atol = np.rad2deg(ANGLE_ATOL) if name.endswith("_deg") else ANGLE_ATOL
    np.testing.assert_allclose(got, ref, rtol=RTOL, atol=atol, err_msg=name, equal_nan=True)


@pytest.mark.parametrize("scene_name", ["block_scene", "linkage_scene"])
def test_tick_kernel_matches_the_jax_reference(scene_name, request):
    """One control tick of 256 random states: the next control state, accumulators,
    actuator commands and trace rows of the Warp kernel equal kernels.grasp.tick's (the
    linkage runs its DriveMap tables)."""
    scene = request.getfixturevalue(scene_name)
    n = 256
    inputs, params, s, a, qpos, qvel, cfrc = _random_states(scene, n, seed=1)
    ad = addresses(scene)
    o = ad.object_qpos
    pos0, quat0 = inputs.qpos0[:, o : o + 3], inputs.qpos0[:, o + 3 : o + 7]
    vtick = jax.vmap(gk.tick, in_axes=(0, None, 0, 0, 0, 0, 0, 0, 0))
    s_ref, a_ref, ctrl_ref, row_ref = jax.jit(lambda *x: vtick(x[0], ad, *x[1:]))(
        params, s, a, qpos, qvel, cfrc, pos0, quat0
    )

    dev = "cpu"
    with wp.ScopedDevice(dev):
        n_ticks = SHORT.n_ticks()
        k = wp.array(np.zeros(n, np.int32), dtype=int)
        ctl = gw.to_struct_array(s, gw.Control, dev)
        acc = gw.to_struct_array(a, gw.Acc, dev)
        ctrl = wp.zeros((n, scene.model.nu), dtype=float)
        trace = wp.zeros((n, n_ticks, gw.NTRACE), dtype=float)
        wp.launch(
            warp_kernels.tick,
            dim=n,
            inputs=[
                gw.addresses(ad),
                gw.drive(ad, dev),
                n_ticks,
                1,
                gw.to_struct_array(params, gw.Params, dev),
                ctl,
                acc,
                wp.array(pos0, dtype=wp.vec3),
                wp.array(quat0, dtype=wp.vec4),
                k,
                wp.zeros(n, dtype=int),
                wp.array(qpos, dtype=float),
                wp.array(qvel, dtype=float),
                wp.array(cfrc, dtype=wp.spatial_vector),
                ctrl,
                trace,
            ],
        )
    # a state that was already finished (DONE, diverged) keeps everything as it was
    finished = (np.asarray(s.phase) == gk.DONE) | np.asarray(a.diverged)
    got_s, got_a = gw.from_struct_array(ctl), gw.from_struct_array(acc)
    for f in gk.ControlState._fields:
        ref = np.where(finished, getattr(s, f), getattr(s_ref, f))
        _compare(f"control.{f}", ref, got_s[f])
    for f in gk.Accumulators._fields:
        ref = np.where(finished, getattr(a, f), getattr(a_ref, f))
        _compare(f"acc.{f}", ref, got_a[f])
    live = ~finished
    assert live.sum() > n // 2
    _compare("ctrl", np.asarray(ctrl_ref)[live], ctrl.numpy()[live])
    _compare("trace", np.asarray(row_ref)[live], trace.numpy()[live, 0])
    np.testing.assert_array_equal(k.numpy(), live.astype(np.int32))


def test_finalize_kernel_matches_the_jax_reference(block_scene):
    n = 512
    inputs, params, _, a, *_ = _random_states(block_scene, n, seed=2)
    rng = np.random.default_rng(3)
    a = a._replace(diverged=rng.random(n) < 0.1, t_reached=rng.uniform(-1, 1, n).astype("f4"))
    ref = jax.jit(jax.vmap(gk.finalize))(params, a)
    with wp.ScopedDevice("cpu"):
        out = wp.zeros(n, dtype=gw.Result)
        wp.launch(
            warp_kernels.finalize,
            dim=n,
            inputs=[
                gw.to_struct_array(params, gw.Params, "cpu"),
                gw.to_struct_array(a, gw.Acc, "cpu"),
                out,
            ],
        )
    got = wd._typed(gw.from_struct_array(out))
    assert set(got) == set(ref) == set(wd.RESULT_FIELDS)
    for name in wd.RESULT_FIELDS:
        assert got[name].dtype == np.asarray(ref[name]).dtype, name
        _compare(name, ref[name], got[name])


def test_refill_hands_out_picks_in_slot_order():
    slot_pick = np.array([0, 1, 2, 3])
    ended = np.array([False, True, False, True])
    new, fresh, nxt = wd.refill_order(slot_pick, ended, 4, 5)
    np.testing.assert_array_equal(new, [0, 4, 2, -1])
    np.testing.assert_array_equal(fresh, [False, True, False, False])
    assert nxt == 5
    # an idle slot (-1) never "ends" again; the queue stays empty
    new, fresh, nxt = wd.refill_order(new, np.array([True, False, False, True]), nxt, 5)
    np.testing.assert_array_equal(new, [-1, 4, 2, -1])
    assert not fresh.any() and nxt == 5


def test_traces_are_held_after_a_picks_end():
    t, f = 6, len(gk.TRACE_FIELDS)
    rows = np.arange(2 * t * f, dtype=np.float32).reshape(2, t, f)
    out = wd.pad_traces(rows, np.array([3, 6]), np.array([gk.DONE, gk.HOLD]), SHORT)
    tcol, pcol = gk.TRACE_FIELDS.index("t_s"), gk.TRACE_FIELDS.index("phase")
    np.testing.assert_array_equal(out[1], rows[1])  # ran every tick: untouched
    np.testing.assert_array_equal(out[0, 3:, 1], rows[0, 2, 1])
    np.testing.assert_allclose(np.diff(out[0, 2:, tcol]), SHORT.control_period_s, rtol=1e-3)
    assert (out[0, 3:, pcol] == gk.DONE).all()


def test_carried_fields_are_what_warp_holds_per_world():
    fields = wd.carried_fields()
    assert {"geom_size", "body_mass", "opt.impratio", "opt.tolerance"} <= fields
    assert not fields & {"pair_friction", "pair_solref", "pair_solimp"}


def test_without_a_gpu_warp_says_what_is_missing(block_scene, monkeypatch):
    monkeypatch.delenv(wd.ALLOW_CPU_ENV)
    monkeypatch.setattr(wd.devices, "nvidia_driver_present", lambda: False)
    with pytest.raises(mp.ConfigError, match=r"NVIDIA GPU.*no NVIDIA driver.*\.\[gpu\]"):
        wd.WarpBackend(block_scene, SHORT, 4)


# the shortest procedure that still closes, lifts and holds: the end-to-end test runs
# MuJoCo Warp on the CPU kernel by kernel (~50 ms a physics step)
BRIEF = GraspConfig(close_timeout_s=0.4, lift_height_mm=5.0, hold_s=0.02)


def test_picks_through_a_refilled_shrinking_pool_match_one_slot_each_and_the_c_engine():
    """Three picks through a pool of two slots on Warp's CPU device -- one slot refilled,
    then the pool halved to one slot in the tail -- give bitwise the results of the
    same picks one slot each (record, no refill), so a pick's result does not depend on
    its slot or pool; labels equal MuJoCo C's, forces and lift within the engines'
    agreement, and the traces end where C's do."""
    scene = mp.build_scene(mp.load_object("block"), mp.GripperSpec(), grasp=BRIEF)
    picks = pp.generate_normal(scene.object, scene.gripper, 3, seed=0, grasp=BRIEF)
    inputs = make_inputs(scene, BRIEF, picks)
    from mjx_pick.engine.c_backend import MujocoBackend

    ref, ref_traces = MujocoBackend(scene, BRIEF, 8, nthread=1).run(inputs, record=True)
    backend = wd.WarpBackend(
        scene, BRIEF, batch_size=2, ticks_per_call=5, shrink_levels=1, shrink_min_slots=1
    )
    pooled, _ = backend.run(inputs)
    assert sorted(k[0] for k in backend._pools) == [1, 2]  # the tail ran in the halved pool
    assert backend.pool_stats.rounds > 3 and backend.pool_stats.picks == 3
    alone, traces = backend.run(inputs, record=True)
    for name in wd.RESULT_FIELDS:
        np.testing.assert_array_equal(pooled[name], alone[name], err_msg=name)
    np.testing.assert_array_equal(pooled["success"], ref["success"])
    np.testing.assert_array_equal(pooled["failure"], ref["failure"])
    # two engines, two colliders: forces at F_d within 1 %, lift within 0.1 mm
    np.testing.assert_allclose(pooled["max_force_left_n"], ref["max_force_left_n"], rtol=0.01)
    np.testing.assert_allclose(pooled["lift_height_mm"], ref["lift_height_mm"], atol=0.1)
    assert traces.shape == ref_traces.shape
    t, z = gk.TRACE_FIELDS.index("t_s"), gk.TRACE_FIELDS.index("object_z_m")
    np.testing.assert_allclose(traces[..., t], ref_traces[..., t], rtol=1e-5)
    # the lift may start a tick apart on the two engines; where it ends is the same
    np.testing.assert_allclose(traces[:, -1, z], ref_traces[:, -1, z], atol=1e-4)
    assert backend.pool_stats.steps > 0
    assert backend.pool_stats.iteration_quantile(0.5) >= 1


def test_variant_models_differ_only_in_fields_warp_takes_per_world(block):
    """Two gripper variants of one model structure: MuJoCo Warp's models differ only in
    fields this backend carries per simulation, and hold MuJoCo's values row-major
    (float32, never transformed) -- what a slot's refill writes into its model row."""
    import dataclasses

    import mujoco_warp as mjw

    base = mp.GripperSpec()
    other = dataclasses.replace(base, finger_width_mm=30.0, pad_height_mm=30.0, stroke_mm=100.0)
    a, b = mp.build_scene(block, base), mp.build_scene(block, other)
    with wp.ScopedDevice("cpu"):
        ma, mb = mjw.put_model(a.model), mjw.put_model(b.model)
    carried = wd.carried_fields()
    differ = set()
    for f in dataclasses.fields(ma):
        x, y = getattr(ma, f.name), getattr(mb, f.name)
        if isinstance(x, wp.array):
            if x.shape != y.shape or not np.array_equal(x.numpy(), y.numpy()):
                differ.add(f.name)
    differ -= {"pair_friction", "pair_solref", "pair_solimp"}
    assert differ and differ <= carried, differ - carried
    for name in differ:
        leaf = getattr(mb, name).numpy()
        mine = np.asarray(getattr(b.model, name), np.float32).reshape(leaf.shape)
        np.testing.assert_array_equal(leaf, mine, err_msg=name)


def test_a_process_plans_its_jax_for_the_backends_it_will_build(monkeypatch):
    from mjx_pick.engine import backend, devices

    monkeypatch.setattr(devices, "_jax_on_cpu", False)
    with pytest.raises(mp.ConfigError, match=r"\['warp'\] and \['mjx-warp'\] cannot share"):
        backend.plan_jax(["mujoco", "warp", "mjx-warp"])
    assert not devices._jax_on_cpu
    backend.plan_jax(["mujoco", "mjx"])  # the C engine beside MJX: JAX as it is
    assert not devices._jax_on_cpu
    backend.plan_jax(["mujoco", "warp"])  # beside Warp: JAX's CPU platform only
    assert devices._jax_on_cpu


def test_overflowing_picks_are_rerun_with_grown_buffers_until_none_overflows(monkeypatch):
    """Both Warp backends' overflow rule on a stand-in engine: a pick overflows while
    its need exceeds the buffers; overflowing picks alone are re-run with the buffers
    doubled where they overflowed, their rows replaced; past MAX_GROWTH, an error."""
    import types

    from mjx_pick.engine import pool, warp_buffers
    from mjx_pick.engine.backend import RunStats

    contact_bit, row_bit = 1, 4
    need = np.array([3, 9, 20, 4])  # contacts each pick needs

    def engine(backend):
        def run(inputs):
            idx = inputs.qpos0[:, 0].astype(int)
            over = np.where(need[idx] > backend.buffers.contacts, contact_bit, 0)
            backend.stats.n += len(idx)
            out = {"value": idx * 10.0 + backend.buffers.contacts}
            return out, None, pool.Diagnostics(over, need[idx], need[idx])

        return run

    def inputs_for(n):
        return wd.PickInputs(
            qpos0=np.arange(n, dtype=np.float32)[:, None],
            params=np.zeros(n, np.float32),
            pair_friction=np.zeros((n, 1, 5), np.float32),
            pair_solref=np.zeros((n, 1, 2), np.float32),
            pair_solimp=np.zeros((n, 1, 5), np.float32),
        )

    backend = types.SimpleNamespace(
        buffers=warp_buffers.BufferSizes(4, 8), growths=0, stats=RunStats()
    )
    run = engine(backend)
    inputs = inputs_for(4)
    merged, _, diag = warp_buffers.rerun_overflowed(
        backend, inputs, run(inputs), run, (contact_bit, row_bit), str
    )
    # 4 -> 8 -> 16 -> 32 contacts: pick 1 fits at 16, pick 2 at 32; picks 0 and 3 never re-run
    assert backend.growths == 3 and backend.buffers.contacts == 32 and backend.buffers.rows == 8
    np.testing.assert_array_equal(merged["value"], [4.0, 26.0, 52.0, 34.0])
    assert not diag.overflow.any() and backend.stats.n == 4
    monkeypatch.setattr(warp_buffers, "MAX_GROWTH", 0)
    small = types.SimpleNamespace(
        buffers=warp_buffers.BufferSizes(4, 8), growths=0, stats=RunStats()
    )
    run = engine(small)
    with pytest.raises(warp_buffers.BufferOverflowError, match="in 2 of 4 pick-points"):
        warp_buffers.rerun_overflowed(small, inputs, run(inputs), run, (1, 4), str)


def test_tilted_grasps_on_warp_match_the_c_engine():
    """Grasps given as poses, the approach turned from vertical about the closing axis
    (the pads' faces stay on the block's: a face contact, as a vertical pick's), the
    gripper's tilt carried per simulation as body_quat and the lift's jnt_axis, the
    pads' forces measured along the closing axis: MuJoCo Warp on its CPU device labels
    them as MuJoCo C does, forces at F_d within 1 %, the lift within 0.5 mm. (A turn
    about the axis across the pads puts a pad's edge on the face: a line contact whose
    outcome each engine's collider decides its own way, left to the GPU benchmark's
    stable-label agreement.)"""
    from scipy.spatial.transform import Rotation

    from mjx_pick.core import grasps as gm
    from mjx_pick.engine.c_backend import MujocoBackend

    scene = mp.build_scene(mp.load_object("block"), mp.GripperSpec(), grasp=SHORT)
    picks = pp.generate_normal(scene.object, scene.gripper, 2, seed=0, grasp=SHORT)
    t = gm.poses(picks, scene.grasp_height_mm)
    t[:, :3, :3] = t[:, :3, :3] @ Rotation.from_euler("x", [[25], [-20]], degrees=True).as_matrix()
    starts = {k: getattr(picks, k) for k in ("opening_mm", "gap_left_mm", "gap_right_mm")}
    inputs = make_inputs(scene, SHORT, gm.from_poses(t, picks.pick_id, **starts))
    assert set(inputs.model) == {"body_quat", "jnt_axis"}
    ref, _ = MujocoBackend(scene, SHORT, 8, nthread=1).run(inputs)
    out, _ = wd.WarpBackend(scene, SHORT, batch_size=2).run(inputs)
    np.testing.assert_array_equal(out["success"], ref["success"])
    np.testing.assert_array_equal(out["failure"], ref["failure"])
    np.testing.assert_allclose(out["max_force_left_n"], ref["max_force_left_n"], rtol=0.01)
    np.testing.assert_allclose(out["lift_height_mm"], ref["lift_height_mm"], atol=0.5)
