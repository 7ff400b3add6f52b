"""The MuJoCo C backend pinned to the MJX backend, and backend selection.

The full-size check (512 door-opener pick-points, default procedure) runs on a GPU in
benchmarks/agreement.py (figures in benchmarks/RESULTS.md); this is its CI size.
"""

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.backend import make_backend
from mjx_pick.engine.inputs import make_inputs

SHORT = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.3)


@pytest.mark.mjx
def test_backends_agree_on_door_opener(door_opener):
    gripper = mp.load_gripper("robotiq-2f85")
    # 16 pick-points on the pad box alone: MJX's JAX physics on a CPU computes every pad
    # pair's contacts every step, and the rim's 16 pairs on this part make the test
    # several times slower; the rim's labels are compared between C and Warp (the
    # jitted path users run) on a GPU, benchmarks/RESULTS.md
    picks = pp.generate_normal(door_opener, gripper, 16, seed=3)
    # both engines at the physics MJX-JAX runs (the differentiable physics); MJX's labels
    # against C's there and at the default physics: benchmarks/RESULTS.md, "mjx_physics.py"
    contact = mp.ContactParams.differentiable(mp.ContactParams(pad_collision="mean_radius"))
    scene = mp.build_scene(door_opener, gripper, contact, mp.SolverParams.differentiable())
    inputs = make_inputs(scene, SHORT, picks)
    c, _ = make_backend("mujoco", scene, SHORT, batch_size=16).run(inputs)
    j, _ = make_backend("mjx", scene, SHORT, batch_size=16).run(inputs)
    agree = np.mean(c["success"] == j["success"])
    # the two engines differ in their collision routines and solver details, so a
    # chaotic pick (a part spun over the table by the first pad) may end apart: 90 %
    # of labels at this size (99.6 % measured at 16,384 on a GPU, results/history.md). Scores
    # of successes crowd near 1, where a rank correlation measures noise: their
    # median absolute difference must stay below 0.02 (a tenth of a typical gap
    # between a clean grasp and one that turned 30 deg)
    assert agree >= 0.9, f"labels agree on {agree:.1%}"
    gap = np.median(np.abs(c["score"] - j["score"]))
    assert gap <= 0.02, f"median score difference {gap:.3f}"
    assert not c["diverged"].any() and not j["diverged"].any()
    # the shared kernel gives both the same bookkeeping: no systematic offset between
    # their reach times where both reached the force (a period's slip in the kernel's
    # bookkeeping would move every pick alike: the signed median within one control
    # period), and a spread from the engines' own contact dynamics of a few periods
    # (12.5 ms median, -20..+220 ms, on these picks with mujoco 4.0.0, mujoco-mjx 3.17.0,
    # jax 0.10.2 on a CPU, 2026-11-28; the same at e17f288, before this round's changes)
    both = (c["t_reached_s"] > 0) & (j["t_reached_s"] > 0)
    late = c["t_reached_s"][both] - j["t_reached_s"][both]
    assert abs(np.median(late)) <= SHORT.control_period_s + 1e-6, late
    assert np.median(np.abs(late)) <= 3 * SHORT.control_period_s + 1e-6, late


def test_auto_backend_choice(block):
    scene = mp.build_scene(block, mp.GripperSpec())
    backend = make_backend("auto", scene, SHORT, batch_size=4)
    # warp where it can run (an NVIDIA GPU with warp-lang and mujoco-warp), else the C
    # engine
    from mjx_pick.engine.warp_direct import warp_problem

    assert backend.name == ("warp" if warp_problem() is None else "mujoco")
    with pytest.raises(mp.ConfigError, match="backend = 'gpu'"):
        make_backend("gpu", scene, SHORT, batch_size=4)


def test_c_backend_flags_a_blow_up(block):
    # a non-finite state makes MuJoCo warn and reset that simulation: the backend must
    # flag it diverged and leave it unscored, and leave the others alone
    scene = mp.build_scene(block, mp.GripperSpec())
    picks = pp.generate_normal(block, mp.GripperSpec(), 4, seed=0)
    inputs = make_inputs(scene, SHORT, picks)
    inputs.qpos0[1, scene.index.object_qpos + 2] = np.inf
    out, _ = make_backend("mujoco", scene, SHORT, batch_size=4).run(inputs)
    assert list(out["diverged"]) == [False, True, False, False]
    assert np.isnan(out["score"][1]) and not out["success"][1]
    assert out["success"][[0, 2, 3]].sum() >= 2


def test_set_contact_is_one_mapping_in_numpy_and_jax(block):
    import jax.numpy as jnp

    from mjx_pick.engine.inputs import set_contact

    scene = mp.build_scene(block, mp.GripperSpec())
    m, n = scene.model, 3
    base = [
        np.broadcast_to(a, (n, *a.shape)).astype(np.float32)
        for a in (m.pair_friction, m.pair_solref, m.pair_solimp)
    ]
    values = {
        "pad_friction": np.array([0.2, 0.5, 0.9]),  # per simulation
        "table_friction": 0.3,  # one for all
        "pad_solref": [-5000.0, -40.0],  # one vector for all
        "table_solimp": np.tile([0.9, 0.95, 0.001, 0.5, 2.0], (n, 1)),  # a row each
    }
    fr, ref, imp = set_contact(scene, *base, values)
    pads, table = list(scene.index.pad_pairs), list(scene.index.table_pairs)
    want = np.float32([[0.2] * len(pads), [0.5] * len(pads), [0.9] * len(pads)])
    np.testing.assert_array_equal(fr[:, pads, 0], want)
    np.testing.assert_array_equal(fr[:, pads, 0], fr[:, pads, 1])
    # torsion follows the Coulomb coefficient when it is not given
    per_mu = np.float32(scene.contact.torsion_per_friction_m)
    np.testing.assert_array_equal(fr[:, pads, 2], fr[:, pads, 0] * per_mu)
    assert (fr[:, table, :2] == np.float32(0.3)).all()
    assert (ref[:, pads] == np.float32([-5000.0, -40.0])).all()
    assert (imp[:, table] == np.float32([0.9, 0.95, 0.001, 0.5, 2.0])).all()
    # nothing else moves
    untouched = np.ones_like(fr, bool)
    untouched[:, pads] = False
    untouched[:, table, :2] = False
    np.testing.assert_array_equal(fr[untouched], base[0][untouched])
    np.testing.assert_array_equal(imp[:, pads], base[2][:, pads])
    # the same code in jax.numpy gives the same arrays
    out = set_contact(scene, *(jnp.asarray(a) for a in base), values, xp=jnp)
    for a, b in zip((fr, ref, imp), out, strict=True):
        np.testing.assert_array_equal(a, np.asarray(b))
