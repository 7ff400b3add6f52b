"""Grasps on meshes and from files, and physical trials: the 6-DoF checks, antipodal
candidates, the formats' round trip, TRIALS.csv's refusals and a small validate run."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from mjx_pick.core import grasps as g
from mjx_pick.core.antipodal import AntipodalConfig, antipodal_poses
from mjx_pick.core.config import ConfigError
from mjx_pick.core.grasp_checks import REASONS, GraspChecker
from mjx_pick.core.gripper import load_gripper
from mjx_pick.core.objects import load_asset, object_from_mesh
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import build_scene
from mjx_pick.studies.evaluation import evaluate

MJX_PICK = shutil.which("mjx-pick") or f"{sys.executable} -m mjx_pick.cli"
# the physical trials beside the project (never copied into it): ../shared/data
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "ipc_graspsim_cube"
FAST = {"grasp": GraspConfig(lift_height_mm=5.0, hold_s=0.05)}


@pytest.fixture(scope="module")
def block_scene():
    return build_scene(load_asset("block"), load_gripper("robotiq-2f85"))


def _vertical(x_mm, y_mm, height_mm) -> np.ndarray:
    """Grasp frames (N, 4, 4) straight down at (x, y, height) in the object frame."""
    n = len(x_mm)
    t = np.tile(np.eye(4), (n, 1, 1))
    t[:, :3, :3] = g.FLIP
    t[:, :3, 3] = np.stack([x_mm, y_mm, height_mm], 1) * 1e-3
    return t


@pytest.fixture(scope="module")
def post_scene(tmp_path_factory):
    """A 10 mm square post, 40 mm high, on a 120 x 10 x 5 mm plate, under a 2F-85."""
    from shapely.geometry import Polygon

    profile = Polygon([(-60, 0), (60, 0), (60, 5), (5, 5), (5, 40), (-5, 40), (-5, 5), (-60, 5)])
    mesh = trimesh.creation.extrude_polygon(profile, 10.0)  # x, y(up), extruded along z
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    path = tmp_path_factory.mktemp("post") / "post.stl"
    mesh.export(path)
    obj = object_from_mesh(path, unit="mm", mass_g=20.0)
    return build_scene(obj, load_gripper("robotiq-2f85"))


def test_the_checks_reject_only_what_the_gripper_cannot_do(post_scene):
    """Gripping the post (its 10 mm measured by the rays, the start opening by the speed
    rule): feasible; far beside it: nothing between the pads; low enough for the open
    fingers to land on the plate: they touch the part; lower, closing across the plate:
    the table; turned to approach from below: the table."""
    heights = [30.0, 30.0, 22.0, 10.0, 30.0]
    poses = _vertical([0, 200, 0, 0, 0], [0, 0, 0, 0, 0], heights)
    poses[3, :3, :3] = poses[3, :3, :3] @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    poses[4, :3, :3] = np.eye(3)  # E's z (the approach) up
    res = GraspChecker(post_scene, safety_zone_mm=5.0)(poses)
    reasons = [REASONS[r] for r in res["reason"]]
    assert reasons == ["feasible", "off_object", "collision", "table", "table"], reasons
    gap = res["opening_mm"][0] - res["gap_left_mm"][0] - res["gap_right_mm"][0]
    assert gap == pytest.approx(10.0, abs=0.01)
    assert res["opening_mm"][0] == pytest.approx(20.0, abs=0.01)  # 5 mm each side


def test_a_part_wider_than_the_stroke_is_too_wide():
    obj = load_asset("block")
    narrow = load_gripper("franka-hand")
    import dataclasses

    narrow = dataclasses.replace(narrow, stroke_mm=0.5 * (obj.mesh.extents[0] * 1e3))
    scene = build_scene(obj, narrow)
    top = obj.mesh.bounds[1, 2] * 1e3
    res = GraspChecker(scene)(_vertical([0], [0], [0.5 * top]))
    assert REASONS[res["reason"][0]] == "too_wide"


def test_antipodal_candidates_are_antipodal_from_above_and_clear_the_table():
    mesh = trimesh.creation.box((0.03, 0.05, 0.02))
    mesh.apply_translation((0, 0, 0.01))
    config = AntipodalConfig(max_tilt_deg=45.0)
    t = antipodal_poses(mesh, (85.0, 22.0, 38.0), config, np.random.default_rng(0))
    assert len(t) > 100
    rot = t[:, :3, :3]
    assert np.allclose(np.swapaxes(rot, 1, 2) @ rot, np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(rot), 1.0)
    # a box's antipodal pairs close along its axes; the approach is within 45 deg of down
    closing = np.abs(rot[:, :, 0])
    assert np.all(closing.max(axis=1) > np.cos(np.deg2rad(config.cone_deg)) - 1e-9)
    assert np.all(-rot[:, 2, 2] >= np.cos(np.deg2rad(45.0)) - 1e-9)
    # the pads' lowest corner stays table_clearance_mm above the table
    corners = np.array([(0, a * 11.0, b * 19.0) for a in (-1, 1) for b in (-1, 1)]) * 1e-3
    low = (t[:, None, :3, 3] + np.einsum("nij,kj->nki", rot, corners))[..., 2].min(axis=1)
    assert low.min() >= config.table_clearance_mm * 1e-3 - 1e-9


def test_antipodal_grasps_simulate_and_survive_a_file_round_trip(tmp_path, block_scene):
    """evaluate --grasps antipodal on the block, then its labels exported as each format
    and read back as grasps of the exported mesh: the same grasps, the same labels."""
    obj = block_scene.object
    run = evaluate(
        obj, "robotiq-2f85", n=4, grasps="antipodal", backend="mujoco", out=tmp_path / "r", **FAST
    )
    table = run.table
    assert {"height_mm", "tilt_deg", "grasp_pose"} <= set(table.column_names)
    assert len(table) == 4
    from mjx_pick.outputs.exchange import FORMATS, export_labels

    for fmt in FORMATS:
        files = export_labels(tmp_path / "r", fmt, tmp_path / f"g_{fmt}{_suffix(fmt)}")
        mesh = object_from_mesh(files["mesh"], unit="m", mass_g=obj.mass_kg * 1e3)
        back = evaluate(
            mesh, "robotiq-2f85", grasps=str(files["labels"]), backend="mujoco", **FAST
        ).table
        assert back["pick_id"].to_pylist() == table["pick_id"].to_pylist(), fmt
        assert back["success"].to_pylist() == table["success"].to_pylist(), fmt
        assert np.allclose(back["opening_mm"], table["opening_mm"], atol=1e-3), fmt


def _suffix(fmt: str) -> str:
    from mjx_pick.outputs import exchange

    return exchange._format(fmt).SUFFIX


def test_a_grasp_file_in_another_unit_is_refused_naming_the_distance(tmp_path, block_scene):
    far = _vertical([0.0], [0.0], [15.0])
    far[:, :3, 3] *= 1000.0  # poses in mm read as m
    path = tmp_path / "g.csv"
    rows = " ".join(f"{v:g}" for v in far[0].ravel())
    path.write_text(f"grasp_pose,depth_mm\n{rows},0\n")
    from mjx_pick.studies.grasp_sources import file_grasps

    with pytest.raises(ConfigError, match="unit or frame disagrees"):
        file_grasps(block_scene, path)


# ------------------------------------------------------------------ physical trials
def _trials_csv(folder: Path, rows: list[dict]) -> Path:
    """A TRIALS.csv of rows (missing columns: a 30 mm cube, 3 g, abb-yumi-smart, one
    vertical grasp over its centre) beside a cube mesh of our own."""
    mesh = trimesh.creation.box((0.03, 0.03, 0.03))
    mesh.export(folder / "cube.obj")
    grasp = _vertical([0.0], [0.0], [0.0])[0]
    base = {
        "object": "cube.obj",
        "mass_g": "3",
        "gripper": "abb-yumi-smart",
        "object_pose": " ".join(f"{v:g}" for v in np.eye(4).ravel()),
        "grasp_pose": " ".join(f"{v:g}" for v in grasp.ravel()),
        "depth_mm": "0",
        "success": "1",
    }
    columns = list(base) + ["trial"]
    lines = [",".join(columns)]
    for k, row in enumerate(rows):
        full = {**base, "trial": f"t{k}", **row}
        lines.append(",".join(str(full[c]) for c in columns if c in full))
    path = folder / "TRIALS.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(
    ("row", "match"),
    [
        ({"trial": "t0"}, "line 3, column trial: 't0' is the id of line 2"),
        ({"success": "yes"}, "line 3, column success"),
        ({"gripper": "nope"}, "line 3, column gripper: 'nope' is neither a gripper preset"),
        ({"mass_g": "-3"}, "line 3, column mass_g"),
        ({"grasp_pose": "1 2 3"}, "line 3, column grasp_pose"),
        ({"grasp_pose": " ".join(["1"] * 16)}, "grasp_pose: 1 pose.*line 3"),
        ({"object": "missing.obj"}, "line 3, column object"),
    ],
)
def test_a_trials_file_is_refused_naming_the_line_and_column(tmp_path, row, match):
    from mjx_pick.studies.validation import read_trials

    path = _trials_csv(tmp_path, [{}, row])
    with pytest.raises(ConfigError, match=match):
        read_trials(path)


def test_a_trials_file_without_success_is_refused(tmp_path):
    from mjx_pick.studies.validation import read_trials

    path = _trials_csv(tmp_path, [{}])
    text = path.read_text().replace(",success", "").replace(",1,t0", ",t0")
    path.write_text(text)
    with pytest.raises(ConfigError, match="no column.*success"):
        read_trials(path)


def test_repeats_of_a_grasp_on_a_part_at_its_stable_pose_are_one_grasp(tmp_path):
    """Trials that leave object_pose empty (the mesh's most stable pose): one scene,
    and a grasp's repeats one grasp -- as with the pose given."""
    from mjx_pick.studies.validation import read_trials

    far = _vertical([10.0], [0.0], [0.0])[0]
    other = {"grasp_pose": " ".join(f"{v:g}" for v in far.ravel())}
    for pose in ("", " ".join(f"{v:g}" for v in np.eye(4).ravel())):
        rows = [{"object_pose": pose}, {"object_pose": pose}, {**other, "object_pose": pose}]
        trials = read_trials(_trials_csv(tmp_path, rows))
        assert trials.grasp_index().tolist() == [0, 0, 1], pose
        assert len(trials.groups()) == 1, pose


def test_validation_figures_follow_the_confusion_matrix():
    from mjx_pick.studies.validation import figures

    real = np.array([1, 1, 1, 0, 0, 1, 1, 0], bool)
    sim = np.array([1, 1, 0, 0, 1, 1, 1, 1], bool)
    f = figures(real, sim, grasp=np.arange(8), seed=0, resamples=500)
    assert f["confusion"] == {"tp": 4, "fp": 2, "fn": 1, "tn": 1}
    assert f["accuracy"]["value"] == pytest.approx(5 / 8)
    assert f["precision"]["value"] == pytest.approx(4 / 6)
    assert f["recall"]["value"] == pytest.approx(4 / 5)
    assert f["f1"]["value"] == pytest.approx(8 / 11)
    for name in ("accuracy", "precision", "recall", "f1"):
        lo, hi = f[name]["ci95"]
        assert lo <= f[name]["value"] <= hi


@pytest.mark.skipif(not SHARED.is_dir(), reason=f"the public cube trials are not at {SHARED}")
def test_validate_on_the_public_cube_trials(tmp_path):
    """mjx-pick validate on the IPC-GraspSim cube trials (read where they lie): every
    trial labelled, the figures consistent with the confusion matrix, the output's
    documented fields."""
    out = tmp_path / "val"
    res = subprocess.run(
        [*MJX_PICK.split(), "validate", str(SHARED / "trials.csv"), "--out", str(out)]
        + ["--backend", "mujoco"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    report = json.loads((out / "validation.json").read_text())
    assert isinstance(report["n"], int) and report["n"] == 125
    c = report["confusion"]
    assert c["tp"] + c["fp"] + c["fn"] + c["tn"] == 125
    for name in ("accuracy", "precision", "recall", "f1"):
        assert set(report[name]) == {"value", "ci95"}
    assert report["accuracy"]["value"] == pytest.approx((c["tp"] + c["tn"]) / 125)
    assert "cube_3cm.obj" in report["per_object"]
    assert "f1" in res.stdout


def test_a_folder_of_parts_runs_as_one_job_and_exports_per_part(tmp_path):
    """evaluate DIR --grasps antipodal through the installed command: each part in a
    run folder of its own, one table with an object column, a second call with --resume
    simulating nothing new; export writes each part's labels into its folder."""
    parts = tmp_path / "parts"
    parts.mkdir()
    trimesh.creation.box((0.04, 0.02, 0.02)).export(parts / "bar.stl")
    trimesh.creation.cylinder(radius=0.012, height=0.03).export(parts / "peg.stl")
    out = tmp_path / "set"
    argv = [*MJX_PICK.split(), "evaluate", str(parts), "--density-kg-m3", "1200"]
    argv += ["--grasps", "antipodal", "--n", "3", "--out", str(out), "--backend", "mujoco"]
    argv += ["--lift-height-mm", "5", "--hold-s", "0.05", "--no-progress", "--traces", "0"]
    # an option of one part refused for every part before any folder, never dropped
    refused = subprocess.run([*argv, "--simplify-mm", "1"], capture_output=True, text=True)
    assert refused.returncode != 0 and "simplify_mm does not apply" in refused.stderr
    assert not out.exists()
    argv += ["--material", "rubber"]  # one that applies: every part takes it
    res = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    for part in ("bar", "peg"):
        config = json.loads((out / "objects" / part / "config.json").read_text())
        assert config["object"]["material"] == "rubber"
    import pyarrow.parquet as pq

    table = pq.read_table(out / "results.parquet")
    assert sorted(set(table["object"].to_pylist())) == ["bar", "peg"]
    assert table.num_rows == 6 and "grasp_pose" in table.column_names
    summary = json.loads((out / "summary.json").read_text())
    assert summary["parts"] == 2 and summary["n"] == 6
    written = (out / "objects" / "bar" / "results.parquet").stat().st_mtime_ns
    again = subprocess.run([*argv, "--resume"], capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-3000:]
    # each part's complete folder read back, not simulated again
    assert (out / "objects" / "bar" / "results.parquet").stat().st_mtime_ns == written
    exp = subprocess.run(
        [*MJX_PICK.split(), "export", str(out), "--format", "csv"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert exp.returncode == 0, exp.stderr[-3000:]
    assert (out / "objects" / "bar" / "grasps_csv.csv").is_file()
    assert (out / "objects" / "peg" / "grasps_csv_object.obj").is_file()


def test_robust_ranks_grasps_given_as_poses(tmp_path, block_scene):
    """robust on an antipodal run: its best grasps, their planar part perturbed, their
    tilt kept (the draws checked by the 6-DoF checks), ranked."""
    from mjx_pick.core.settings import Settings
    from mjx_pick.studies.robust import robust_best

    run = tmp_path / "r"
    evaluate(block_scene.object, "robotiq-2f85", n=3, grasps="antipodal", backend="mujoco",
             out=run, n_traces=0, **FAST)  # fmt: skip
    base = Settings(load_gripper("robotiq-2f85"), grasp=FAST["grasp"])
    ranked = robust_best(
        block_scene.object, base, results=run, top_k=2, m=2, sigma_xy_mm=1.0, backend="mujoco"
    )
    assert ranked.num_rows == 2 and set(ranked["trials"].to_pylist()) == {2}
    ids = set(ranked["pick_id"].to_pylist())
    import pyarrow.parquet as pq

    assert ids <= set(pq.read_table(run / "results.parquet")["pick_id"].to_pylist())


def test_compare_ranks_grippers_on_one_shared_set_of_antipodal_grasps(block_scene):
    """compare --grasps antipodal: one candidate set checked on every gripper's scene,
    a grasp a gripper cannot take its failure, the same candidates for each."""
    from mjx_pick.core.settings import Settings
    from mjx_pick.studies.comparison import compare

    grippers = [load_gripper("robotiq-2f85"), load_gripper("onrobot-rg2")]
    res = compare(
        block_scene.object, grippers, Settings(grasp=FAST["grasp"]), n=3, grasps="antipodal",
        backend="mujoco",
    )  # fmt: skip
    assert [row["gripper"] for row in res.ranking] and res.success.shape == (2, 3)
    assert res.feasible.any(axis=0).all()  # every candidate taken by some gripper
    assert {"tilt_deg", "grasp_pose"} <= set(res.table.column_names)


def test_design_searches_grippers_on_antipodal_grasps(block_scene, tmp_path):
    """design --grasps antipodal: its rounds and final compare the variants on shared
    antipodal grasps; the folder records the source and reads back complete."""
    import json

    from mjx_pick.core.settings import Settings
    from mjx_pick.studies.comparison import design_search

    base = Settings(gripper=load_gripper("robotiq-2f85"), grasp=FAST["grasp"])
    run = dict(n=2, grasps="antipodal", backend="mujoco", out=tmp_path / "d")
    res = design_search(
        block_scene.object, {"finger_width_mm": (15.0, 30.0)}, base, variants=2, rounds=1,
        final_n=2, **run,
    )  # fmt: skip
    assert 15.0 <= res.best.finger_width_mm <= 30.0
    assert {"tilt_deg", "grasp_pose"} <= set(res.final.table.column_names)
    run_record = json.loads((tmp_path / "d" / "run.json").read_text())
    assert "antipodal" in json.dumps(run_record)  # the source in its resume key
    again = design_search(
        block_scene.object, {"finger_width_mm": (15.0, 30.0)}, base, variants=2, rounds=1,
        final_n=2, resume=True, **run,
    )  # fmt: skip
    assert again.final.already_complete and again.best == res.best
    np.testing.assert_array_equal(again.final.success, res.final.success)


def test_the_page_checks_the_model_file_of_a_gripper_toml_saved_with_a_bom(tmp_path):
    """A gripper TOML saved with a byte-order mark (Notepad) is read by the page's
    trials check as validate reads it: the model file it names must lie inside the work
    folder, as for any other TOML."""
    from mjx_pick.gui.trials_input import check_trials

    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "model.xml").write_text("<mujoco/>")
    toml = 'base = "robotiq-2f85"\nname = "g"\n[mjcf]\nfile = "../model.xml"\n'
    (work / "grip.toml").write_bytes(b"\xef\xbb\xbf" + toml.encode())
    path = _trials_csv(work, [{"gripper": "grip.toml"}])
    with pytest.raises(ConfigError, match=r"grip.toml: its \[mjcf\] file model.xml lies outside"):
        check_trials(path, work, "TRIALS.csv")


def test_a_trial_grasping_from_under_the_table_is_rejected_not_a_crash(tmp_path):
    """A trial whose grasp approaches from below (the identity pose: approach +z) is a
    grasp the checks reject for the table, counted as a predicted failure with no tilt;
    the other trials are simulated."""
    from mjx_pick.studies.options import RunOptions
    from mjx_pick.studies.validation import validate

    below = " ".join(f"{v:g}" for v in np.eye(4).ravel())
    path = _trials_csv(tmp_path, [{}, {"grasp_pose": below, "success": "0"}])
    fast = {"grasp": FAST["grasp"], "keep_grasp": ("lift_height_mm", "hold_s")}
    with pytest.warns(UserWarning, match="using 20 N"):  # the procedure fitted to the gripper
        res = validate(path, RunOptions(backend="mujoco"), **fast)
    rows = res.table.to_pylist()
    assert rows[1]["sim_outcome"] == "rejected: table" and not rows[1]["sim_success"]
    assert np.isnan(rows[1]["tilt_deg"]) and rows[0]["tilt_deg"] == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("grasps", "depth_mm", "match"),
    [
        ("antipodl", None, "neither 'topdown', 'antipodal' nor a grasp file"),
        ("missing.csv", None, "grasps file 'missing.csv' does not exist"),
        ("antipodal", 10.0, "depth_mm .--depth-mm. is for grasps read from a file"),
    ],
)
def test_every_study_refuses_a_grasp_source_before_any_folder(
    block_scene, tmp_path, grasps, depth_mm, match
):
    """The grasp source is checked with the run options, for every study alike (sweep
    and robust as evaluate and compare): nothing is written."""
    from mjx_pick.studies.robust import robust_best
    from mjx_pick.studies.sweeps import ParamSpec, sweep

    spec = ParamSpec.parse("contact.pad_friction=0.5,0.9")
    run = {"n": 2, "grasps": grasps, "depth_mm": depth_mm, "backend": "mujoco"}
    for study in (
        lambda out: sweep(block_scene.object, [spec], out=out, **run),
        lambda out: robust_best(block_scene.object, out=out, **run),
    ):
        with pytest.raises(ConfigError, match=match):
            study(tmp_path / "run")
        assert not (tmp_path / "run").exists()
