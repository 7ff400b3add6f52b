"""A traced pick-point's bodies: their shapes and their world poses, row by row."""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.mjcf_gripper import PREFIX, characterise

__all__ = ["BodyShape", "BodyTrack", "GeomMesh", "TracePose", "body_track", "scene_shapes"]

# MuJoCo's viewer and renderer show geom groups 0-2 unless told otherwise; the scene keeps
# its collision pieces, pad collision boxes and hull in groups 3 and 4
SHOWN_GROUPS = 3
# an infinite plane (size 0) is drawn this large, m (half the side)
PLANE_HALF_SIZE_M = 0.5
# a plane is drawn as a slab this thick under its surface, m
PLANE_THICKNESS_M = 0.002


class TracePose:
    """Sets a scene model's joints from a trace's rows (a trace as ``Run.trace`` gives).

    An MJCF gripper (gripper.mjcf) is posed from the traced pad travel through its
    measured close (``mjx_pick.core.mjcf_gripper``); a parametric gripper from its two
    finger slides. A trace with ``gripper_tilt_wxyz`` (a grasp turned from vertical)
    turns the model's gripper as the simulation did (model's body_quat and the lift's
    jnt_axis are set: pass a model of the trace's own).
    """

    def __init__(self, model, trace: dict, gripper: GripperSpec | None = None):
        self.trace = trace
        self.linkage = (
            None if gripper is None or gripper.mjcf is None else characterise(gripper.mjcf)
        )
        fingers = () if self.linkage else ("finger_left", "finger_right")
        self.adr = {
            j: int(model.jnt_qposadr[model.joint(j).id]) for j in ("object", "lift", *fingers)
        }
        tilt = trace.get("gripper_tilt_wxyz")
        if tilt is not None:  # a grasp turned from vertical: the gripper as it was placed
            _tilt_gripper(model, np.asarray(tilt, float))
        self.links = []
        if self.linkage:
            self.links = [
                int(model.jnt_qposadr[model.joint(PREFIX + j).id]) for j in self.linkage.joint_names
            ]

    def __len__(self) -> int:
        return len(self.trace["t_s"])

    @property
    def dt(self) -> float:
        """The trace's time step (the control period), s."""
        t = self.trace["t_s"]
        return float(t[1] - t[0]) if len(t) > 1 else 0.005

    def apply(self, data, k: int) -> None:
        """Row k's joint positions into data.qpos (call mj_forward or mj_kinematics after)."""
        tr, adr = self.trace, self.adr
        o = adr["object"]
        data.qpos[o : o + 3] = [tr[f"object_{c}_m"][k] for c in "xyz"]
        data.qpos[o + 3 : o + 7] = [tr[f"object_q{c}"][k] for c in "wxyz"]
        data.qpos[adr["lift"]] = tr["lift_m"][k]
        if self.linkage:
            travel = 0.5 * (tr["finger_left_m"][k] + tr["finger_right_m"][k])
            data.qpos[self.links] = self.linkage.joint_positions(travel)[0]
        else:
            data.qpos[adr["finger_left"]] = tr["finger_left_m"][k]
            data.qpos[adr["finger_right"]] = tr["finger_right_m"][k]


def _tilt_gripper(model, tilt_wxyz: np.ndarray) -> None:
    """model's gripper turned by tilt (w, x, y, z) about its origin, its lift kept on the
    world's z (``Scene.placement``)."""
    from mjx_pick.core.grasps import quat_to_mat

    model.body_quat[model.body("gripper").id] = tilt_wxyz
    model.jnt_axis[model.joint("lift").id] = quat_to_mat(tilt_wxyz)[2]


@dataclasses.dataclass(frozen=True)
class GeomMesh:
    """One shown geom as triangles in its body's frame."""

    name: str  # the geom's name in the scene, or geom<id> for an unnamed one
    geom_id: int
    vertices: np.ndarray  # (V, 3) float32, m, body frame
    faces: np.ndarray  # (F, 3) uint32, counter-clockwise seen from outside
    rgba: tuple[float, float, float, float]  # colour as MuJoCo draws it, 0-1


@dataclasses.dataclass(frozen=True)
class BodyShape:
    """A body with shown geoms: the world body (the table) first, then in model order."""

    name: str  # the body's name in the scene ("world", "object", "gripper/left_pad", ...)
    body_id: int
    geoms: tuple[GeomMesh, ...]


@dataclasses.dataclass(frozen=True)
class BodyTrack:
    """Every shown body's world pose at every trace row."""

    t_s: np.ndarray  # (T,) s
    phase: np.ndarray  # (T,) phase names
    bodies: tuple[str, ...]  # (B,) names, the order of :func:`scene_shapes`
    position_m: np.ndarray  # (T, B, 3) float32, world frame (MuJoCo Z-up; the table at z=0)
    quat_wxyz: np.ndarray  # (T, B, 4) float32, unit quaternions, world frame


def scene_shapes(model) -> list[BodyShape]:
    """The bodies of a compiled scene that have a shown geom (groups 0-2, not fully
    transparent), each geom as triangles in its body's frame: meshes as compiled, boxes,
    spheres, capsules, cylinders and ellipsoids tessellated, a plane as a slab under its
    surface. Height fields and SDFs are not drawn (no scene of this package has one)."""
    import mujoco

    shapes = []
    for b in range(model.nbody):
        geoms = []
        for g in np.flatnonzero(model.geom_bodyid == b):
            if model.geom_group[g] >= SHOWN_GROUPS:
                continue
            rgba = _geom_rgba(model, int(g))
            if rgba[3] <= 0:
                continue
            tri = _geom_triangles(model, int(g))
            if tri is None:
                continue
            vertices, faces = tri
            rot = np.empty(9)
            mujoco.mju_quat2Mat(rot, model.geom_quat[g])
            in_body = vertices @ rot.reshape(3, 3).T + model.geom_pos[g]
            name = model.geom(int(g)).name or f"geom{int(g)}"
            geoms.append(
                GeomMesh(name, int(g), in_body.astype(np.float32), faces.astype(np.uint32), rgba)
            )
        if geoms:
            shapes.append(BodyShape(model.body(b).name or f"body{b}", b, tuple(geoms)))
    return shapes


def body_track(
    model, trace: dict, shapes: list[BodyShape], gripper: GripperSpec | None = None
) -> BodyTrack:
    """The world pose of each body of shapes at every row of trace: the row's joint state
    (:class:`TracePose`) through MuJoCo's forward kinematics, so an MJCF gripper's
    linkage is posed as the simulation posed it. model is left as it is (a tilted
    grasp's trace turns a copy's gripper): one model serves any number of traces."""
    import copy

    import mujoco

    if trace.get("gripper_tilt_wxyz") is not None:
        model = copy.copy(model)
    data = mujoco.MjData(model)
    pose = TracePose(model, trace, gripper)
    ids = [s.body_id for s in shapes]
    n = len(pose)
    position = np.empty((n, len(ids), 3), np.float32)
    quat = np.empty((n, len(ids), 4), np.float32)
    for k in range(n):
        pose.apply(data, k)
        mujoco.mj_kinematics(model, data)
        position[k] = data.xpos[ids]
        quat[k] = data.xquat[ids]
    return BodyTrack(
        t_s=np.asarray(trace["t_s"], float),
        phase=np.asarray(trace["phase"]),
        bodies=tuple(s.name for s in shapes),
        position_m=position,
        quat_wxyz=quat,
    )


def _geom_rgba(model, g: int) -> tuple[float, float, float, float]:
    """A geom's colour as MuJoCo draws it: its material's (times the mean colour of the
    material's texture, if it has one) where it has one, else its own rgba."""
    m = int(model.geom_matid[g])
    if m < 0:
        return tuple(float(v) for v in model.geom_rgba[g])
    import mujoco

    rgba = np.array(model.mat_rgba[m], float)
    tex = int(model.mat_texid[m, mujoco.mjtTextureRole.mjTEXROLE_RGB])
    if tex >= 0:
        adr, h, w, c = (
            int(v)
            for v in (
                model.tex_adr[tex],
                model.tex_height[tex],
                model.tex_width[tex],
                model.tex_nchannel[tex],
            )
        )
        pixels = model.tex_data[adr : adr + h * w * c].reshape(-1, c)
        rgba[:3] *= pixels[:, :3].mean(axis=0) / 255.0
    return tuple(float(v) for v in rgba)


def _geom_triangles(model, g: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(vertices (V, 3) in the geom's frame, faces (F, 3)) of geom g, or None for a type
    not drawn."""
    import mujoco
    import trimesh

    kind = model.geom_type[g]
    size = np.asarray(model.geom_size[g], float)
    gt = mujoco.mjtGeom
    if kind == gt.mjGEOM_MESH:
        d = int(model.geom_dataid[g])
        v0, nv = int(model.mesh_vertadr[d]), int(model.mesh_vertnum[d])
        f0, nf = int(model.mesh_faceadr[d]), int(model.mesh_facenum[d])
        return np.asarray(model.mesh_vert[v0 : v0 + nv], float), model.mesh_face[f0 : f0 + nf]
    if kind == gt.mjGEOM_PLANE:
        hx, hy = (s if s > 0 else PLANE_HALF_SIZE_M for s in size[:2])
        m = trimesh.creation.box(extents=(2 * hx, 2 * hy, PLANE_THICKNESS_M))
        m.apply_translation((0.0, 0.0, -0.5 * PLANE_THICKNESS_M))
    elif kind == gt.mjGEOM_BOX:
        m = trimesh.creation.box(extents=2 * size)
    elif kind == gt.mjGEOM_SPHERE:
        m = trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    elif kind == gt.mjGEOM_ELLIPSOID:
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        m.apply_scale(size)
    elif kind == gt.mjGEOM_CAPSULE:
        m = trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=(16, 16))
    elif kind == gt.mjGEOM_CYLINDER:
        m = trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=24)
    else:
        return None
    return np.asarray(m.vertices, float), np.asarray(m.faces)
