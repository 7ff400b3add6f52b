"""Settings to simulation inputs: one conversion, one route for contact values, one rule
fitting the procedure to a gripper, the control period checked when settings are made."""

import dataclasses

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.cli import build_parser
from mjx_pick.cli import inputs as cli_inputs
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.inputs import make_inputs, pick_inputs, scene_of

SHORT = GraspConfig(close_timeout_s=0.6, lift_height_mm=5.0, hold_s=0.05)


@pytest.mark.parametrize("gripper", ["robotiq-2f85", "robotiq-2f85-linkage"])
def test_contact_values_reach_the_pairs_on_one_route(gripper, block):
    # a study runs each variant on a scene compiled for another of the same structure,
    # the contact carried per pick; evaluate runs on the variant's own scene: both must
    # give every pair (the linkage's box pads too) the same values, bit for bit
    g = mp.load_gripper(gripper)
    mine = mp.Settings(g, mp.ContactParams(pad_friction=0.37, pad_stiffness_n_per_mm=80.0))
    mine = dataclasses.replace(mine, grasp=SHORT)
    other = dataclasses.replace(mine, contact=mp.ContactParams(pad_friction=1.1))
    assert mine.structure() == other.structure()
    picks = pp.generate_normal(block, g, 3, seed=0, grasp=SHORT)
    own = make_inputs(scene_of(block, mine), SHORT, picks)
    shared = pick_inputs(scene_of(block, other), mine, picks)
    for name in ("pair_friction", "pair_solref", "pair_solimp", "qpos0"):
        np.testing.assert_array_equal(getattr(shared, name), getattr(own, name), err_msg=name)
    for a, b in zip(shared.params, own.params, strict=True):
        np.testing.assert_array_equal(a, b)
    assert own.pair_friction.dtype == np.float32 and own.pair_solimp.shape[-1] == 5


def test_one_rule_fits_the_procedure_to_a_gripper():
    rg2 = mp.load_gripper("onrobot-rg2")  # 3-40 N, 38-127 mm/s
    slow = dataclasses.replace(rg2, speed_min_mm_s=10.0, speed_max_mm_s=60.0)
    grasp, note = GraspConfig().fitted_to(slow)
    assert (grasp.grip_force_n, grasp.closing_speed_mm_s) == (40.0, 60.0)
    assert "the default 50 N is outside onrobot-rg2's 3-40 N: using 40 N" in note
    assert "the default 100 mm/s" in note and "using 60 mm/s" in note
    # what the user set is kept (and refused out of range by check_gripper)
    kept, note = GraspConfig().fitted_to(slow, keep=("grip_force_n",))
    assert (kept.grip_force_n, kept.closing_speed_mm_s, "grip" in note) == (50.0, 60.0, False)
    with pytest.raises(mp.ConfigError, match="grip_force_n = 50 is out of range"):
        kept.check_gripper(slow)
    # the settings of a comparison: every gripper at its nearest in-range values
    on_rg2, _ = mp.Settings(grasp=GraspConfig(grip_force_n=80.0)).on_gripper(rg2)
    assert on_rg2.gripper is rg2 and on_rg2.grasp.grip_force_n == 40.0


def test_the_cli_fits_only_what_the_user_left_unset(tmp_path, capsys):
    parse = build_parser().parse_args
    speed = tmp_path / "speed.toml"
    speed.write_text("closing_speed_mm_s = 50.0\n")  # inside the RG2's 38-127 mm/s
    args = parse(["evaluate", "block", "--gripper", "onrobot-rg2", "--grasp", str(speed)])
    grasp = cli_inputs.inputs_of(args)[4]
    assert (grasp.grip_force_n, grasp.closing_speed_mm_s) == (40.0, 50.0)
    assert "using 40 N" in capsys.readouterr().err
    speed.write_text("closing_speed_mm_s = 20.0\n")  # the user's: kept, then refused
    args = parse(["evaluate", "block", "--gripper", "onrobot-rg2", "--grasp", str(speed)])
    with pytest.raises(mp.ConfigError, match="closing_speed_mm_s = 20 is out of range"):
        cli_inputs.inputs_of(args)[4].check_gripper(mp.load_gripper("onrobot-rg2"))


def test_the_control_period_is_checked_when_settings_are_made():
    with pytest.raises(mp.ConfigError, match="whole multiple of solver.timestep_s"):
        mp.Settings(grasp=GraspConfig(control_period_s=0.0045))
    with pytest.raises(mp.ConfigError, match="whole multiple"):
        mp.evaluate("block", grasp=GraspConfig(control_period_s=0.0045), n=1, backend="mujoco")
