"""Label export in the field's grasp formats: each file read back by a reader written here
against the format's published field list (not mjx_pick's own reader), the poses
checked against the documented transform, the object's mesh beside the file, and every
error a user can meet."""

import json
import shutil

import h5py
import numpy as np
import pyarrow.parquet as pq
import pytest
import trimesh
import yaml
from scipy.spatial.transform import Rotation

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core.config import ConfigError
from mjx_pick.core.mjcf_gripper import characterise
from mjx_pick.core.procedure import GraspConfig

PROC = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.3)
FORMATS = ("acronym", "graspgen", "isaac-grasp")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """An evaluate folder of a parametric jaw and one of a linkage (MJCF) gripper."""
    root = tmp_path_factory.mktemp("runs")
    out = {}
    for gripper in ("robotiq-2f85", "robotiq-2f85-linkage"):
        mp.evaluate("door_opener", gripper, n=4, seed=1, grasp=PROC, out=root / gripper)
        out[gripper] = root / gripper
    return out


def published(fmt: str, path):
    """(transforms (N,4,4), success (N,) bool, mesh file, scale) by the format's own
    field list: ACRONYM's load_grasps/load_mesh, GraspGen's documented json loading, the
    isaac_grasp specification."""
    if fmt == "acronym":
        with h5py.File(path, "r") as data:
            t = np.array(data["grasps/transforms"])
            ok = np.array(data["grasps/qualities/flex/object_in_gripper"]) == 1
            return t, ok, data["object/file"][()].decode("utf-8"), data["object/scale"][()]
    if fmt == "graspgen":
        with open(path) as f:
            d = json.load(f)
        grasps = np.array(d["grasps"]["transforms"])
        mask = np.array(d["grasps"]["object_in_gripper"])
        assert mask.dtype == bool  # the loader indexes grasps[grasp_mask]
        return grasps, mask, d["object"]["file"], d["object"]["scale"]
    with open(path) as f:
        d = yaml.safe_load(f)
    assert d["format"] == "isaac_grasp" and d["format_version"] == 1.0
    t, ok = [], []
    for g in d["grasps"].values():
        m = np.eye(4)
        q = g["orientation"]
        m[:3, :3] = Rotation.from_quat([*q["xyz"], q["w"]]).as_matrix()
        m[:3, 3] = g["position"]
        t.append(m)
        ok.append(g["confidence"] > 0)
        assert 0.0 <= g["confidence"] <= 1.0
    return np.array(t), np.array(ok), d["object_file"], d["object_scale"]


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("gripper", ["robotiq-2f85", "robotiq-2f85-linkage"])
def test_export_reads_back_with_the_formats_own_fields(runs, tmp_path, fmt, gripper):
    run = runs[gripper]
    suffix = {"acronym": ".h5", "graspgen": ".json", "isaac-grasp": ".yaml"}[fmt]
    written = mp.export_labels(run, fmt, tmp_path / f"grasps{suffix}")
    table = pq.read_table(run / "results.parquet")
    transforms, ok, mesh_file, scale = published(fmt, written["labels"])
    n = table.num_rows
    assert transforms.shape == (n, 4, 4) and ok.tolist() == table["success"].to_pylist()
    # rigid transforms: rotation orthonormal, right-handed; last row 0 0 0 1
    rot = transforms[:, :3, :3]
    np.testing.assert_allclose(
        rot @ rot.transpose(0, 2, 1), np.tile(np.eye(3), (n, 1, 1)), atol=1e-6
    )
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-6)
    np.testing.assert_allclose(transforms[:, 3], np.tile([0, 0, 0, 1.0], (n, 1)))
    # the mesh beside the file, by the file's own reference and scale: the part as simulated
    mesh = trimesh.load(written["labels"].parent / mesh_file, force="mesh")
    mesh.apply_scale(scale)
    assert written["mesh"].name == mesh_file and scale == 1.0
    assert mesh.volume == pytest.approx(2095.1e-9 * 5.0, rel=0.02)  # area x 5 mm
    np.testing.assert_allclose(mesh.bounds[:, 2], [0.0, 0.005], atol=1e-9)
    # our own reader returns what was written, with the extras
    back = mp.read_labels(written["labels"])
    np.testing.assert_allclose(back.transforms, transforms, atol=1e-8)
    assert back.pick_id.tolist() == table["pick_id"].to_pylist()
    np.testing.assert_allclose(back.score, table["score"].to_numpy(), atol=1e-6)


@pytest.mark.parametrize("gripper", ["robotiq-2f85", "robotiq-2f85-linkage"])
def test_the_pose_is_the_documented_transform(runs, tmp_path, gripper):
    """E = G turned about x at the gripper's base: the object's origin, lifted to the grasp
    centre's height, lies at (x, -y, depth) in E; E's z points down, its x is G's x."""
    run = runs[gripper]
    labels = mp.read_labels(mp.export_labels(run, "graspgen", tmp_path / "g.json")["labels"])
    table = pq.read_table(run / "results.parquet").to_pandas()
    config = json.loads((run / "config.json").read_text())
    g = mp.load_gripper(gripper)
    z_tcp = (config["scene"]["fingertip_height_mm"] + 0.5 * g.pad_height_mm) * 1e-3
    mount = 0.0 if g.mjcf is None else -float(characterise(g.mjcf).pad_centre_z[0])
    for k, row in table.iterrows():
        t = labels.transforms[k]
        depth = mount + (row.height_compensation_mm * 1e-3 if g.mjcf is not None else 0.0)
        assert labels.depth_m[k] == pytest.approx(depth, abs=1e-9)
        local = np.linalg.inv(t) @ [0.0, 0.0, z_tcp, 1.0]
        np.testing.assert_allclose(local[:3], [row.x_mm * 1e-3, -row.y_mm * 1e-3, depth], atol=1e-9)
        np.testing.assert_allclose(t[:3, 2], [0, 0, -1], atol=1e-12)  # approach: down
        yaw = np.radians(row.yaw_deg)
        np.testing.assert_allclose(t[:3, 0], [np.cos(yaw), -np.sin(yaw), 0], atol=1e-9)
    if g.mjcf is not None:  # a linkage's base is its mount, 14 cm above its pads
        assert 0.1 < labels.depth_m.min()


def test_depth_mm_puts_the_base_behind_the_grasp_centre(runs, tmp_path):
    run = runs["robotiq-2f85"]
    a = mp.read_labels(mp.export_labels(run, "acronym", tmp_path / "a.h5")["labels"])
    b = mp.read_labels(
        mp.export_labels(run, "acronym", tmp_path / "b.h5", depth_mm=103.4)["labels"]
    )
    np.testing.assert_allclose(b.depth_m, 0.1034)
    # the same grasp centre: base + depth along the approach
    tcp_a = a.transforms[:, :3, 3]
    tcp_b = b.transforms[:, :3, 3] + 0.1034 * b.transforms[:, :3, 2]
    np.testing.assert_allclose(tcp_a, tcp_b, atol=1e-9)


def test_the_cli_writes_each_format_once(runs, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(runs["robotiq-2f85"], run)
    assert main(["export", str(run), "--format", "isaac-grasp"]) == 0
    out = capsys.readouterr().out
    assert "grasps_isaac_grasp.yaml" in out and (run / "grasps_isaac_grasp_object.obj").is_file()
    assert main(["export", str(run), "--format", "isaac-grasp"]) == 2  # a ConfigError
    assert "exists" in capsys.readouterr().err
    assert main(["export", str(run), "--format", "isaac-grasp", "--overwrite"]) == 0


def test_clear_errors(runs, tmp_path):
    run = runs["robotiq-2f85"]
    with pytest.raises(ConfigError, match=r"'hdf5' is not a grasp format: choose one of acronym"):
        mp.export_labels(run, "hdf5")
    with pytest.raises(ConfigError, match="is not an evaluate output folder"):
        mp.export_labels(tmp_path, "acronym")
    with pytest.raises(ConfigError, match=r"export.depth_mm = -5.0 is out of range"):
        mp.export_labels(run, "acronym", tmp_path / "d.h5", depth_mm=-5.0)
    with pytest.raises(ConfigError, match=r"format acronym ends in \.h5"):
        mp.export_labels(run, "acronym", tmp_path / "x.json")
    broken = tmp_path / "broken"
    shutil.copytree(run, broken)
    table = pq.read_table(broken / "results.parquet").drop_columns(["yaw_deg"])
    pq.write_table(table, broken / "results.parquet")
    with pytest.raises(ConfigError, match=r"has no yaw_deg column\(s\): it is not an evaluate"):
        mp.export_labels(broken, "graspgen")
    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(ConfigError, match="is not a GraspGen grasp file"):
        mp.read_labels(tmp_path / "x.json")
    with pytest.raises(ConfigError, match="its suffix names none"):
        mp.read_labels(tmp_path / "x.txt")
