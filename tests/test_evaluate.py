"""evaluate() and the mjx-pick CLI end to end: outputs, user pick-points, bad inputs."""

import json
import os

import numpy as np
import pyarrow.parquet as pq
import pytest

import mjx_pick as mp
from mjx_pick import cli
from mjx_pick.core.config import to_toml
from mjx_pick.core.metrics import COLUMNS, MARGINAL_BAND
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.studies.evaluation import evaluate, experiment_key

FAST = GraspConfig(close_timeout_s=0.8, lift_height_mm=30.0, hold_s=0.2)


@pytest.fixture()
def fast_toml(tmp_path):
    path = tmp_path / "grasp.toml"
    path.write_text(to_toml(FAST))
    return path


def test_evaluate_writes_every_output(tmp_path, block):
    ev = evaluate(
        block,
        "robotiq-2f85",
        n=12,
        seed=1,
        grasp=FAST,
        backend="mujoco",
        batch_size=8,
        out=tmp_path / "run",
        n_traces=2,
    )
    out = tmp_path / "run"
    table = pq.read_table(out / "results.parquet")
    assert table.column_names == list(COLUMNS)
    assert table.num_rows == 12
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n"] == 12 and summary["backend"] == "mujoco"
    assert summary["compile_s"] > 0 and summary["run_s"] > 0 and summary["picks_per_s"] > 0
    assert summary["f_gmin_n"] == pytest.approx(block.mass_kg * 9.81 * 1.1 / (2 * 0.86), rel=1e-6)
    config = json.loads((out / "config.json").read_text())
    assert config["seed"] == 1 and config["grasp"]["hold_s"] == 0.2
    assert config["versions"]["mujoco"]
    traces = pq.read_table(out / "traces.parquet")
    assert set(traces.column("rank").to_pylist()) == {"best", "worst"}
    assert len(set(traces.column("pick_id").to_pylist())) == 4
    assert (out / "scene.xml").read_text().startswith("<mujoco")
    assert ev.summary["success_rate"] == pytest.approx(np.mean(table["success"]))
    # each judged label's margin has its sign; the summary counts those decided by a hair
    margin, success = np.asarray(table["label_margin"], float), np.asarray(table["success"])
    judged = np.isfinite(margin)
    assert judged.any() and np.array_equal(success[judged], margin[judged] >= 0)
    assert not success[~judged].any()
    assert summary["labels_marginal"] == int(np.sum(np.abs(margin[judged]) < MARGINAL_BAND))
    # a second run into the same folder must not mix results silently
    with pytest.raises(mp.ConfigError, match="--resume"):
        evaluate(block, n=12, seed=1, grasp=FAST, backend="mujoco", batch_size=8, out=out)
    again = evaluate(
        block,
        n=12,
        seed=1,
        grasp=FAST,
        backend="mujoco",
        batch_size=8,
        out=out,
        resume=True,
        n_traces=0,
    )
    assert again.table.equals(table)
    with pytest.raises(mp.ConfigError, match="another configuration"):
        evaluate(
            block, n=12, seed=2, grasp=FAST, backend="mujoco", batch_size=8, out=out, resume=True
        )


def test_the_summary_times_every_fixed_cost_this_call_paid(block):
    # an object given by name is prepared by evaluate: its time is the run's "object";
    # one given prepared is not; the caller's own costs come first
    by_name = evaluate("block", n=4, grasp=FAST, backend="mujoco", batch_size=8, n_traces=0)
    parts = by_name.summary["time_s"]
    assert list(parts) == ["object", "scene", "picks", "compile", "simulate", "write"]
    assert all(v >= 0 for v in parts.values())
    given = evaluate(
        block,
        n=4,
        grasp=FAST,
        backend="mujoco",
        batch_size=8,
        n_traces=0,
        fixed_costs={"import_s": 1.5},
    )
    assert list(given.summary["time_s"])[:2] == ["import", "scene"]
    assert given.summary["time_s"]["import"] == 1.5


def test_cli_evaluate_with_user_picks(tmp_path, fast_toml, capsys):
    picks = tmp_path / "picks.csv"
    picks.write_text("x_mm,y_mm,yaw_deg\n0,0,0\n2,-1,15\n")
    code = cli.main(
        [
            "evaluate",
            "block",
            "--picks",
            str(picks),
            "--grasp",
            str(fast_toml),
            "--backend",
            "mujoco",
            "--out",
            str(tmp_path / "o"),
            "--no-progress",
            "--traces",
            "1",
            "--step-check",
        ]
    )
    assert code == 0
    table = pq.read_table(tmp_path / "o" / "results.parquet")
    np.testing.assert_allclose(table["x_mm"].to_numpy(), [0, 2])
    assert table["success"].to_numpy().all()
    text = " ".join(capsys.readouterr().out.split())
    assert "success rate" in text
    # the label checks' lines, with the counts of the table's own columns
    margin = np.abs(np.asarray(table["label_margin"], float))
    assert f"labels by a hair {int(np.sum(margin < 0.1))} of 2" in text
    changed = int(np.sum(~np.asarray(table["label_converged"])))
    assert f"labels the step changes {changed} of 2" in text


@pytest.mark.parametrize(
    "content, match",
    [
        ("x_mm,yaw_deg\n0,0\n", "missing column"),
        ("x_mm,y_mm,yaw_deg\n0,zero,0\n", "line 2"),
        ("x_mm,y_mm,yaw_deg\n0,0,0\n80,0,0\n", "pick_id 1 \\(line 3\\): off_object"),
        ("x_mm,y_mm,yaw_deg,grip_force_n\n0,0,0,30\n", "unknown column.*grip_force_n"),
    ],
)
def test_cli_bad_picks_file(tmp_path, fast_toml, capsys, content, match):
    picks = tmp_path / "p.csv"
    picks.write_text(content)
    code = cli.main(
        [
            "evaluate",
            "block",
            "--picks",
            str(picks),
            "--grasp",
            str(fast_toml),
            "--backend",
            "mujoco",
            "--no-progress",
        ]
    )
    assert code == 2
    import re

    assert re.search(match, capsys.readouterr().err)


def test_cli_bad_settings(capsys):
    assert cli.main(["evaluate", "block", "--grip-force-n", "500", "--backend", "mujoco"]) == 2
    err = capsys.readouterr().err
    assert "grip_force_n = 500 is out of range" in err and "235" in err
    assert cli.main(["evaluate", "nope.png", "--px-per-mm", "10"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert cli.main(["evaluate", "block", "--gripper", "nope"]) == 2
    assert "unknown gripper preset" in capsys.readouterr().err


def test_optimization_mode_stops_at_k(tmp_path, block):
    ev = evaluate(
        block,
        grasp=FAST,
        backend="mujoco",
        batch_size=8,
        until=3,
        min_score=0.5,
        max_n=32,
        n_traces=0,
    )
    good = np.asarray(ev.table["success"]) & (np.asarray(ev.table["score"]) >= 0.5)
    assert good.sum() >= 3
    assert ev.table.num_rows % 8 == 0 and ev.table.num_rows <= 32


def test_cli_picks_and_listings(tmp_path, capsys):
    assert cli.main(["picks", "door_opener", "--n", "20", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "picks.csv").read_text().count("\n") == 21
    assert (tmp_path / "candidates.png").stat().st_size > 10_000
    assert cli.main(["presets"]) == 0 and "robotiq-2f85" in capsys.readouterr().out
    assert cli.main(["assets"]) == 0 and "door_opener" in capsys.readouterr().out


def test_picks_file_with_an_infeasible_row(tmp_path, block):
    picks = tmp_path / "picks.csv"
    picks.write_text("x_mm,y_mm,yaw_deg\n0,0,0\n300,0,0\n1,0,10\n")
    grasp = GraspConfig(close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)
    with pytest.raises(mp.ConfigError, match=r"pick_id 1 \(line 3\): off_object.*--skip-infe"):
        evaluate(block, picks=picks, grasp=grasp, backend="mujoco", n_traces=0)
    with pytest.warns(UserWarning, match=r"1 of 3 .*pick_id 1 \(line 3\): off_object; left"):
        ev = evaluate(
            block, picks=picks, grasp=grasp, backend="mujoco", n_traces=0, skip_infeasible=True
        )
    # the kept rows keep their index in the file
    assert ev.table["pick_id"].to_pylist() == [0, 2]


def test_picks_file_ids_are_kept_through_to_the_results(tmp_path, block):
    # a pick_id column was renumbered 0, 1, ...: joining by id gave other rows
    picks = tmp_path / "picks.csv"
    picks.write_text("pick_id,x_mm,y_mm,yaw_deg\n7,0,0,0\n3,300,0,0\n12,1,0,10\n")
    grasp = GraspConfig(close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)
    with pytest.warns(UserWarning, match=r"pick_id 3 \(line 3\): off_object; left out"):
        ev = evaluate(
            block, picks=picks, grasp=grasp, backend="mujoco", n_traces=0, skip_infeasible=True
        )
    assert ev.table["pick_id"].to_pylist() == [7, 12]
    np.testing.assert_allclose(ev.table["x_mm"].to_numpy(), [0.0, 1.0])


@pytest.mark.parametrize(
    "content, match",
    [
        ("x_mm,y_mm,yaw_deg\n0,0,0\n1,0,0\n0,0,0\n", r"1 repeated pose.*line 4 repeats line 2"),
        ("pick_id,x_mm,y_mm,yaw_deg\n5,0,0,0\n5,1,0,0\n", r"repeated pick_id.*line 3 repeats"),
        ("pick_id,x_mm,y_mm,yaw_deg\n1.5,0,0,0\n", r"line 2: pick_id = '1.5' must be a whole"),
        ("pick_id,x_mm,y_mm,yaw_deg\n-1,0,0,0\n", r"pick_id = '-1'"),
        (
            "x_mm,y_mm,yaw_deg,grip_force_n,note\n0,0,0,30,a\n",
            r"unknown column\(s\) grip_force_n, note; allowed: x_mm, y_mm, yaw_deg, pick_id",
        ),
        ("x_mm,y_mm,yaw_deg\n0,0,0,9\n", r"line 2: more cells than columns"),
    ],
)
def test_picks_file_repeats_and_unknown_columns_are_refused(tmp_path, content, match):
    from mjx_pick.studies.pickfiles import read_picks_csv

    path = tmp_path / "p.csv"
    path.write_text(content)
    with pytest.raises(mp.ConfigError, match=match):
        read_picks_csv(path)


def test_picks_file_saved_by_excel_with_a_byte_order_mark(tmp_path):
    from mjx_pick.studies.pickfiles import read_picks_csv

    path = tmp_path / "p.csv"
    path.write_bytes("\ufeffx_mm,y_mm,yaw_deg,opening_mm,coverage\r\n1,2,3,40,0.5\r\n".encode())
    rows = read_picks_csv(path)
    assert (rows.pick_id.tolist(), rows.x_mm.tolist(), rows.yaw_deg.tolist()) == ([0], [1], [3])


def test_a_bad_picks_file_is_refused_before_the_folder_is_claimed(tmp_path, block):
    picks = tmp_path / "p.csv"
    picks.write_text("x_mm,y_mm,yaw_deg\n0,0,0\n0,0,0\n")
    with pytest.raises(mp.ConfigError, match="repeated pose"):
        evaluate(block, picks=picks, backend="mujoco", out=tmp_path / "run")
    assert not (tmp_path / "run").exists()


def _key(obj, **settings):
    """evaluate's resume key of obj with the default settings (or these)."""
    gripper = mp.GripperSpec()
    scene = mp.build_scene(obj, gripper, grasp=FAST)
    values = {"gripper": gripper, "grasp": FAST, "seed": 0, "n": 100, "backend": "mujoco"}
    return experiment_key(scene, {**values, **settings})


def test_resume_key_is_the_experiment_not_the_install(tmp_path, block):
    # the same asset read from two places (a checkout and site-packages: `python -m
    # pytest` imports the first, a CLI started elsewhere the second) is one experiment
    import shutil
    import subprocess
    import sys
    import tomllib
    from importlib import resources

    entry = tomllib.loads(
        (resources.files("mjx_pick.assets") / "objects" / "manifest.toml").read_text()
    )["block"]
    kwargs = {k: entry[k] for k in ("px_per_mm", "thickness_mm", "mass_g", "material")}
    copies = []
    for where in ("checkout", "site-packages"):
        path = tmp_path / where / "block.png"
        path.parent.mkdir()
        with resources.as_file(resources.files("mjx_pick.assets") / "objects" / "block.png") as f:
            shutil.copy(f, path)
        copies.append(mp.object_from_image(path, name="block", **kwargs))
    assert copies[0].source != copies[1].source
    key = _key(block)
    assert _key(copies[0]) == _key(copies[1]) == key
    # a process started outside the checkout computes the same key
    code = "import mjx_pick as mp; from tests_key import key; print(key(mp.load_asset('block')))"
    helper = tmp_path / "tests_key.py"
    helper.write_text(
        "import mjx_pick as mp\n"
        "from mjx_pick.studies.evaluation import experiment_key\n"
        f"from mjx_pick.core.procedure import GraspConfig\nFAST = {FAST!r}\n"
        "def key(obj):\n"
        "    g = mp.GripperSpec()\n"
        "    scene = mp.build_scene(obj, g, grasp=FAST)\n"
        "    values = {'gripper': g, 'grasp': FAST, 'seed': 0, 'n': 100, 'backend': 'mujoco'}\n"
        "    return experiment_key(scene, values)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == key
    # what decides results changes it: the object's content, physics, seed
    heavier = mp.object_from_image(
        tmp_path / "checkout" / "block.png",
        name="block",
        **{**kwargs, "mass_g": 2 * kwargs["mass_g"]},
    )
    assert _key(heavier) != key
    assert _key(block, seed=1) != key
    assert _key(block, contact=mp.ContactParams(pad_friction=0.5)) != key


def test_optimization_mode_resumes_where_it_stopped(tmp_path, block):
    # a killed run leaves its manifest, chunk plan and finished chunks (batches): that
    # state, cut after two batches, resumes to the uninterrupted run's table
    import shutil

    run = dict(grasp=FAST, backend="mujoco", batch_size=8, until=20, min_score=0.9)
    run.update(max_n=64, n_traces=0)
    whole = evaluate(block, **run, out=tmp_path / "whole", keep_chunks=True)
    parts = sorted((tmp_path / "whole" / "chunks").glob("part-*.parquet"))
    assert len(parts) >= 3, "the test needs a run of three batches or more"
    cut = tmp_path / "cut"
    (cut / "chunks").mkdir(parents=True)
    for name in (
        "mjx_pick_run.json",
        "config.json",
        "chunks/plan.json",
        *(f"chunks/{p.name}" for p in parts[:2]),
    ):
        shutil.copy2(tmp_path / "whole" / name, cut / name)
    stamps = {p.name: (cut / "chunks" / p.name).stat().st_mtime_ns for p in parts[:2]}
    with pytest.raises(mp.ConfigError, match="--resume"):
        evaluate(block, **run, out=cut)
    resumed = evaluate(block, **run, out=cut, resume=True, keep_chunks=True)
    assert resumed.table.equals(whole.table)
    for name, stamp in stamps.items():
        assert (cut / "chunks" / name).stat().st_mtime_ns == stamp, f"{name} was redone"
    assert len(list((cut / "chunks").glob("part-*.parquet"))) == len(parts)


def test_stability_check_moves_the_object_and_marks_the_labels_it_flips(block):
    ev = evaluate(block, n=8, seed=3, grasp=FAST, backend="mujoco", stability_um=1.0, n_traces=0)
    t = ev.table.to_pandas()
    assert {"success_shifted", "score_shifted", "label_stable"} <= set(t.columns)
    assert (t["label_stable"] == (t["success"] == t["success_shifted"])).all()
    assert ev.summary["labels_unstable"] == int((~t["label_stable"]).sum())
    # the micrometre reached the physics (the C engine is deterministic: without the
    # shift every score would be equal), and moved the scores by little
    diff = (t["score"] - t["score_shifted"]).abs()
    assert (diff > 0).any() and diff.median() < 0.05
    with pytest.raises(mp.ConfigError, match="stability_um"):
        evaluate(block, n=8, grasp=FAST, backend="mujoco", stability_um=-1)
    with pytest.raises(mp.ConfigError, match="Ray"):
        evaluate(block, n=8, grasp=FAST, stability_um=1.0, ray="127.0.0.1:1")


def test_step_check_is_the_same_pick_points_at_half_the_time_step(block, tmp_path, capsys):
    run = dict(n=6, seed=3, grasp=FAST, backend="mujoco", n_traces=0)
    ev = evaluate(block, step_check=True, **run)
    t = ev.table.to_pandas()
    # the check's labels are those of a run of its own at half the step
    half = evaluate(block, solver=mp.SolverParams(timestep_s=0.0005), **run).table.to_pandas()
    assert (t["success_half_step"] == half["success"]).all()
    assert (t["label_converged"] == (t["success"] == t["success_half_step"])).all()
    assert ev.summary["labels_unconverged"] == int((~t["label_converged"]).sum())
    # a step that cannot be halved is refused before anything runs or is written
    out = tmp_path / "refused"
    with pytest.raises(mp.ConfigError, match="--step-check halves solver.timestep_s = 1e-05"):
        evaluate(block, solver=mp.SolverParams(timestep_s=1e-5), step_check=True, out=out, **run)
    assert not out.exists()
    with pytest.raises(mp.ConfigError, match="Ray"):
        evaluate(block, n=8, grasp=FAST, step_check=True, ray="127.0.0.1:1")


def test_a_presets_force_range_gives_the_default_grip_force(tmp_path, capsys):
    # `--gripper onrobot-rg2` failed with the default 50 N (its range is 3-40 N)
    from mjx_pick.cli import inputs

    rg2 = mp.load_gripper("onrobot-rg2")
    grasp, note = GraspConfig().fitted_to(rg2)
    assert grasp.grip_force_n == 40.0 and "outside onrobot-rg2's 3-40 N: using 40 N" in note
    assert GraspConfig().fitted_to(mp.load_gripper("robotiq-2f85")) == (GraspConfig(), None)
    parse = cli.build_parser().parse_args
    args = parse(["evaluate", "block", "--gripper", "onrobot-rg2"])
    assert inputs.inputs_of(args)[4].grip_force_n == 40.0
    assert "using 40 N" in capsys.readouterr().err
    # a force the user set is never moved
    args = parse(["evaluate", "block", "--gripper", "onrobot-rg2", "--grip-force-n", "50"])
    assert inputs.inputs_of(args)[4].grip_force_n == 50.0
    grasp_file = tmp_path / "g.toml"
    grasp_file.write_text("grip_force_n = 50.0\n")
    args = parse(["evaluate", "block", "--gripper", "onrobot-rg2", "--grasp", str(grasp_file)])
    assert inputs.inputs_of(args)[4].grip_force_n == 50.0
    code = cli.main(["evaluate", "block", "--gripper", "onrobot-rg2", "--grip-force-n", "50"])
    assert code == 2 and "grip_force_n = 50 is out of range" in capsys.readouterr().err
    with pytest.warns(UserWarning, match="using 40 N"), pytest.raises(mp.ConfigError):
        evaluate("block", "onrobot-rg2", n=1, backend="mujoco", resume=True)  # stops: no --out


def test_optimization_mode_stops_at_a_small_batch_and_view_finds_the_best_trace(tmp_path):
    from mjx_pick.outputs.reporting.viewer import check_view
    from mjx_pick.studies.evaluation import until_batch

    assert until_batch(20, 1024) == 64 and until_batch(1, 1024) == 32
    assert until_batch(1000, 256) == 256  # never above the backend's batch
    block = mp.load_asset("block")
    grasp = mp.GraspConfig(close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)
    out = tmp_path / "opt"
    ev = mp.evaluate(
        block,
        until=2,
        min_score=0.5,
        max_n=500,
        grasp=grasp,
        backend="mujoco",
        out=out,
        n_traces=1,
    )
    # batches of 32 until found, not a whole device batch (1,024 on the CPU) at once
    assert ev.config["chunk_size"] == 32
    assert ev.table.num_rows % 32 == 0 and ev.table.num_rows < 500
    run, trace, scene = check_view(out, "best")  # the README's `view --pick best`
    assert scene.is_file() and run.traced()[0][1] == "best"
    with pytest.raises(mp.ConfigError, match="a traced pick_id, best or worst"):
        check_view(out, "middle")
