"""Output folders are owned (issue 21): a command refuses a folder another command
wrote, or the same command with another configuration, before any work; unusable
paths are one-line errors; --overwrite replaces, --resume continues."""

import os

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core import pickpoints as pp
from mjx_pick.outputs.rundir import MANIFEST, claim, finish, read_manifest
from mjx_pick.studies.sweeps import ParamSpec, sweep


def test_claim_refuses_other_commands_and_configurations(tmp_path):
    out = tmp_path / "run"
    claim(out, "evaluate", "k1")
    (out / "results.parquet").write_bytes(b"x")
    finish(out)
    assert read_manifest(out)["status"] == "complete"
    claim(out, "evaluate", "k1")  # the same command and configuration: allowed
    with pytest.raises(mp.ConfigError, match=r"holds the results of `mjx-pick evaluate`"):
        claim(out, "sweep", "k2")
    with pytest.raises(mp.ConfigError, match="another configuration"):
        claim(out, "evaluate", "k2")
    # robust may add its files to an evaluate folder; its manifest stays evaluate's
    claim(out, "robust", "k3", joins=("evaluate",))
    assert read_manifest(out)["command"] == "evaluate"
    # --overwrite empties it first
    claim(out, "sweep", "k2", overwrite=True)
    assert read_manifest(out)["command"] == "sweep" and not (out / "results.parquet").exists()
    with pytest.raises(mp.ConfigError, match="contradict"):
        claim(out, "sweep", "k2", overwrite=True, resume=True)


def test_unusable_and_foreign_paths_are_refused(tmp_path):
    a_file = tmp_path / "file.txt"
    a_file.write_text("mine")
    with pytest.raises(mp.ConfigError, match="is a file, not a folder"):
        claim(a_file, "evaluate", "k")
    with pytest.raises(mp.ConfigError, match="cannot be"):
        claim("/proc/mjx_pick_test", "evaluate", "k")
    foreign = tmp_path / "photos"
    foreign.mkdir()
    (foreign / "holiday.jpg").write_bytes(b"x")
    with pytest.raises(mp.ConfigError, match="did not write"):
        claim(foreign, "evaluate", "k", overwrite=True)  # never emptied
    assert (foreign / "holiday.jpg").exists()
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o500)
        with pytest.raises(mp.ConfigError, match="cannot be written"):
            claim(ro, "evaluate", "k")


def test_sweep_into_an_evaluate_folder_is_refused_before_simulating(tmp_path, capsys):
    block = mp.load_asset("block")
    out = tmp_path / "ev"
    picks = pp.FeasibilityChecker(block, mp.GripperSpec()).batch(
        np.arange(2), np.zeros(2), np.zeros(2), np.zeros(2), "user"
    )
    grasp = mp.GraspConfig(close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)
    mp.evaluate(block, picks=picks, grasp=grasp, backend="mujoco", out=out, n_traces=0)
    assert read_manifest(out)["command"] == "evaluate"
    assert (out / MANIFEST).is_file()
    sim = mp.Simulator(block, "mujoco")
    with pytest.raises(mp.ConfigError, match="mjx-pick evaluate"):
        sweep(block, [ParamSpec.parse("contact.pad_friction=0.2,0.5")], n=2, simulator=sim, out=out)
    assert sim.rollouts == 0  # refused before any simulation
    # the CLI says it in one line, no traceback
    assert main(["picks", "block", "--n", "5", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "holds the results of `mjx-pick evaluate`" in err and "Traceback" not in err
