"""Output folders are owned (issue 21): a command refuses a folder another command
wrote, or the same command with another configuration, before any work; unusable
paths are one-line errors; --overwrite replaces, --resume continues."""

import os

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import write_atomic
from mjx_pick.outputs.rundir import (
    MANIFEST,
    claim,
    config_hash,
    end_claims,
    finish,
    lock_holder,
    read_manifest,
)
from mjx_pick.studies.sweeps import ParamSpec, sweep


def test_claim_refuses_other_commands_and_configurations(tmp_path):
    out = tmp_path / "run"
    claim(out, "evaluate", "k1")
    write_atomic(out / "results.parquet", b"x")  # recorded: the run's own file
    finish(out)
    (out / "notes.txt").write_text("mine")  # a user's, beside the results
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
    assert (out / "notes.txt").read_text() == "mine"  # only recorded files are removed
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


HOLDER = """
import sys, time
from mjx_pick.outputs.rundir import claim
from mjx_pick.core.config import write_atomic
out = claim(sys.argv[1], "evaluate", "k1")
write_atomic(out / "config.json", "{}")
write_atomic(out / "scene.xml", "<mujoco/>")
print("claimed", flush=True)
time.sleep(120)
"""


def _hold(out):
    """A second process that claims out and keeps writing it (until killed)."""
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(out)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "claimed"
    return proc


def test_a_folder_being_written_is_locked_and_a_dead_writer_is_detected(tmp_path):
    out = tmp_path / "run"
    proc = _hold(out)
    try:
        # neither a second writer nor --overwrite touches the live run's files
        for kw in ({}, {"overwrite": True}, {"resume": True}):
            with pytest.raises(mp.ConfigError, match=rf"pid {proc.pid} on .*started"):
                claim(out, "evaluate", "k2", **kw)
        assert (out / "config.json").is_file() and (out / "scene.xml").is_file()
        assert read_manifest(out)["status"] == "running"
        assert lock_holder(out)["pid"] == proc.pid
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    # the lock died with its process: the folder's "running" run is known dead, and a
    # corrected configuration takes the folder without --overwrite
    assert lock_holder(out) is None
    claim(out, "evaluate", "k2")
    assert read_manifest(out)["config_key"] == "k2"
    assert not (out / "config.json").exists()  # nothing of the dead attempt is kept
    finish(out)
    assert lock_holder(out) is None  # released by finish


def test_refusal_names_each_changed_setting_and_offers_a_new_folder(tmp_path):
    out = tmp_path / "run"
    old = {"n": 200, "contact": {"pad_friction": 0.86, "stiffness": 1.0}, "seed": 0}
    claim(out, "evaluate", config_hash(old), settings=old)
    (out / "chunks").mkdir()
    (out / "chunks" / "part-000000.parquet").write_bytes(b"x")
    finish(out, "interrupted")
    new = {"n": 300, "contact": {"pad_friction": 0.5, "stiffness": 1.0}, "seed": 0}
    with pytest.raises(mp.ConfigError) as err:
        claim(out, "evaluate", config_hash(new), resume=True, settings=new)
    text = str(err.value)
    assert "contact.pad_friction: 0.86 -> 0.5" in text and "n: 200 -> 300" in text
    assert "stiffness" not in text and "seed" not in text
    assert "1 finished chunks" in text
    assert text.index("--out NEW") < text.index("--overwrite")
    assert (out / "chunks" / "part-000000.parquet").is_file()


def test_a_failed_run_is_replaced_by_a_corrected_one(tmp_path):
    out = tmp_path / "run"
    claim(out, "evaluate", "k1")
    write_atomic(out / "config.json", "{}")
    finish(out, "failed", message="no feasible pick-point")
    (out / "photos").mkdir()
    (out / "photos" / "cell.jpg").write_bytes(b"x")  # a user's, put there afterwards
    m = read_manifest(out)
    assert (m["status"], m["message"]) == ("failed", "no feasible pick-point")
    claim(out, "evaluate", "k2")  # no --overwrite needed: nothing finished is there
    assert read_manifest(out)["status"] == "running" and not (out / "config.json").exists()
    assert (out / "photos" / "cell.jpg").is_file()  # never the run's: kept


def test_end_claims_marks_unfinished_folders(tmp_path):
    out = tmp_path / "run"
    claim(out, "evaluate", "k1")
    assert out.resolve() in end_claims("terminated", "stopped by SIGTERM")
    m = read_manifest(out)
    assert (m["status"], m["message"]) == ("terminated", "stopped by SIGTERM")
    assert lock_holder(out) is None


TINY = ["--traces", "0", "--hold-s", "0.05", "--lift-height-mm", "5", "--no-progress"]


def test_inputs_are_checked_before_the_folder_is_claimed(tmp_path, capsys):
    out = tmp_path / "ev"
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("x_mm,y_mm,yaw_deg\n0,zero,0\n")
    far = tmp_path / "far.csv"
    far.write_text("x_mm,y_mm,yaw_deg\n500,0,0\n")  # no feasible pick-point
    for extra in (["--n", "0"], ["--picks", str(bad_csv)], ["--picks", str(far)]):
        assert main(["evaluate", "block", *extra, "--out", str(out), *TINY]) == 2
        assert read_manifest(out) is None, extra  # the folder was never claimed
    assert "Traceback" not in capsys.readouterr().err


def _boom(error):
    def simulate(*args, **kwargs):
        raise error

    return simulate


def test_an_error_after_claiming_marks_the_folder_failed_and_a_rerun_proceeds(
    tmp_path, capsys, monkeypatch
):
    from mjx_pick.studies import evaluation

    out = tmp_path / "ev"
    part = out / "chunks" / "part-000000.parquet"
    denied = PermissionError(13, "Permission denied", str(part))
    with monkeypatch.context() as m:
        m.setattr(evaluation, "_simulate", _boom(denied))
        assert main(["evaluate", "block", "--n", "4", "--out", str(out), *TINY]) == 1
    err = capsys.readouterr().err
    assert f"{part}: Permission denied" in err and "Traceback" not in err
    manifest = read_manifest(out)
    assert manifest["status"] == "failed" and "Permission denied" in manifest["message"]
    assert lock_holder(out) is None
    # a corrected run (here: another seed) takes the folder without --overwrite
    assert main(["evaluate", "block", "--n", "4", "--seed", "1", "--out", str(out), *TINY]) == 0
    assert read_manifest(out)["status"] == "complete"
    assert "replacing the files of an unfinished" in capsys.readouterr().err


def test_sigterm_stops_a_run_like_ctrl_c(tmp_path, capsys, monkeypatch):
    import signal
    import time

    from mjx_pick.studies import evaluation

    def killed(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the handler raises here
        raise AssertionError("SIGTERM did not stop the run")

    monkeypatch.setattr(evaluation, "_simulate", killed)
    out = tmp_path / "ev"
    before = signal.getsignal(signal.SIGTERM)  # another library's (Ray's), in a shared worker
    assert main(["evaluate", "block", "--n", "4", "--out", str(out), *TINY]) == 143
    assert "terminated (SIGTERM)" in capsys.readouterr().err
    manifest = read_manifest(out)
    assert manifest["status"] == "terminated" and "SIGTERM" in manifest["message"]
    assert signal.getsignal(signal.SIGTERM) is before  # restored


def test_resume_over_a_corrupt_chunk_simulates_it_again(tmp_path, capsys):
    import json

    block = mp.load_asset("block")
    grasp = mp.GraspConfig(close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)
    out = tmp_path / "ev"
    kw = dict(n=4, grasp=grasp, backend="mujoco", out=out, n_traces=0, chunk_size=2)
    first = mp.evaluate(block, keep_chunks=True, **kw)
    # as a run killed after its chunks: the last one cut short on disk
    manifest = read_manifest(out)
    manifest["status"] = "interrupted"
    (out / MANIFEST).write_text(json.dumps(manifest))
    (out / "results.parquet").unlink()
    bad = out / "chunks" / "part-000001.parquet"
    bad.write_bytes(bad.read_bytes()[:40])
    again = mp.evaluate(block, resume=True, **kw)
    assert f"{bad}: unreadable chunk" in capsys.readouterr().err
    assert again.table.equals(first.table)


def test_resume_over_a_chunk_of_another_versions_columns_is_refused(tmp_path):
    import json

    import pyarrow.parquet as pq

    block = mp.load_asset("block")
    grasp = mp.GraspConfig(close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)
    out = tmp_path / "ev"
    kw = dict(n=4, grasp=grasp, backend="mujoco", out=out, n_traces=0, chunk_size=2)
    mp.evaluate(block, keep_chunks=True, **kw)
    manifest = read_manifest(out)
    manifest["status"] = "interrupted"
    (out / MANIFEST).write_text(json.dumps(manifest))
    (out / "results.parquet").unlink()
    # as written by a version whose results did not have the last column yet
    old = out / "chunks" / "part-000001.parquet"
    table = pq.read_table(old)
    pq.write_table(table.drop_columns([table.column_names[-1]]), old)
    with pytest.raises(mp.ConfigError, match="another version of mjx-pick.*choose another --out"):
        mp.evaluate(block, resume=True, **kw)
