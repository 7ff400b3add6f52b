"""Extending the tool as docs/architecture.md says: a gripper of one's own (the backend's
and the failure reason's: tests/test_registry.py, tests/test_outcomes.py)."""

import json

from mjx_pick.cli import main

GRIPPER = """\
name = "my-jaw"
stroke_mm = 90.0
finger_width_mm = 20.0
finger_depth_mm = 8.0
pad_height_mm = 30.0
force_min_n = 10.0
force_max_n = 120.0
speed_min_mm_s = 20.0
speed_max_mm_s = 150.0
finger_mass_g = 50.0
body_mass_g = 900.0
"""


def test_adding_a_gripper_is_one_file(tmp_path):
    toml = tmp_path / "my-jaw.toml"
    toml.write_text(GRIPPER)
    out = tmp_path / "run"
    argv = ["evaluate", "block", "--gripper-file", str(toml), "--n", "3", "--backend"]
    argv += ["mujoco", "--lift-height-mm", "5", "--hold-s", "0.05", "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    config = json.loads((out / "config.json").read_text())
    assert config["gripper"]["name"] == "my-jaw" and config["gripper"]["stroke_mm"] == 90.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n"] == 3 and summary["gripper"] == "my-jaw"
