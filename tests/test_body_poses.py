"""The 3-D replay's data: every shown body's shape where MuJoCo puts it, and its poses
as the trace moved it (the parallel jaw's slides and lift, the object's free joint, an
MJCF linkage posed from the traced pad travel)."""

import base64
import os

import mujoco
import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.core.mjcf_gripper import PREFIX
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.gui.replay3d import SceneReplay, row_at
from mjx_pick.outputs.plots import FAILURE_COLOUR
from mjx_pick.outputs.reporting import Run
from mjx_pick.outputs.reporting.body_poses import TracePose, body_track, scene_shapes

FAST = GraspConfig(close_timeout_s=1.0, lift_height_mm=20.0, hold_s=0.1)
# float32 poses and vertices: 1e-7 relative on coordinates of at most 0.5 m
POSE_TOL_M = 1e-6
# a tessellated sphere, capsule or cylinder falls short of its true extent by the cosine
# of half a facet's angle (icosphere of 2 subdivisions: under 2 %)
TESSELLATION_REL = 0.03


@pytest.fixture(scope="module")
def runs(tmp_path_factory, door_opener):
    """{gripper: (Run, model)}: the parallel jaw and the 2F-85 linkage, 3 pick-points,
    the best and worst traced."""
    out = {}
    for name in ("robotiq-2f85", "robotiq-2f85-linkage"):
        folder = tmp_path_factory.mktemp(name)
        mp.evaluate(
            door_opener,
            mp.load_gripper(name),
            n=3,
            seed=1,
            grasp=FAST,
            backend="mujoco",
            out=folder,
            n_traces=1,
        )
        out[name] = (Run.load(folder), mujoco.MjModel.from_xml_path(str(folder / "scene.xml")))
    return out


def traced(run):
    pid, _ = run.traced()[0]
    return run.trace(pid)


def test_the_parallel_jaws_bodies_move_as_the_trace_says(runs):
    run, model = runs["robotiq-2f85"]
    trace = traced(run)
    shapes = scene_shapes(model)
    track = body_track(model, trace, shapes, run.gripper)
    names = list(track.bodies)
    assert names == ["world", "object", "gripper", "finger_left", "finger_right"]
    pos, quat = track.position_m, track.quat_wxyz
    assert pos.shape == (len(trace["t_s"]), 5, 3) and quat.shape == (len(trace["t_s"]), 5, 4)
    # the object body's frame is its free joint's: the traced position and orientation
    obj = names.index("object")
    want = np.column_stack([trace[f"object_{c}_m"] for c in "xyz"])
    np.testing.assert_allclose(pos[:, obj], want, atol=POSE_TOL_M)
    q = np.column_stack([trace[f"object_q{c}"] for c in "wxyz"])
    np.testing.assert_allclose(np.abs(np.sum(quat[:, obj] * q, axis=1)), 1.0, atol=1e-6)
    # the fingers slide towards each other along x by their traced travel; all lift
    lift = trace["lift_m"] - trace["lift_m"][0]
    for body, sign, travel in ((3, 1, "finger_left_m"), (4, -1, "finger_right_m")):
        moved = pos[:, body] - pos[0, body]
        np.testing.assert_allclose(
            moved[:, 0], sign * (trace[travel] - trace[travel][0]), atol=POSE_TOL_M
        )
        np.testing.assert_allclose(moved[:, 2], lift, atol=POSE_TOL_M)
    np.testing.assert_allclose(pos[:, 2, 2] - pos[0, 2, 2], lift, atol=POSE_TOL_M)
    assert lift[-1] == pytest.approx(FAST.lift_height_mm * 1e-3, abs=1e-3)
    # the world body (the table) never moves
    np.testing.assert_allclose(pos[:, 0], 0.0)
    np.testing.assert_allclose(quat[:, 0], np.tile([1.0, 0, 0, 0], (len(pos), 1)))


def test_the_linkages_pads_move_by_the_traced_travel_mirrored(runs):
    """The trace holds the pads' travel, not the linkage's joints: posed through the
    gripper's measured close, the pad faces (their geoms' centres, carried by the pad
    bodies' tracked poses) move towards each other by the traced travel."""
    run, model = runs["robotiq-2f85-linkage"]
    trace = traced(run)
    track = body_track(model, trace, scene_shapes(model), run.gripper)
    names = list(track.bodies)
    travel = 0.5 * (trace["finger_left_m"] + trace["finger_right_m"])
    closed = travel - travel[0]
    assert closed.max() > 2e-3  # the pads closed on the part
    mjcf = run.gripper.mjcf
    faces = []
    for geoms in (mjcf.pad_left_geoms, mjcf.pad_right_geoms):
        ids = [model.geom(PREFIX + g).id for g in geoms]
        b = names.index(model.body(model.geom_bodyid[ids[0]]).name)
        x = []
        for k in range(len(closed)):
            rot = np.empty(9)
            mujoco.mju_quat2Mat(rot, track.quat_wxyz[k, b].astype(float))
            centres = track.position_m[k, b] + model.geom_pos[ids] @ rot.reshape(3, 3).T
            x.append(centres[:, 0].mean())
        faces.append(np.asarray(x) - x[0])
    # the pads tilt by a fraction of a degree as they close: their geoms' centres follow
    # the faces' travel (the characterisation's bounding boxes) within 0.2 mm
    np.testing.assert_allclose(faces[0], closed, atol=2e-4)
    np.testing.assert_allclose(faces[1], -closed, atol=2e-4)


@pytest.mark.parametrize("gripper", ["robotiq-2f85", "robotiq-2f85-linkage"])
def test_every_shown_geom_is_drawn_where_mujoco_puts_it(runs, gripper):
    """Each drawn geom, posed by the track at a few rows, fills MuJoCo's own bounding box
    of that geom (its centre and half-sizes in the geom's frame, placed by mj_forward)."""
    run, model = runs[gripper]
    trace = traced(run)
    shapes = scene_shapes(model)
    track = body_track(model, trace, shapes, run.gripper)
    drawn = {g.name for s in shapes for g in s.geoms}
    shown = {
        model.geom(g).name or f"geom{g}"
        for g in range(model.ngeom)
        if model.geom_group[g] < 3 and model.geom_rgba[g][3] > 0
    }
    assert drawn == shown
    assert {"table", "object_visual"} <= drawn
    data = mujoco.MjData(model)
    pose = TracePose(model, trace, run.gripper)
    for k in (0, len(pose) // 2, len(pose) - 1):
        pose.apply(data, k)
        mujoco.mj_forward(model, data)
        for b, shape in enumerate(shapes):
            rot = np.empty(9)
            mujoco.mju_quat2Mat(rot, track.quat_wxyz[k, b].astype(float))
            for geom in shape.geoms:
                g = geom.geom_id
                world = geom.vertices @ rot.reshape(3, 3).T + track.position_m[k, b]
                local = (world - data.geom_xpos[g]) @ data.geom_xmat[g].reshape(3, 3)
                if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE:
                    assert local[:, 2].max() == pytest.approx(0.0, abs=POSE_TOL_M)
                    continue
                centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
                lo, hi = local.min(axis=0), local.max(axis=0)
                tol = TESSELLATION_REL * half + 1e-5
                assert np.all(np.abs(lo - (centre - half)) <= tol), (geom.name, lo, centre - half)
                assert np.all(np.abs(hi - (centre + half)) <= tol), (geom.name, hi, centre + half)


def test_the_browsers_payload_holds_the_same_numbers(runs):
    run, model = runs["robotiq-2f85"]
    trace = traced(run)
    replay = SceneReplay(run.path / "scene.xml", run.gripper)
    shapes = replay.shapes_payload()
    track = replay.track_payload(trace, failed=False)
    want = body_track(model, trace, replay.shapes, run.gripper)

    def floats(text):
        return np.frombuffer(base64.b64decode(text), "<f4")

    assert [b["name"] for b in shapes["bodies"]] == list(want.bodies) == track["bodies"]
    np.testing.assert_array_equal(floats(track["position"]), want.position_m.ravel())
    np.testing.assert_array_equal(floats(track["quat_wxyz"]), want.quat_wxyz.ravel())
    np.testing.assert_array_equal(floats(track["t"]), trace["t_s"].astype(np.float32))
    pad = next(b for b in shapes["bodies"] if b["name"] == "finger_left")["geoms"][0]
    faces = np.frombuffer(base64.b64decode(pad["faces"]), "<u4").reshape(-1, 3)
    vertices = floats(pad["vertices"]).reshape(-1, 3)
    assert faces.max() == len(vertices) - 1 and len(faces) == 12  # a box
    assert pad["color"] == "#1a1a1a" and pad["opacity"] == 1.0  # rgba .1 .1 .1 1
    # a failed pick-point's object is drawn in the maps' failure colour; a success's not
    assert track["colours"] == {}
    assert replay.track_payload(trace, failed=True)["colours"] == {"object": FAILURE_COLOUR}


def test_a_scene_written_again_is_loaded_again(runs, tmp_path):
    run, _ = runs["robotiq-2f85"]
    scene = tmp_path / "scene.xml"
    scene.write_bytes((run.path / "scene.xml").read_bytes())
    replay = SceneReplay(scene, run.gripper)
    assert replay.is_for(scene, run.gripper)
    assert not replay.is_for(scene, runs["robotiq-2f85-linkage"][0].gripper)
    stat = scene.stat()
    os.utime(scene, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert not replay.is_for(scene, run.gripper)


def test_a_slider_time_shows_the_nearest_row():
    t = np.arange(5) * 0.005
    assert [row_at(t, v) for v in (-1.0, 0.0, 0.0024, 0.0026, 0.0199, 0.02, 3.0)] == [
        0,
        0,
        0,
        1,
        4,
        4,
        4,
    ]
