"""Grasps as poses: the conversion to and from 4x4 transforms, where the scene puts them,
and that pick-points are the vertical grasps (same labels as poses)."""

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mjx_pick.core import grasps as g
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.gripper import load_gripper
from mjx_pick.core.objects import load_asset
from mjx_pick.core.scene import build_scene
from mjx_pick.kernels import grasp as kg
from mjx_pick.kernels import types as kt

# float64 round trips of products of a few rotations: a few ulps of 1 and of 0.1 m
_ROUND_TRIP = 1e-12


def _random_poses(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.zeros((n, 4, 4))
    t[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    t[:, :3, 3] = rng.normal(0.0, 0.05, (n, 3))
    t[:, 3, 3] = 1.0
    return t


def test_poses_round_trip_through_the_planar_tilt_height_parts():
    t = _random_poses(400, 0)
    batch = g.from_poses(t)
    assert np.abs(g.poses(batch, 0.0) - t).max() < _ROUND_TRIP
    # each tilt is a rotation about a horizontal axis (no turn about z)
    assert np.abs(batch.tilt_quat[:, 3]).max() < _ROUND_TRIP
    assert np.allclose(np.linalg.norm(batch.tilt_quat, axis=1), 1.0)


def test_a_pick_point_is_the_vertical_grasp_at_the_grasp_height():
    picks = g.GraspBatch(
        np.arange(3),
        *(np.array(v, float) for v in ([1, -2, 30], [4, 5, -6], [10, 200, 350])),
        *(np.zeros(3) for _ in range(4)),
        rejected={},
        n_candidates=3,
    )
    t = g.poses(picks, 12.5)
    # docs/formats.md: R_OE = Rz(-yaw) diag(1, -1, -1), the object origin at (x, -y, h)
    # in E less the depth (0 here: E's origin at the grasp centre)
    yaw = np.deg2rad(picks.yaw_deg)
    assert np.allclose(t[:, :3, :3], g.rz(-yaw) @ g.FLIP)
    origin_in_e = np.einsum("nji,nj->ni", t[:, :3, :3], -t[:, :3, 3])
    assert np.allclose(origin_in_e * 1e3, np.stack([picks.x_mm, -picks.y_mm, 12.5 + 0 * yaw], 1))
    d = g.decompose(t)
    assert np.array_equal(d["tilt_quat"], np.tile([1.0, 0, 0, 0], (3, 1)))  # exactly vertical
    assert np.allclose(d["x_mm"], picks.x_mm) and np.allclose(d["height_mm"], 12.5)
    assert np.allclose(np.mod(d["yaw_deg"] - picks.yaw_deg + 180, 360) - 180, 0, atol=1e-9)


def test_an_approach_from_under_the_table_is_refused():
    t = np.eye(4)[None].copy()
    t[0, :3, :3] = np.diag([1.0, 1.0, 1.0])  # E's z (the approach) up: from below
    assert g.decompose(t)["upward"][0]
    with pytest.raises(ValueError, match="under the table"):
        g.from_poses(t)


@pytest.mark.parametrize("gripper", ["robotiq-2f85", "robotiq-2f85-linkage"])
def test_the_scene_puts_the_grasp_centre_and_axes_where_the_pose_says(gripper):
    """Placed (qpos and the tilt's model fields), the pads' centre and the gripper's
    axes, seen from the object, are the pose's -- for a parallel jaw and for a linkage
    whose pads descend as they close (its height compensation along the approach)."""
    obj, grip = load_asset("block"), load_gripper(gripper)
    scene = build_scene(obj, grip)
    t = _random_poses(6, 1)
    # above the table, approaching from above within 60 degrees of vertical
    t[:, :3, :3] = (
        Rotation.from_euler(
            "xyz", np.random.default_rng(2).uniform(-60, 60, (6, 3)), degrees=True
        ).as_matrix()
        @ g.FLIP
    )
    t[:, 2, 3] = 0.03
    opening = np.full(6, 0.8 * grip.stroke_mm)
    gap = np.full(6, 0.5 * grip.stroke_mm)
    batch = g.from_poses(
        t, opening_mm=opening, gap_left_mm=0.5 * (opening - gap), gap_right_mm=0.5 * (opening - gap)
    )
    start = scene.placement(batch)
    m, d = scene.model, mujoco.MjData(scene.model)
    kin = scene.kinematics
    for i in range(6):
        for name, values in start.model.items():
            getattr(m, name)[:] = values[i]
        d.qpos[:] = start.qpos[i]
        mujoco.mj_kinematics(m, d)
        obj_rot = d.xmat[scene.index.object_body].reshape(3, 3)
        obj_pos = d.xpos[scene.index.object_body]
        grip_rot = d.xmat[scene.index.gripper_body].reshape(3, 3)
        grip_pos = d.xpos[scene.index.gripper_body]
        # the pads' centre at the grasp gap: the gripper origin for a parallel jaw, the
        # mount's offset less the compensation along the gripper's z for a linkage
        offset = np.zeros(3)
        if kin is not None:
            offset[2] = kin.pad_centre_z[0] - kin.height_compensation_m(gap[i] * 1e-3)
        centre = grip_pos + grip_rot @ offset
        in_object = obj_rot.T @ (centre - obj_pos)
        assert np.allclose(in_object, t[i, :3, 3], atol=1e-9)
        assert np.allclose(obj_rot.T @ grip_rot @ g.FLIP, t[i, :3, :3], atol=1e-9)
        assert np.allclose(start.closing_axis[i], grip_rot[:, 0], atol=1e-12)
        # the lift's axis stays the world's z
        lift = m.joint("lift").id
        assert np.allclose(grip_rot @ m.jnt_axis[lift], [0, 0, 1], atol=1e-12)


def test_pick_points_take_no_model_field_and_start_as_before():
    obj, grip = load_asset("block"), load_gripper("robotiq-2f85")
    scene = build_scene(obj, grip)
    picks = pp.generate_normal(obj, grip, 8, seed=3)
    start = scene.placement(picks)
    assert start.model == {}
    o = scene.index.object_qpos
    assert np.array_equal(start.qpos[:, o], picks.x_mm * 1e-3)
    assert np.array_equal(start.qpos[:, o + 6], np.sin(np.deg2rad(picks.yaw_deg) / 2))
    assert np.array_equal(start.qpos[:, scene.index.lift_qpos], np.zeros(8))
    assert np.array_equal(start.closing_axis, np.tile([1.0, 0, 0], (8, 1)))


def test_pad_forces_are_measured_along_the_closing_axis():
    """kernels.grasp.measure: a pad pushed along the gripper's closing axis reads its
    full force whatever the axis's direction in the world."""
    axis = np.array([0.6, 0.0, 0.8])
    params = kt.GraspParams(
        *(np.float32(1.0) for _ in kt.GraspParams._fields[:-3]),
        closing_axis_x=np.float32(axis[0]),
        closing_axis_y=np.float32(axis[1]),
        closing_axis_z=np.float32(axis[2]),
    )
    ad = kt.Addresses(
        object_qpos=0,
        lift_qpos=7,
        finger_left_qpos=8,
        finger_right_qpos=9,
        object_body=1,
        finger_left_body=2,
        finger_right_body=3,
        lift_actuator=0,
        finger_left_actuator=1,
        finger_right_actuator=2,
        nu=3,
        drive=None,
    )
    cfrc = np.zeros((4, 6), np.float32)
    cfrc[2, 3:] = -20.0 * axis  # the object pushes the left pad back along -axis
    cfrc[3, 3:] = 20.0 * axis
    m = kg.measure(params, ad, np.zeros(10, np.float32), np.zeros(9, np.float32), cfrc)
    assert float(m.force_left) == pytest.approx(20.0, rel=1e-6)
    assert float(m.force_right) == pytest.approx(20.0, rel=1e-6)


def test_pick_points_given_as_poses_label_alike_and_tilted_grasps_hold():
    """The same pick-points as 4x4 poses simulate to the same labels and scores (MuJoCo
    C); turned 30 degrees about the closing axis, or 15 about the axis across the pads, the
    block is still held at F_d, measured along the tilted closing axis."""
    from mjx_pick.studies.evaluation import evaluate

    obj, grip = load_asset("block"), load_gripper("robotiq-2f85")
    picks = pp.generate_normal(obj, grip, 4, seed=0)
    height = build_scene(obj, grip).grasp_height_mm
    t = g.poses(picks, height)
    starts = {k: getattr(picks, k) for k in ("opening_mm", "gap_left_mm", "gap_right_mm")}
    as_picks = evaluate(obj, grip, picks=picks, backend="mujoco").table
    as_poses = evaluate(obj, grip, picks=g.from_poses(t, picks.pick_id, **starts)).table
    for column in ("success", "failure", "score", "max_force_left_n"):
        assert as_poses[column].to_pylist() == as_picks[column].to_pylist(), column
    assert as_poses["tilt_deg"].to_pylist() == [0.0] * 4
    for axis, deg in (("x", 30.0), ("y", 15.0)):
        turned = t.copy()
        turned[:, :3, :3] = t[:, :3, :3] @ Rotation.from_euler(axis, deg, degrees=True).as_matrix()
        table = evaluate(obj, grip, picks=g.from_poses(turned, picks.pick_id, **starts)).table
        assert all(table["success"].to_pylist()), (axis, table["failure"].to_pylist())
        assert np.allclose(table["tilt_deg"], deg)
        f_d = 50.0  # the default grip force, reached along the closing axis
        assert np.allclose(table["max_force_left_n"], f_d, rtol=0.1), table["max_force_left_n"]
