"""evaluate() and the mjx-pick CLI end to end: outputs, user pick-points, bad inputs."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

import mjx_pick as mp
from mjx_pick import cli
from mjx_pick.config import to_toml
from mjx_pick.evaluate import evaluate
from mjx_pick.grasp import GraspConfig
from mjx_pick.metrics import COLUMNS

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
        ]
    )
    assert code == 0
    table = pq.read_table(tmp_path / "o" / "results.parquet")
    np.testing.assert_allclose(table["x_mm"].to_numpy(), [0, 2])
    assert table["success"].to_numpy().all()
    assert "success rate" in capsys.readouterr().out


@pytest.mark.parametrize(
    "content, match",
    [
        ("x_mm,yaw_deg\n0,0\n", "missing column"),
        ("x_mm,y_mm,yaw_deg\n0,zero,0\n", "row 2"),
        ("x_mm,y_mm,yaw_deg\n0,0,0\n80,0,0\n", "row 3 \\(off_object\\)"),
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
        n=0 or 1,
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
    with pytest.raises(mp.ConfigError, match=r"row 3 \(off_object\).*--skip-infeasible"):
        evaluate(block, picks=picks, grasp=grasp, backend="mujoco", n_traces=0)
    with pytest.warns(UserWarning, match=r"1 of 3 .*row 3 \(off_object\); left out"):
        ev = evaluate(
            block, picks=picks, grasp=grasp, backend="mujoco", n_traces=0, skip_infeasible=True
        )
    # the kept rows keep their index in the file
    assert ev.table["pick_id"].to_pylist() == [0, 2]
