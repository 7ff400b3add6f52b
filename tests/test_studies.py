"""Sweeps, gripper comparison and design search, robustness, minimum grip force:
each against a case whose answer is known."""

import dataclasses
import json
import re

import numpy as np
import pyarrow.parquet as pq
import pytest
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import to_toml
from mjx_pick.core.procedure import GraspConfig, min_grasp_force_n
from mjx_pick.studies.robust import robust_best
from mjx_pick.studies.sweeps import ParamSpec, apply, variants

# short procedure: 30 mm lift, 0.2 s hold
FAST = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.2)
LIGHT = mp.GripperSpec(name="light-gripper", force_min_n=1.0)


@pytest.fixture(scope="module")
def heavy_block():
    # 1 kg, 40 x 20 x 20 mm: friction decides, eq. (1) is ~10 N at mu 0.5
    return mp.object_from_polygon(box(-20, -10, 20, 10), thickness_mm=20, mass_g=1000, name="heavy")


def test_param_parsing():
    p = ParamSpec.parse("contact.pad_friction=0.4:1.0:4")
    assert p.name == "contact.pad_friction" and np.allclose(p.values, [0.4, 0.6, 0.8, 1.0])
    assert ParamSpec.parse("controller.force_n=20,40").name == "grasp.grip_force_n"
    log = ParamSpec.parse("contact.pad_stiffness_n_per_mm=1:100:3:log")
    assert np.allclose(log.values, [1, 10, 100])
    rnd = ParamSpec.parse("gripper.stroke_mm=40:90")
    assert rnd.values == () and (rnd.low, rnd.high) == (40, 90)
    combos = variants([p, ParamSpec.parse("controller.force_n=20,40")])
    assert len(combos) == 8
    drawn = variants([rnd], random=5, seed=1)
    assert len(drawn) == 5 and all(40 <= c["gripper.stroke_mm"] <= 90 for c in drawn)
    with pytest.raises(mp.ConfigError, match="unknown parameter 'contact.nope'"):
        ParamSpec.parse("contact.nope=1:2:3")
    with pytest.raises(mp.ConfigError, match="write NAME=LO:HI:N"):
        ParamSpec.parse("contact.pad_friction")
    with pytest.raises(mp.ConfigError, match="a grid sweep needs"):
        variants([rnd])
    # values are validated by the settings themselves, naming the field
    with pytest.raises(mp.ConfigError, match="contact.pad_friction = -0.5 is out of range"):
        apply(mp.Settings(), "contact.pad_friction", -0.5)
    with pytest.raises(mp.ConfigError, match="fingers cannot fit the stroke"):
        apply(mp.Settings(), "gripper.stroke_mm", 10)


def test_sweep_success_rises_with_pad_friction(heavy_block, tmp_path):
    base = mp.Settings(gripper=LIGHT, grasp=dataclasses.replace(FAST, grip_force_n=20.0))
    sim = mp.Simulator(heavy_block, "mujoco")
    res = mp.sweep(
        heavy_block,
        [ParamSpec.parse("contact.pad_friction=0.1,0.2,0.5,1.0")],
        base,
        n=8,
        seed=0,
        simulator=sim,
        out=tmp_path,
    )
    rates = [v["success_rate"] for v in res.variants]
    # m (g + a) / (2 F_d) = 0.30: below it nothing holds, above it the centred grasps do
    assert rates[0] == 0.0 and rates[1] == 0.0
    assert rates[3] >= rates[2] > 0.0
    assert len(sim.backends) == 1, "contact sweeps share one compiled simulation"
    table = pq.read_table(tmp_path / "results.parquet")
    assert table.num_rows == 32 and "contact.pad_friction" in table.column_names
    assert sorted(set(table["variant"].to_pylist())) == [0, 1, 2, 3]
    assert (tmp_path / "sweep.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "variants.json").read_text())[3]["n"] == 8


def test_sweep_of_gripper_geometry_shares_one_program(block):
    # a scene per width, one backend: the widths' model fields ride with the pick-points
    sim = mp.Simulator(block, "mujoco")
    res = mp.sweep(
        block,
        [ParamSpec.parse("gripper.finger_width_mm=12,30"), ParamSpec.parse("controller.kp=1,3")],
        mp.Settings(grasp=FAST),
        n=4,
        simulator=sim,
    )
    assert len(res.variants) == 4 and len(sim.backends) == 1 and sim.scenes == 2
    assert res.timing["programs"] == 1 and res.timing["scenes"] == 2
    assert res.table.num_rows == 16


def test_compare_ranks_a_gripper_too_small_for_the_object_last(block, tmp_path):
    tiny = dataclasses.replace(mp.GripperSpec(), name="tiny", stroke_mm=18.0, finger_depth_mm=4)
    grippers = [tiny, mp.load_gripper("robotiq-2f85"), mp.load_gripper("onrobot-rg2")]
    res = mp.compare(block, grippers, mp.Settings(grasp=FAST), n=12, backend="mujoco", out=tmp_path)
    assert res.ranking[-1]["gripper"] == "tiny"
    assert res.ranking[-1]["success_rate"] == 0.0 and res.ranking[-1]["feasible"] == 0
    assert res.ranking[0]["success_rate"] > 0.5
    assert res.ranking[-1]["p_vs_best"] < 0.01  # McNemar on the shared pick-points
    lo, hi = res.ranking[0]["success_ci"]
    assert lo <= res.ranking[0]["success_rate"] <= hi
    # the RG2 cannot squeeze 50 N: it is compared at its strongest
    rg2 = next(r for r in res.ranking if r["gripper"] == "onrobot-rg2")
    assert rg2["grip_force_n"] == 40.0
    for name in ("ranking.json", "ranking.png", "maps.png", "results.parquet"):
        assert (tmp_path / name).is_file(), name


def test_design_search_finds_a_stroke_that_fits(block, tmp_path):
    base = mp.Settings(gripper=dataclasses.replace(mp.GripperSpec(), name="narrow", stroke_mm=28))
    res = mp.design_search(
        block,
        {"stroke_mm": (20.0, 85.0)},
        base,
        variants=4,
        n=8,
        rounds=2,
        final_n=12,
        backend="mujoco",
        out=tmp_path,
    )
    # the block is 20 mm wide: a 28 mm stroke leaves no room for the 2 x 5 mm safety zone
    assert res.best.stroke_mm > 30
    best, narrow = (
        next(r for r in res.final.ranking if r["gripper"] == g.name) for g in (res.best, res.base)
    )
    assert best["success_rate"] > narrow["success_rate"]
    assert mp.load_gripper(tmp_path / "best_gripper.toml") == res.best


def test_design_search_stopped_resumes_from_its_chunks_and_a_complete_one_reads_back(
    block, tmp_path
):
    # the rounds' chunks are kept under out as they finish (the resume every command
    # has): a search stopped after its first chunk resumes to the uninterrupted result
    grasp = GraspConfig(close_timeout_s=0.6, lift_height_mm=5.0, hold_s=0.05)
    base = mp.Settings(grasp=grasp)
    bounds = {"finger_width_mm": (14.0, 30.0)}
    run = dict(variants=2, n=4, rounds=2, final_n=4, backend="mujoco", batch_size=4)
    whole = mp.design_search(block, bounds, base, **run, out=tmp_path / "whole")
    sim = mp.Simulator(block, "mujoco", 4)

    def ctrl_c(done: int, _total: int) -> None:
        if done > 0:
            raise KeyboardInterrupt

    sim.runner.on_progress = ctrl_c
    out = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        mp.design_search(block, bounds, base, **run, out=out, simulator=sim)
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    assert len(list((out / "chunks").glob("part-*.parquet"))) == 1
    with pytest.raises(mp.ConfigError, match="pass --resume"):
        mp.design_search(block, bounds, base, **run, out=out)
    resumed = mp.design_search(block, bounds, base, **run, out=out, resume=True)
    assert resumed.best == whole.best
    assert json.dumps(resumed.rounds) == json.dumps(whole.rounds)  # NaN-safe equality
    assert resumed.final.table.equals(whole.final.table)
    assert not (out / "chunks").exists(), "a complete search's chunks are removed"
    again = mp.design_search(block, bounds, base, **run, out=out, resume=True)
    assert again.final.already_complete and again.best == whole.best
    assert json.dumps(again.rounds) == json.dumps(whole.rounds)  # NaN-safe
    assert json.dumps(again.final.ranking) == json.dumps(whole.final.ranking)


def test_min_grip_force_of_a_centred_block_matches_coulomb(heavy_block):
    # the smallest force that lifts a centred block is Coulomb's with the lift's
    # acceleration, m (g + a) / (2 mu). At a = 4 m/s^2 it is 1.41x the static need, so
    # it cannot be mistaken for eq. (1) with its safety factor 1.1
    mu, accel = 0.5, 4.0
    grasp = GraspConfig(close_timeout_s=1.0, lift_accel_mm_s2=accel * 1e3)
    base = mp.Settings(gripper=LIGHT, contact=mp.ContactParams(pad_friction=mu), grasp=grasp)
    picks = pp.FeasibilityChecker(heavy_block, LIGHT).batch(
        np.arange(1), np.zeros(1), np.zeros(1), np.zeros(1), "user"
    )
    force = mp.min_grip_force(heavy_block, picks, base, hi_n=60.0, backend="mujoco")
    coulomb = heavy_block.mass_kg * (9.81 + accel) / (2 * mu)
    eq1 = min_grasp_force_n(heavy_block, mu, grasp.safety_factor)  # S_f = 1.1
    assert abs(coulomb / eq1 - 1) > 0.2  # the two differ: the test can tell them apart
    assert force[0] == pytest.approx(coulomb, rel=0.10)


def test_robust_probability_of_centred_and_edge_grasps():
    # a 120 mm bar gripped across its middle is robust; 40 mm from its centre of mass
    # with low friction it swings out of the grip under most draws
    bar = mp.object_from_polygon(box(-60, -5, 60, 5), thickness_mm=10, mass_g=300, name="bar")
    gripper = mp.GripperSpec()
    picks = pp.FeasibilityChecker(bar, gripper).batch(
        np.arange(2), np.zeros(2), np.array([0.0, 40.0]), np.full(2, 90.0), "user"
    )
    base = mp.Settings(
        contact=mp.ContactParams(pad_friction=0.3),
        grasp=dataclasses.replace(FAST, grip_force_n=20.0, hold_s=0.3),
    )
    table = mp.robustness(bar, picks, base, m=16, seed=0, backend="mujoco").to_pylist()
    by_id = {row["pick_id"]: row for row in table}
    assert by_id[0]["robust_p"] >= 0.9
    assert by_id[1]["robust_p"] <= 0.5
    assert table[0]["pick_id"] == 0 and table[0]["rank"] == 1
    assert by_id[1]["robust_ci_low"] <= by_id[1]["robust_p"] <= by_id[1]["robust_ci_high"]


def _ctrl_c_after_a_chunk(done: int, _total: int) -> None:
    if done > 0:
        raise KeyboardInterrupt


def test_robust_stopped_resumes_from_its_chunks_to_the_uninterrupted_table(block, tmp_path):
    # robust keeps its chunks as every command does: stopped after its first chunk (the
    # n pick-points' simulation), --resume gives the uninterrupted table; a complete
    # run reads back; another setting is refused, named
    grasp = GraspConfig(close_timeout_s=0.6, lift_height_mm=5.0, hold_s=0.05)
    base = mp.Settings(grasp=grasp)
    run = dict(n=6, top_k=2, m=4, seed=1, backend="mujoco", batch_size=4)
    whole = robust_best(block, base, **run, out=tmp_path / "whole")
    sim = mp.Simulator(block, "mujoco", 4)
    sim.runner.on_progress = _ctrl_c_after_a_chunk
    out = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        robust_best(block, base, **run, out=out, simulator=sim)
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    assert len(list((out / "chunks").glob("part-*.parquet"))) == 1
    with pytest.raises(mp.ConfigError, match="pass --resume"):
        robust_best(block, base, **run, out=out)
    with pytest.raises(mp.ConfigError, match=r"changed: m: 4 -> 5"):
        robust_best(block, base, **{**run, "m": 5}, out=out, resume=True)
    resumed = robust_best(block, base, **run, out=out, resume=True)
    assert resumed.equals(whole)
    assert pq.read_table(out / "robustness.parquet").equals(whole)
    assert not (out / "chunks").exists(), "a complete run's chunks are removed"
    again = robust_best(block, base, **run, out=out, resume=True)
    assert again.equals(whole)


def test_robust_in_an_evaluate_folder_resumes_from_its_own_chunks(block, tmp_path):
    # robust adds its ranking to the evaluate folder the pick-points came from: its
    # chunks are its own (chunks/robust/), evaluate's manifest and files stay, and a
    # stopped run resumes to the uninterrupted table
    grasp = GraspConfig(close_timeout_s=0.6, lift_height_mm=5.0, hold_s=0.05)
    run = dict(n=8, seed=2, backend="mujoco", batch_size=4)
    base = mp.Settings(grasp=grasp)
    folders = {}
    for name in ("whole", "cut"):
        folders[name] = tmp_path / name
        mp.evaluate(block, options=mp.RunOptions(**run, out=folders[name]), grasp=grasp)
    manifest = json.loads((folders["cut"] / "mjx_pick_run.json").read_text())
    draws = dict(top_k=2, m=4, seed=2, backend="mujoco", batch_size=4)
    whole = robust_best(block, base, results=folders["whole"], **draws, out=folders["whole"])
    out = folders["cut"]
    sim = mp.Simulator(block, "mujoco", 4)
    sim.runner.on_progress = _ctrl_c_after_a_chunk
    with pytest.raises(KeyboardInterrupt):
        robust_best(block, base, results=out, **draws, out=out, simulator=sim)
    assert json.loads((out / "run-robust.json").read_text())["status"] == "interrupted"
    assert len(list((out / "chunks" / "robust").glob("part-*.parquet"))) == 1
    with pytest.raises(mp.ConfigError, match=r"changed: sigma_xy_mm: 2.0 -> 3.0"):
        robust_best(block, base, results=out, **draws, sigma_xy_mm=3.0, out=out, resume=True)
    resumed = robust_best(block, base, results=out, **draws, out=out, resume=True)
    assert resumed.equals(whole)
    assert not (out / "chunks").exists(), "a complete run's chunks are removed"
    assert json.loads((out / "mjx_pick_run.json").read_text()) == manifest, "evaluate's"
    record = json.loads((out / "run-robust.json").read_text())
    assert record["status"] == "complete" and record["config_key"]
    again = robust_best(block, base, results=out, **draws, out=out, resume=True)
    assert again.equals(whole)


def test_cli_studies(tmp_path, capsys):
    grasp = tmp_path / "grasp.toml"
    grasp.write_text(to_toml(FAST))
    common = ["block", "--grasp", str(grasp), "--backend", "mujoco", "--seed", "0"]
    assert (
        main(
            [
                "sweep",
                *common,
                "--n",
                "4",
                "--param",
                "controller.force_n=20,40",
                "--out",
                str(tmp_path / "sw"),
            ]
        )
        == 0
    )
    assert (tmp_path / "sw" / "results.parquet").is_file()
    # progress on stderr (not a terminal here: whole lines, the last one once)
    err = capsys.readouterr().err
    assert "\r" not in err and err.count("sweep: 2 variants (mujoco): 100% 8/8 sim") == 1, err
    assert (
        main(
            [
                "compare",
                *common,
                "--n",
                "6",
                "--grippers",
                "robotiq-2f85,franka-hand",
                "--out",
                str(tmp_path / "cmp"),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert re.search(r"compare: 2 grippers \(mujoco\): 100% (\d+)/\1 sim", err), err
    assert (
        main(
            [
                "robust",
                *common,
                "--n",
                "6",
                "--top-k",
                "2",
                "--m",
                "4",
                "--out",
                str(tmp_path / "rb"),
            ]
        )
        == 0
    )
    assert pq.read_table(tmp_path / "rb" / "robustness.parquet").num_rows == 2
    # one bar over both stages, its total growing: the 6 pick-points, then the draws
    lines = capsys.readouterr().err.splitlines()
    first, last = re.fullmatch(r"robust \(mujoco\): 100% 6/6 sim .*", lines[0]), lines[-1]
    total = re.fullmatch(r"robust \(mujoco\): 100% (\d+)/\1 sim .*", last)
    assert first and total and int(total[1]) > 6, lines
    assert sum(f"{total[1]}/{total[1]}" in line for line in lines) == 1, lines
    assert (
        main(
            [
                "evaluate",
                *common,
                "--n",
                "3",
                "--min-force",
                "--traces",
                "0",
                "--no-progress",
                "--out",
                str(tmp_path / "ev"),
            ]
        )
        == 0
    )
    assert "%" not in capsys.readouterr().err, "--no-progress shows none"
    table = pq.read_table(tmp_path / "ev" / "results.parquet")
    forces = table["min_force_n"].to_numpy()
    found = np.isfinite(forces)
    # the 43 g block needs ~0.3 N (eq. 1): every pick that holds at all already holds at
    # the 2F-85's 20 N floor, and is flagged so instead of reading as "needs 20 N"
    assert found.any()
    assert np.all(forces[found] == 20.0)
    assert np.all(table["min_force_at_floor"].to_numpy()[found])
    # one run record in every folder, written the same way by every command
    for folder, command in (
        ("sw", "sweep"),
        ("cmp", "compare"),
        ("rb", "robust"),
        ("ev", "evaluate"),
    ):
        run = json.loads((tmp_path / folder / "run.json").read_text())
        assert run["command"] == command and run["status"] == "complete", folder
        assert run["backend"] == "mujoco" and run["device"].startswith("cpu:"), folder
        assert run["seed"] == 0 and run["versions"]["mujoco"], folder
        assert run["timing"]["run_s"] > 0 and run["timing"]["wall_s"] > 0, folder
        assert run["config"]["object"]["name"] == "block", folder
    assert main(["sweep", *common, "--param", "contact.nope=1:2:3"]) == 2
    assert "unknown parameter 'contact.nope'" in capsys.readouterr().err
    assert main(["design", *common, "--bound", "stroke=1:2"]) == 2
    assert "not a numeric gripper field" in capsys.readouterr().err


def test_robust_refuses_results_of_another_object(tmp_path, capsys, door_opener):
    # an evaluate folder of the door opener handed to `robust` for the block: refused
    # with the two names, before anything is simulated
    import pyarrow as pa

    run = tmp_path / "door"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"object": door_opener.summary()}))
    cols = {"pick_id": [0], "x_mm": [0.0], "y_mm": [0.0], "yaw_deg": [0.0], "score": [1.0]}
    pq.write_table(pa.table({**cols, "success": [True]}), run / "results.parquet")
    assert main(["robust", "block", "--results", str(run)]) == 2
    err = capsys.readouterr().err
    assert "object 'door_opener', not this run's 'block'" in err
