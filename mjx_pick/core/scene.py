"""Scene: object on a table under a two-finger gripper, as one MuJoCo model.

Details: docs/model.md (core/scene.py).
"""

from __future__ import annotations

import dataclasses
import hashlib
import html
import re
from pathlib import Path
from typing import NamedTuple

import mujoco
import numpy as np

from mjx_pick.core import grasps as grasp_math
from mjx_pick.core import mjcf_gripper
from mjx_pick.core.escape import xml_attr
from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.objects import MAX_HULL_VERTICES, ObjectModel
from mjx_pick.core.physics import (
    PAD_RIM_RECESS_MM,
    ContactParams,
    MujocoContact,
    SolverParams,
    mujoco_contact,
    patch_mean_radius_mm,
)
from mjx_pick.core.procedure import GraspConfig, pad_band_mm
from mjx_pick.kernels.types import DriveMap

# the robot arm carrying the gripper: a stiff, well-damped vertical servo
LIFT_STIFFNESS_N_PER_M = 2e4
LIFT_DAMPING_NS_PER_M = 400.0
LIFT_FORCE_LIMIT_N = 500.0
TABLE_HALF_SIZE_M = 0.5
# an MJCF gripper's own bodies carry its mass; this is the arm's flange that lifts it
MJCF_CARRIAGE_MASS_KG = 0.1


@dataclasses.dataclass(frozen=True)
class SceneIndex:
    """Ids and addresses the controller and the metrics need (ints: static under jit)."""

    object_body: int
    gripper_body: int  # the mount (tests measure the pads' depth below it)
    finger_left_body: int
    finger_right_body: int
    object_qpos: int  # start of the object's free joint (x, y, z, qw, qx, qy, qz)
    lift_qpos: int
    finger_left_qpos: int
    finger_right_qpos: int
    lift_actuator: int
    finger_left_actuator: int
    finger_right_actuator: int
    pad_pairs: tuple[int, ...]  # pair ids of pad-object contacts
    table_pairs: tuple[int, ...]  # pair ids of table-object contacts
    pad_bottom_z0_m: float  # fingertip height above the table at the grasp
    stroke_m: float
    # MJCF gripper: finger joints -> pad travel -> control tables; None: parallel jaw
    drive: DriveMap | None = None
    gripper_qpos: tuple[int, ...] = ()  # qpos addresses of the MJCF gripper's joints
    # pair ids of an MJCF gripper's link-object contacts (its link_contacts): the pads'
    # contact values
    link_pairs: tuple[int, ...] = ()


def pad_patch_mm(obj: ObjectModel, gripper: GripperSpec, grasp: GraspConfig):
    """(width, height) of a pad's contact patch on the object, mm (``mjx_pick.core.physics``).

    Width: the pad's, or the object's smallest width in the pads' band if narrower (of
    its largest piece where the band cuts the object in several: a pad presses on one).
    Height: the object's side wall within the band.
    """
    lo, hi = pad_band_mm(obj, gripper, grasp)
    band = obj.band_outline(lo, hi)
    if band.geom_type == "MultiPolygon":
        band = max(band.geoms, key=lambda piece: piece.area)
    width = gripper.finger_width_mm
    if not band.is_empty:
        rect = np.asarray(band.minimum_rotated_rectangle.exterior.coords)
        sides = np.linalg.norm(np.diff(rect[:3], axis=0), axis=1)
        width = min(width, float(sides.min()))
    return width, obj.wall_height_mm(lo, hi)


def pad_collision_box_mm(
    obj: ObjectModel, gripper: GripperSpec, grasp: GraspConfig, cone: str = "pyramidal"
):
    """(half width, half height, height offset) of a parametric pad's collision box, mm,
    with ``ContactParams.pad_collision = "mean_radius"`` (the default lets the whole pad
    collide).

    MuJoCo's collider puts a flat pad's contact points at the corners of its overlap
    with a flat face (the two ends of a line contact). With pyramidal cones a corner at
    (a, b) from the patch centre resists spin about the grip axis with mu N max(|a|, |b|)
    of its normal force N, where a uniformly pressed rubber pad resists with mu N r_mean
    (r_mean the patch's mean radius, ``mjx_pick.core.physics``). The collision box is
    therefore cut to the pad's central 2 r_mean in width, and, where the object's wall
    is taller than 2 r_mean, to 2 r_mean in height centred on the wall: every corner
    then sits at most r_mean from the patch centre. The offset is the box centre's
    height above the pad's centre (0 where the box keeps the pad's height). The visual
    pad keeps the gripper's size. What it costs (a part is touched only within the box;
    a face turned in the grip is met by the box's edge): ``mjx_pick.core.physics``.
    """
    width, height = pad_patch_mm(obj, gripper, grasp)
    r = patch_mean_radius_mm(width, height)
    lo, hi = pad_band_mm(obj, gripper, grasp)
    if cone == "elliptic":
        return _elliptic_box_mm(obj, gripper, width, height, r, lo, hi)
    half_w = min(r, 0.5 * gripper.finger_width_mm)
    if height <= 2 * r:
        return half_w, 0.5 * gripper.pad_height_mm, 0.0
    return half_w, r, _box_offset_mm(obj, gripper, r, lo, hi)


class PadBox(NamedTuple):
    """One collision box of a parametric pad, mm, in the finger's frame: its half width
    and half height in the pad's plane, its centre's offsets across the pad (y) and in
    height (z), and how far its face lies behind the pad's face (recess)."""

    half_width_mm: float
    half_height_mm: float
    y_mm: float = 0.0
    z_mm: float = 0.0
    recess_mm: float = 0.0


def pad_collision_geoms_mm(
    obj: ObjectModel, gripper: GripperSpec, grasp: GraspConfig, contact: ContactParams, cone: str
) -> list[PadBox] | None:
    """A parametric pad's collision boxes for ``contact.pad_collision``; None where the
    whole pad collides ("pad").

    "mean_radius": the box of :func:`pad_collision_box_mm`. "rimmed": that box and the
    whole pad recessed by ``physics.PAD_RIM_RECESS_MM`` behind it (the rim), which only
    a part the box misses reaches (none where the box is the whole pad).
    """
    if contact.pad_collision == "pad":
        return None
    half_w, half_h, dz = pad_collision_box_mm(obj, gripper, grasp, cone)
    box = PadBox(half_w, half_h, 0.0, dz)
    whole = PadBox(0.5 * gripper.finger_width_mm, 0.5 * gripper.pad_height_mm)
    cut = (box.half_width_mm, box.half_height_mm) != (whole.half_width_mm, whole.half_height_mm)
    if contact.pad_collision == "rimmed" and cut:
        return [box, whole._replace(recess_mm=PAD_RIM_RECESS_MM)]
    return [box]


def _box_offset_mm(obj, gripper, half_h: float, lo: float, hi: float) -> float:
    """Height of a collision box's centre above the pad's centre, mm: on the centre of
    the object's wall in the pad band lo..hi, the box (half height half_h) kept within
    the pad's height."""
    _, centre = obj.wall_mm(lo, hi)
    limit = 0.5 * gripper.pad_height_mm - half_h
    return float(np.clip(centre - 0.5 * (lo + hi), -limit, limit))


def _elliptic_box_mm(obj, gripper, width, height, r, lo, hi):
    """The collision box for elliptic cones: a corner at (a, b) resists spin with
    mu N sqrt(a^2 + b^2) (its Euclidean distance, not the pyramid's max(|a|, |b|)), and
    each point's soft-finger torsion mu_t adds to it in quadrature. The overlap's
    corners are put at r_c = r_mean cos(theta) and mu_t = mu r_mean sin(theta)
    (``physics.ELLIPTIC_TORSION_SHARE`` = sin(theta)), so that pure torsion holds mu N
    r_mean, the rubber pad's. A wall short enough keeps the pad's height (the overlap's
    height is the wall's) and only the width is cut; a taller wall gets a box of the
    patch's aspect, centred on the wall."""
    from mjx_pick.core.physics import ELLIPTIC_TORSION_SHARE

    rc = r * np.sqrt(1.0 - ELLIPTIC_TORSION_SHARE**2)
    if 0.5 * height <= rc / np.sqrt(2.0):
        half_w = min(np.sqrt(rc**2 - (0.5 * height) ** 2), 0.5 * gripper.finger_width_mm)
        return float(half_w), 0.5 * gripper.pad_height_mm, 0.0
    s = rc / np.hypot(0.5 * width, 0.5 * height)
    half_w, half_h = s * 0.5 * width, s * 0.5 * height
    return float(half_w), float(half_h), _box_offset_mm(obj, gripper, half_h, lo, hi)


class Placement(NamedTuple):
    """Where N grasps start (:meth:`Scene.placement`)."""

    qpos: np.ndarray  # (N, nq)
    # per-simulation model fields, MjModel name -> (N, *field shape): the gripper's tilt
    # (body_quat, and the lift's jnt_axis kept on world z); empty for vertical grasps
    model: dict
    closing_axis: np.ndarray  # (N, 3) the gripper's closing axis (its x) in world axes


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """A compiled scene: the model, its MJCF text, the index, and what built it."""

    model: mujoco.MjModel
    xml: str
    index: SceneIndex
    contact: MujocoContact
    object: ObjectModel
    gripper: GripperSpec
    solver: SolverParams
    pad_patch_mm: tuple[float, float]  # (width, height) of the pads' contact patch
    # the MJCF gripper's measured close (None: parallel jaw)
    kinematics: mjcf_gripper.Kinematics | None = None

    def portable_xml(self) -> str:
        """The simulated model's MJCF text with every file it names (the object's
        meshes, an MJCF gripper's assets) replaced by ``sha256:<digest>`` of the file's
        bytes: what the model is, never where its files are installed (resume keys)."""

        def digest(m: re.Match) -> str:
            path = Path(html.unescape(m[1]))  # the attribute's text: entities read back
            if not path.is_file():
                return m[0]
            return f'file="sha256:{hashlib.sha256(path.read_bytes()).hexdigest()}"'

        return re.sub(r'file="([^"]+)"', digest, self.xml)

    @property
    def box_pads(self) -> bool:
        """Whether ContactParams.pad_collision applies to its pads (the parametric jaw's,
        or an MJCF gripper's box pads; other MJCF pads keep their own geoms)."""
        return self.kinematics is None or self.kinematics.pad_frames is not None

    @property
    def grasp_height_mm(self) -> float:
        """The pads' centre above the table at the grasp when the gripper is not raised
        (lift 0), mm: a pick-point's grasp height (the procedure's)."""
        return 1e3 * self._tcp_offset_z_m()

    def _tcp_offset_z_m(self) -> float:
        """The pads' centre height at lift 0 in the compiled model, m (an MJCF gripper's
        mount lies above it by its fully-open offset)."""
        z = float(self.model.body_pos[self.index.gripper_body, 2])
        if self.kinematics is not None:
            z += float(self.kinematics.pad_centre_z[0])
        return z

    def placement(self, grasps: GraspBatch) -> Placement:
        """Where N grasps start: the joint positions, and for grasps that are not
        vertical the gripper's tilt as per-simulation model fields (docs/formats.md,
        "Grasps").

        The world's axes are the heading frame of each grasp: the gripper stays where
        the model puts it, turned by the grasp's tilt about its own origin, and is moved
        along world z by its lift joint (whose axis the tilt turns back to world z);
        the object lies at its planar pose under the grasp centre, on the table. An
        MJCF linkage starts raised along its approach by the height compensation for
        the gap its pads close to (grasps' grasp_gap_mm), so that they grip at the
        grasp centre. A pick-point (no tilt, no height) takes no model field, and its
        joint positions are today's bit for bit.
        """
        n = len(grasps)
        idx = self.index
        qpos = np.tile(self.model.qpos0, (n, 1))
        opening_m = np.asarray(grasps.opening_mm, float) * 1e-3
        gap_m = np.asarray(grasps.grasp_gap_mm, float) * 1e-3
        travel = 0.5 * (idx.stroke_m - opening_m)
        kin = self.kinematics
        comp = np.zeros(n)
        if kin is None:
            qpos[:, idx.finger_left_qpos] = travel
            qpos[:, idx.finger_right_qpos] = travel
        else:
            qpos[:, list(idx.gripper_qpos)] = kin.joint_positions(kin.travel_at_opening(opening_m))
            comp = np.asarray(kin.height_compensation_m(gap_m), float).reshape(n)
        # the grasp centre from the gripper's origin, gripper frame: the pads' centre at
        # the gap they close to (below the mount of an MJCF gripper)
        tcp = np.zeros((n, 3))
        if kin is not None:
            tcp[:, 2] = float(kin.pad_centre_z[0]) - comp
        tilt = np.broadcast_to(np.eye(3), (n, 3, 3))
        if grasps.tilt_quat is not None:
            tilt = grasp_math.quat_to_mat(grasps.tilt_quat)
        moved = np.einsum("nij,nj->ni", tilt, tcp)  # exactly tcp where there is no tilt
        lift = comp - (moved[:, 2] - tcp[:, 2])
        if grasps.height_mm is not None:
            lift = lift + (np.asarray(grasps.height_mm, float) * 1e-3 - self._tcp_offset_z_m())
        o = idx.object_qpos
        yaw = np.deg2rad(np.asarray(grasps.yaw_deg, float))
        qpos[:, o] = np.asarray(grasps.x_mm, float) * 1e-3 + moved[:, 0]
        qpos[:, o + 1] = np.asarray(grasps.y_mm, float) * 1e-3 + moved[:, 1]
        qpos[:, o + 2] = 0.0  # object frame origin on the table
        qpos[:, o + 3] = np.cos(yaw / 2)
        qpos[:, o + 4 : o + 6] = 0.0
        qpos[:, o + 6] = np.sin(yaw / 2)
        qpos[:, idx.lift_qpos] = lift
        fields = {}
        if grasps.tilt_quat is not None:
            body_quat = np.tile(self.model.body_quat, (n, 1, 1))
            body_quat[:, idx.gripper_body] = grasps.tilt_quat
            axis = np.tile(self.model.jnt_axis, (n, 1, 1))
            axis[:, self.model.joint("lift").id] = tilt[:, 2, :]  # S^T e_z
            fields = {"body_quat": body_quat, "jnt_axis": axis}
        return Placement(qpos, fields, np.ascontiguousarray(tilt[:, :, 0]))

    def pad_centre_z_m(self, data: mujoco.MjData) -> float:
        """Height of the pads' centre above the table in a simulation of this scene, m
        (the mean of the pad geoms' centres: an MJCF gripper's, or the parallel jaw's
        two pad boxes)."""
        names = [self.model.geom(g).name for g in range(self.model.ngeom)]
        if "pad_left_visual" in names:  # a collision box stands for the pads as built
            pads = [names.index("pad_left_visual"), names.index("pad_right_visual")]
        else:
            pads = [g for g, name in enumerate(names) if _is_pad_geom(name, self.gripper)]
        return float(np.mean(data.geom_xpos[pads, 2]))


def parallel_jaw_pad_side(name: str) -> int | None:
    """Which pad a parallel jaw's geom collides for: 0 (left), 1 (right), or None (not a
    pad collision geom: the pad as built, ``*_visual``, or any other geom). The whole
    pad, its box and the rim behind it are all named ``pad_left*`` / ``pad_right*``
    (:func:`_parallel_jaw_pad_names`)."""
    if name.endswith("_visual"):
        return None
    for side, prefix in enumerate(("pad_left", "pad_right")):
        if name.startswith(prefix):
            return side
    return None


def _is_pad_geom(name: str, gripper: GripperSpec) -> bool:
    if gripper.mjcf is None:
        return parallel_jaw_pad_side(name) is not None
    pads = gripper.mjcf.pad_left_geoms + gripper.mjcf.pad_right_geoms
    return name in {mjcf_gripper.PREFIX + g for g in pads}


def _fmt(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in np.ravel(values))


def scene_xml(
    obj: ObjectModel,
    gripper: GripperSpec,
    mjc: MujocoContact,
    solver: SolverParams,
    fingertip_height_mm: float,
    kinematics: mjcf_gripper.Kinematics | None = None,
    pad_boxes_mm: list[PadBox] | None = None,
) -> str:
    """MJCF text of the scene (deterministic: same inputs, same text).

    pad_boxes_mm: the parallel jaw's pad collision boxes (:func:`pad_collision_geoms_mm`);
    None: the whole pad collides.

    With an MJCF gripper (its measured ``kinematics``) the text holds the ``gripper``
    body without fingers and pairs naming the gripper's pad geoms: attach the gripper
    (``mjcf_gripper.attach``) before compiling it.
    """
    pad_h = gripper.pad_height_mm * 1e-3
    z_grip = fingertip_height_mm * 1e-3 + 0.5 * pad_h  # pad centres
    pad_pieces = obj.pad_pieces(gripper.finger_depth_mm, gripper.finger_width_mm)
    meshes, pieces = _object_meshes_xml(obj, pad_pieces)
    pairs = _contact_pairs_xml(gripper, mjc, len(pad_pieces), pad_boxes_mm)
    table_size = _fmt([TABLE_HALF_SIZE_M, TABLE_HALF_SIZE_M, 0.01])
    gripper_body, actuators = _gripper_xml(gripper, kinematics, z_grip, pad_boxes_mm)
    model = xml_attr(f"mjx_pick {obj.name} {gripper.name}")  # user names: any character
    return f"""<mujoco model="{model}">
{_options_xml(solver)}
  <default>
    <geom contype="0" conaffinity="0"/>
  </default>
  <visual><global offwidth="1280" offheight="960"/></visual>
  <asset>
    {chr(10).join("    " + m for m in meshes).strip()}
    <texture name="grid" type="2d" builtin="checker" width="256" height="256"
             rgb1=".85 .85 .85" rgb2=".75 .75 .75"/>
    <material name="grid" texture="grid" texrepeat="20 20"/>
  </asset>
  <worldbody>
    <light pos="0 -0.3 0.6" dir="0 0.4 -1" diffuse=".8 .8 .8"/>
    <geom name="table" type="plane" size="{table_size}" material="grid"/>
    <camera name="top" pos="0 0 0.45" xyaxes="1 0 0 0 1 0"/>
    <camera name="side" pos="0 -0.35 0.12" xyaxes="1 0 0 0 0.2 1"/>
{_object_body_xml(obj, pieces)}
{gripper_body}
  </worldbody>
  <contact>
{chr(10).join(pairs)}
  </contact>
  <actuator>
{actuators}
  </actuator>
  <sensor>
    <accelerometer name="object_acc" site="object_com"/>
  </sensor>
</mujoco>
"""


def _options_xml(solver: SolverParams) -> str:
    """The scene's ``<compiler>`` and ``<option>`` lines: the solver settings."""
    integrator = {"euler": "Euler"}.get(solver.integrator, solver.integrator)
    return f"""  <compiler angle="radian" autolimits="true"/>
  <option timestep="{solver.timestep_s:.9g}" cone="{solver.cone}" impratio="{solver.impratio:.9g}"
          iterations="{solver.iterations}" ls_iterations="{solver.ls_iterations}"
          tolerance="{solver.tolerance:.9g}" noslip_iterations="{solver.noslip_iterations}"
          integrator="{integrator}"/>"""


def _object_body_xml(obj: ObjectModel, pieces: str) -> str:
    """The object's free body: its inertia (kg, kg m^2, about the centre of mass), the
    accelerometer's site, its visual mesh and ``pieces``, its collision geoms' lines."""
    inertia = obj.inertia_kg_m2
    full = _fmt(
        [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    )
    return f"""    <body name="object">
      <freejoint name="object"/>
      <inertial pos="{_fmt(obj.com_m)}" mass="{obj.mass_kg:.9g}" fullinertia="{full}"/>
      <site name="object_com" pos="{_fmt(obj.com_m)}"/>
      <geom name="object_visual" type="mesh" mesh="visual" group="1" rgba=".2 .45 .8 1" mass="0"/>
{pieces}
    </body>"""


def _object_meshes_xml(obj: ObjectModel, pad_pieces: list) -> tuple[list[str], str]:
    """The object's meshes (visual, the convex pieces the pads touch, the hull the table
    touches) and its collision geoms: (asset lines, body lines)."""
    meshes = [
        f'<mesh name="visual" vertex="{_fmt(obj.mesh.vertices)}" face="{_fmt(obj.mesh.faces)}"/>'
    ]
    meshes += [
        f'<mesh name="piece{i}" vertex="{_fmt(v)}" maxhullvert="{MAX_HULL_VERTICES}"/>'
        for i, v in enumerate(pad_pieces)
    ]
    # a rigid body on a plane touches it only on its convex hull: one table pair. The
    # hull is capped at MAX_HULL_VERTICES (32) (MuJoCo/MJX want no face of more than 20); for a
    # flat object that trims the support polygon's corners by well under a millimetre
    hull = _fmt(np.vstack(obj.pieces))
    meshes.append(f'<mesh name="hull" vertex="{hull}" maxhullvert="{MAX_HULL_VERTICES}"/>')
    pieces = "\n".join(
        f'      <geom name="piece{i}" type="mesh" mesh="piece{i}" group="3" rgba=".9 .5 .1 .5"/>'
        for i in range(len(pad_pieces))
    )
    pieces += '\n      <geom name="hull" type="mesh" mesh="hull" group="4" rgba=".5 .5 .5 .3"/>'
    return meshes, pieces


def _contact_pairs_xml(
    gripper: GripperSpec, mjc: MujocoContact, n_pieces: int, pad_boxes_mm: list[PadBox] | None
) -> list[str]:
    """The scene's only contacts, as explicit pairs: each pad (an MJCF gripper's pad
    geoms, and its links where it asks for them) with each object piece, and the table
    with the object's hull."""
    pad_fr = _fmt([mjc.pad_friction, mjc.pad_friction, mjc.pad_torsion_m, 0.0001, 0.0001])
    tab_fr = _fmt([mjc.table_friction, mjc.table_friction, 0.005, 0.0001, 0.0001])
    if gripper.mjcf is None or pad_boxes_mm is not None:
        names = _parallel_jaw_pad_names(pad_boxes_mm)
        pad_geoms = [
            (f"pad_{side}{k}", f"pad_{side}{k}") for side in ("left", "right") for k in names
        ]
    else:
        # pair names start with pad_left / pad_right (SceneIndex.pad_pairs finds them)
        pad_geoms = [
            (f"{side}{k}", mjcf_gripper.PREFIX + g)
            for side, geoms in (
                ("pad_left", gripper.mjcf.pad_left_geoms),
                ("pad_right", gripper.mjcf.pad_right_geoms),
            )
            for k, g in enumerate(geoms)
        ]
    # every pad geom, the rim too: the whole face stands proud by the margin, so a
    # rim keeps its recess behind the box
    margin = f' margin="{mjc.pad_margin_m:.9g}"' if mjc.pad_margin_m > 0 else ""
    pairs = []
    for i in range(n_pieces):
        for pad, geom in pad_geoms:
            pairs.append(
                f'    <pair name="{pad}_piece{i}" geom1="{geom}" geom2="piece{i}" condim="4" '
                f'friction="{pad_fr}" solref="{_fmt(mjc.pad_solref)}" '
                f'solimp="{_fmt(mjc.pad_solimp)}"{margin}/>'
            )
    if gripper.mjcf is not None and gripper.mjcf.link_contacts:
        for i in range(n_pieces):
            for k, link in enumerate(mjcf_gripper.link_geoms(gripper.mjcf)):
                pairs.append(
                    f'    <pair name="link{k}_piece{i}" geom1="{mjcf_gripper.PREFIX + link}" '
                    f'geom2="piece{i}" condim="3" friction="{pad_fr}" '
                    f'solref="{_fmt(mjc.pad_solref)}" solimp="{_fmt(mjc.pad_solimp)}"/>'
                )
    pairs.append(
        f'    <pair name="table_hull" geom1="table" geom2="hull" condim="3" '
        f'friction="{tab_fr}" solref="{_fmt(mjc.table_solref)}" '
        f'solimp="{_fmt(mjc.table_solimp)}"/>'
    )
    return pairs


def _gripper_xml(
    gripper: GripperSpec,
    kinematics: mjcf_gripper.Kinematics | None,
    z_grip: float,
    pad_boxes_mm: list[PadBox] | None,
) -> tuple[str, str]:
    """The gripper's body and the actuators (the lift's and a parallel jaw's): (body,
    actuators). An MJCF gripper's body here is its carriage only (see scene_xml)."""
    lift_range = _fmt([-LIFT_FORCE_LIMIT_N, LIFT_FORCE_LIMIT_N])
    actuators = f"""    <position name="lift" joint="lift" kp="{LIFT_STIFFNESS_N_PER_M:.9g}"
              kv="{LIFT_DAMPING_NS_PER_M:.9g}" forcerange="{lift_range}"/>"""
    if kinematics is None:
        gripper_body = _parallel_jaw_body_xml(gripper, z_grip, pad_boxes_mm)
        actuators += "\n" + _parallel_jaw_actuators_xml(gripper)
    else:
        # the pads' centre at the grasp height when fully open (lift 0)
        z_mount = z_grip - float(kinematics.pad_centre_z[0])
        gripper_body = f"""    <body name="gripper" pos="0 0 {z_mount:.9g}" gravcomp="1">
      <joint name="lift" type="slide" axis="0 0 1"/>
      <inertial pos="0 0 0" mass="{MJCF_CARRIAGE_MASS_KG:.9g}" diaginertia="1e-3 1e-3 1e-3"/>
    </body>"""
    return gripper_body, actuators


def _parallel_jaw_pad_names(pad_boxes_mm: list[PadBox] | None) -> list[str]:
    """Suffixes of a parallel jaw's pad collision geoms after ``pad_left`` / ``pad_right``:
    "" for the whole pad or the box, ``_rim`` for the rim behind the box."""
    if pad_boxes_mm is None:
        return [""]
    return ["", "_rim"][: len(pad_boxes_mm)]


def _parallel_jaw_body_xml(
    gripper: GripperSpec,
    z_grip: float,
    pad_boxes_mm: list[PadBox] | None = None,
) -> str:
    """The parametric gripper: a body on the lift with two sliding pad fingers.

    Each finger's pad is ``pad_left`` / ``pad_right``, the geom the pad pairs name. With
    ``pad_boxes_mm`` (:func:`pad_collision_geoms_mm`) that geom is the collision box, a
    rim behind it ``pad_left_rim`` (:func:`_parallel_jaw_pad_names`), and
    ``pad_left_visual`` / ``pad_right_visual``, the pad as built, carries the finger's
    mass and collides with nothing; None: the whole pad collides."""
    stroke = gripper.stroke_mm * 1e-3
    depth = gripper.finger_depth_mm * 1e-3
    width = gripper.finger_width_mm * 1e-3
    pad_h = gripper.pad_height_mm * 1e-3
    armature = f"{gripper.drive_inertia_kg:.9g}"  # the drive's reflected inertia
    finger_link_h = 0.03
    return f"""    <body name="gripper" pos="0 0 {z_grip:.9g}" gravcomp="1">
      <joint name="lift" type="slide" axis="0 0 1"/>
      <inertial pos="0 0 {0.5 * pad_h + 0.06:.9g}" mass="{gripper.body_mass_g * 1e-3:.9g}"
                diaginertia="1e-3 1e-3 1e-3"/>
      <geom name="gripper_body" type="box" group="2" rgba=".25 .25 .25 1" mass="0"
            size="{0.5 * stroke + depth + 0.01:.9g} {0.5 * width + 0.01:.9g} 0.03"
            pos="0 0 {0.5 * pad_h + finger_link_h + 0.03:.9g}"/>
      <body name="finger_left" pos="{-0.5 * stroke - 0.5 * depth:.9g} 0 0" gravcomp="1">
        <joint name="finger_left" type="slide" axis="1 0 0"
               range="0 {0.5 * stroke:.9g}" armature="{armature}"/>
        {_parallel_jaw_pad_xml(gripper, "left", pad_boxes_mm)}
        <geom name="link_left" type="box" group="2" mass="0" rgba=".4 .4 .4 1"
              size="{0.5 * depth:.9g} {0.5 * width:.9g} {0.5 * finger_link_h:.9g}"
              pos="0 0 {0.5 * (pad_h + finger_link_h):.9g}"/>
      </body>
      <body name="finger_right" pos="{0.5 * stroke + 0.5 * depth:.9g} 0 0" gravcomp="1">
        <joint name="finger_right" type="slide" axis="-1 0 0"
               range="0 {0.5 * stroke:.9g}" armature="{armature}"/>
        {_parallel_jaw_pad_xml(gripper, "right", pad_boxes_mm)}
        <geom name="link_right" type="box" group="2" mass="0" rgba=".4 .4 .4 1"
              size="{0.5 * depth:.9g} {0.5 * width:.9g} {0.5 * finger_link_h:.9g}"
              pos="0 0 {0.5 * (pad_h + finger_link_h):.9g}"/>
      </body>
    </body>"""


def _parallel_jaw_pad_xml(
    gripper: GripperSpec, side: str, pad_boxes_mm: list[PadBox] | None
) -> str:
    """One finger's pad geoms (side: "left" or "right"): the whole pad, which collides,
    or, with ``pad_boxes_mm``, the pad as built (``pad_<side>_visual``, the finger's
    mass) and its collision boxes (:func:`_parallel_jaw_body_xml`)."""
    depth = gripper.finger_depth_mm * 1e-3
    width = gripper.finger_width_mm * 1e-3
    pad_h = gripper.pad_height_mm * 1e-3
    pad_size = _fmt([0.5 * depth, 0.5 * width, 0.5 * pad_h])
    fmass = gripper.finger_mass_g * 1e-3
    if pad_boxes_mm is None:  # the whole pad collides
        return f"""<geom name="pad_{side}" type="box" size="{pad_size}"
              mass="{fmass:.9g}" rgba=".1 .1 .1 1"/>"""
    boxes = []
    for name, (half_w, half_h, dy, dz, recess) in zip(
        _parallel_jaw_pad_names(pad_boxes_mm), pad_boxes_mm, strict=True
    ):
        # the box is thinned on both faces: its face towards the part lies behind
        box_size = _fmt([0.5 * depth - recess * 1e-3, half_w * 1e-3, half_h * 1e-3])
        box_pos = _fmt([0.0, dy * 1e-3, dz * 1e-3])
        boxes.append(
            f"""
        <geom name="pad_{side}{name}" type="box" size="{box_size}" pos="{box_pos}"
              mass="0" group="3" rgba=".9 .2 .2 .5"/>"""
        )
    return f"""<geom name="pad_{side}_visual" type="box" size="{pad_size}"
              mass="{fmass:.9g}" rgba=".1 .1 .1 1"/>{"".join(boxes)}"""


def _parallel_jaw_actuators_xml(gripper: GripperSpec) -> str:
    """The parametric gripper's finger servos (position, force-limited)."""
    stroke = gripper.stroke_mm * 1e-3
    kp = gripper.drive_stiffness_n_per_mm * 1e3
    kv = gripper.drive_damping_ns_per_mm * 1e3
    fmax = gripper.force_max_n
    return f"""    <position name="finger_left" joint="finger_left" kp="{kp:.9g}" kv="{kv:.9g}"
              forcerange="{-fmax:.9g} {fmax:.9g}" ctrlrange="-0.05 {0.5 * stroke + 0.05:.9g}"/>
    <position name="finger_right" joint="finger_right" kp="{kp:.9g}" kv="{kv:.9g}"
              forcerange="{-fmax:.9g} {fmax:.9g}" ctrlrange="-0.05 {0.5 * stroke + 0.05:.9g}"/>"""


def build_scene(
    obj: ObjectModel,
    gripper: GripperSpec,
    contact: ContactParams | None = None,
    solver: SolverParams | None = None,
    grasp: GraspConfig | None = None,
) -> Scene:
    """Compile the scene for (object, gripper, contact, solver settings, procedure).

    The procedure (grasp) sets the fingertips' height (its grasp-height rule).
    """
    contact = contact or ContactParams()
    solver = solver or SolverParams()
    grasp = grasp or GraspConfig()
    patch = pad_patch_mm(obj, gripper, grasp)
    kin = None if gripper.mjcf is None else mjcf_gripper.characterise(gripper.mjcf)
    # pad_collision applies to the parametric jaw and to an MJCF gripper with box pads
    cut_pads = kin is None or kin.pad_frames is not None
    mjc = mujoco_contact(contact, solver, obj.mass_kg, patch, pad_box=cut_pads)
    tip_mm, _ = pad_band_mm(obj, gripper, grasp)
    boxes = pad_collision_geoms_mm(obj, gripper, grasp, contact, solver.cone) if cut_pads else None
    xml = scene_xml(obj, gripper, mjc, solver, tip_mm, kin, boxes)
    model, xml = _compile_scene(xml, gripper, kin, boxes)
    index = _scene_index(model, gripper, kin, tip_mm)
    return Scene(
        model=model,
        xml=xml,
        index=index,
        contact=mjc,
        object=obj,
        gripper=gripper,
        solver=solver,
        pad_patch_mm=tuple(float(v) for v in patch),
        kinematics=kin,
    )


def _compile_scene(
    xml: str,
    gripper: GripperSpec,
    kin: mjcf_gripper.Kinematics | None,
    boxes: list[PadBox] | None,
) -> tuple[mujoco.MjModel, str]:
    """The compiled model of :func:`scene_xml`'s text and the model's MJCF text: an MJCF
    gripper attached first (with the parallel jaw's pad boxes where it has them). In
    qpos0 every joint is at 0 and the object's quaternion is the identity."""
    if kin is None:
        model = mujoco.MjModel.from_xml_string(xml)
    else:
        spec = mujoco.MjSpec.from_string(xml)
        mjcf_gripper.attach(spec, gripper.mjcf, "gripper")
        if boxes is not None:
            _add_mjcf_pad_boxes(spec, gripper, kin, boxes)
        model = spec.compile()
        xml = spec.to_xml()
    model.qpos0[:] = 0.0
    model.qpos0[model.jnt_qposadr[model.joint("object").id] + 3] = 1.0
    return model, xml


def _finger_names(gripper: GripperSpec, kin: mjcf_gripper.Kinematics | None) -> dict[str, str]:
    """The model's names of each finger's body, joint and actuator, by SceneIndex field:
    the parallel jaw's own, or an attached MJCF gripper's pad bodies, finger joints and
    its one actuator."""
    if kin is None:
        return {
            "finger_left_body": "finger_left",
            "finger_right_body": "finger_right",
            "finger_left_qpos": "finger_left",
            "finger_right_qpos": "finger_right",
            "finger_left_actuator": "finger_left",
            "finger_right_actuator": "finger_right",
        }
    p, act = mjcf_gripper.PREFIX, gripper.mjcf.actuator
    return {
        "finger_left_body": p + kin.pad_bodies[0],
        "finger_right_body": p + kin.pad_bodies[1],
        "finger_left_qpos": p + kin.finger_joints[0],
        "finger_right_qpos": p + kin.finger_joints[1],
        "finger_left_actuator": p + act,
        "finger_right_actuator": p + act,
    }


def _scene_index(
    model: mujoco.MjModel,
    gripper: GripperSpec,
    kin: mjcf_gripper.Kinematics | None,
    tip_mm: float,
) -> SceneIndex:
    """The compiled model's ids and addresses (tip_mm: the fingertips' height above the
    table at the grasp, mm)."""

    def pairs(prefixes) -> tuple[int, ...]:
        return tuple(i for i in range(model.npair) if model.pair(i).name.startswith(prefixes))

    def qadr(joint: str) -> int:
        return int(model.jnt_qposadr[model.joint(joint).id])

    names = _finger_names(gripper, kin)
    mjcf_fields = {}
    if kin is not None:
        mjcf_fields = {
            "drive": kin.drive_map(),
            "gripper_qpos": tuple(qadr(mjcf_gripper.PREFIX + j) for j in kin.joint_names),
        }
    return SceneIndex(
        object_body=model.body("object").id,
        gripper_body=model.body("gripper").id,
        finger_left_body=model.body(names["finger_left_body"]).id,
        finger_right_body=model.body(names["finger_right_body"]).id,
        object_qpos=qadr("object"),
        lift_qpos=qadr("lift"),
        finger_left_qpos=qadr(names["finger_left_qpos"]),
        finger_right_qpos=qadr(names["finger_right_qpos"]),
        lift_actuator=model.actuator("lift").id,
        finger_left_actuator=model.actuator(names["finger_left_actuator"]).id,
        finger_right_actuator=model.actuator(names["finger_right_actuator"]).id,
        pad_pairs=pairs(("pad_left", "pad_right")),
        table_pairs=pairs(("table",)),
        link_pairs=pairs(("link",)),
        pad_bottom_z0_m=tip_mm * 1e-3,
        stroke_m=gripper.stroke_mm * 1e-3,
        **mjcf_fields,
    )


def _add_mjcf_pad_boxes(
    spec: mujoco.MjSpec,
    gripper: GripperSpec,
    kin: mjcf_gripper.Kinematics,
    pad_boxes_mm: list[PadBox],
) -> None:
    """Give an attached MJCF gripper's pads the parallel jaw's collision boxes
    (:func:`pad_collision_geoms_mm`), named like the parallel jaw's (``pad_left``,
    ``pad_left_rim``, ...): each a box in the pad's body, aligned with the gripper's
    axes and centred on the pad geoms' bounding box (``Kinematics.pad_frames``), so that
    the pad pairs name them instead of the gripper's own pad geoms."""
    depth = gripper.finger_depth_mm * 1e-3
    names = _parallel_jaw_pad_names(pad_boxes_mm)
    for side, body, frame in zip(("left", "right"), kin.pad_bodies, kin.pad_frames, strict=True):
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, np.asarray(frame.quat))
        to_body = rot.reshape(3, 3)  # gripper axes -> the body's
        for name, (half_w, half_h, dy, dz, recess) in zip(names, pad_boxes_mm, strict=True):
            offset = to_body @ (np.array([0.0, dy, dz]) * 1e-3)
            spec.body(mjcf_gripper.PREFIX + body).add_geom(
                name=f"pad_{side}{name}",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                # thinned on both faces, like the parallel jaw's: its face towards the
                # part lies recess behind the pad's
                size=[0.5 * depth - recess * 1e-3, half_w * 1e-3, half_h * 1e-3],
                pos=list(np.asarray(frame.centre_m) + offset),
                quat=list(frame.quat),
                contype=0,
                conaffinity=0,
                group=3,
                density=0.0,
                rgba=[0.9, 0.2, 0.2, 0.5],
            )


def height_compensation_mm(gripper: GripperSpec, picks) -> np.ndarray:
    """(N,) mm: how far each pick starts the gripper raised so that its pads, travelling
    along their path as they close, meet the object at the grasp height (the paper's
    section 3.5) -- an MJCF linkage's, for the gap it closes to; 0 for a parallel jaw,
    whose pads close level. picks: a GraspBatch (its grasp_gap_mm)."""
    gap_m = np.asarray(picks.grasp_gap_mm, float) * 1e-3
    if gripper.mjcf is None:
        return np.zeros(len(gap_m))
    kin = mjcf_gripper.characterise(gripper.mjcf)
    return np.asarray(kin.height_compensation_m(gap_m), float).reshape(-1) * 1e3
