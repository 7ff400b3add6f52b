"""MJX-JAX runs one physics, the differentiable one: it says so, refuses others, runs
what it says, and its forward-mode derivatives through a pick are finite.

Its label agreement with MuJoCo C (at the same settings and at the default physics) is
measured at full size in benchmarks/mjx_physics.py (benchmarks/RESULTS.md,
"mjx_physics.py").
"""

import dataclasses

import mujoco
import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import load_toml
from mjx_pick.core.physics import DIFFERENTIABLE_SOLVER, load_contact
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine import registry
from mjx_pick.engine.backend import make_backend
from mjx_pick.engine.inputs import make_inputs

SHORT = GraspConfig(close_timeout_s=0.6, lift_height_mm=10.0, hold_s=0.1)


def _physics(block, contact=None, solver=None):
    return mp.build_scene(block, mp.GripperSpec(), contact, solver, SHORT)


def test_mjx_refuses_every_setting_it_would_not_run_and_says_what_to_pass(block):
    from mjx_pick.engine.mjx_backend import shipped_physics_files

    with pytest.raises(mp.ConfigError) as err:
        make_backend("mjx", _physics(block), SHORT, batch_size=4)  # the default physics
    message = str(err.value)
    for part in (
        "solver.cone = 'elliptic'",
        "solver.impratio = 100.0",
        "solver.iterations = 50",
        "solver.ls_iterations = 50",
        "contact.pad_margin_mm = 0.05",
        "backend 'mujoco' or 'warp'",
    ):
        assert part in message, part
    # the files it names hold the physics it runs
    solver_file, contact_file = shipped_physics_files()
    assert f"--solver {solver_file}" in message and f"--contact {contact_file}" in message
    assert load_toml(mp.SolverParams, solver_file) == mp.SolverParams.differentiable()
    assert load_contact(contact_file)[0] == mp.ContactParams.differentiable()
    # one setting off: named alone; the user's other settings are kept by differentiable()
    own = mp.SolverParams.differentiable(mp.SolverParams(timestep_s=0.0005, iterations=30))
    assert own.timestep_s == 0.0005 and own.iterations == DIFFERENTIABLE_SOLVER["iterations"]
    off = mp.SolverParams.differentiable(mp.SolverParams(iterations=30))
    off = dataclasses.replace(off, ls_iterations=50)
    with pytest.raises(mp.ConfigError, match=r"^solver\.ls_iterations = 50: MJX"):
        make_backend("mjx", _physics(block, mp.ContactParams.differentiable(), off), SHORT, 4)
    ok = _physics(block, mp.ContactParams.differentiable(), own)
    assert make_backend("mjx", ok, SHORT, batch_size=4).scene is ok


def test_choosing_mjx_says_which_physics_it_runs_and_refuses_the_defaults(tmp_path, capsys):
    # the note names the physics; a run at the default physics ends before anything is
    # simulated, naming what differs
    argv = ["evaluate", "block", "--backend", "mjx", "--n", "2", "--out", str(tmp_path / "run")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    note, *rest = err.splitlines()
    assert note == f"mjx-pick: note: --backend mjx is {registry.ENTRIES['mjx'].note}"
    assert "pyramidal cones, impratio 1, 20 solver and 8 line-search iterations" in note
    assert "pads without a contact margin" in note
    assert any(line.startswith("mjx-pick: error: solver.cone = 'elliptic'") for line in rest)
    assert not (tmp_path / "run" / "results.parquet").exists()


@pytest.mark.mjx
def test_mjx_runs_the_physics_it_says_and_differentiates_a_whole_pick(block):
    import jax
    import jax.numpy as jnp

    from mjx_pick.engine.mjx_backend import jax_physics
    from mjx_pick.engine.simulator import differentiable_rollout
    from mjx_pick.studies.calibration.parameters import contact_arrays_jnp

    contact, solver = mp.ContactParams.differentiable(), mp.SolverParams.differentiable()
    scene = _physics(block, contact, solver)
    # the device model holds the settings it says it runs
    opt = jax_physics(scene).model.opt
    assert opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL and float(opt.impratio) == 1.0
    assert (opt.iterations, opt.ls_iterations) == (20, 8)
    assert not np.asarray(jax_physics(scene).model.pair_margin).any()
    # two picks whose labels hang on no rounding, through the whole short procedure: a
    # centred grasp that holds, and the same with the block moved 0.2 m away (the pads
    # close on air: no contact)
    checker = pp.FeasibilityChecker(block, mp.GripperSpec(), grasp=SHORT)
    picks = checker.batch(np.arange(2), np.zeros(2), np.zeros(2), np.zeros(2), "user")
    inputs = make_inputs(scene, SHORT, picks)
    inputs.qpos0[1, scene.index.object_qpos] += 0.2
    settings = mp.Settings(mp.GripperSpec(), contact, solver, SHORT)
    roll = differentiable_rollout(scene, SHORT, False)

    def results(mu):
        # calibration's jvp estimator's mapping of the pad friction to the pair values
        fr, ref, force = contact_arrays_jnp(
            ["pad_friction"], [mu], inputs, scene, settings, block.mass_kg
        )
        return roll(inputs.qpos0, inputs.params._replace(grip_force_n=force), fr, ref,
                    inputs.pair_solimp)[0]  # fmt: skip

    mu = jnp.float32(contact.pad_friction)
    out, tangents = jax.jit(lambda m: jax.jvp(results, (m,), (jnp.float32(1.0),)))(mu)
    assert not np.asarray(out["diverged"]).any()
    np.testing.assert_array_equal(np.asarray(out["success"]), [True, False])
    # the labels are MuJoCo C's at the same settings
    c, _ = make_backend("mujoco", scene, SHORT, batch_size=2).run(inputs)
    np.testing.assert_array_equal(np.asarray(out["success"]), c["success"])
    np.testing.assert_array_equal(np.asarray(out["failure"]), c["failure"])
    for key in ("lift_height_mm", "t_reached_s", "slip_mm", "max_force_left_n"):
        assert np.isfinite(np.asarray(tangents[key])).all(), key
