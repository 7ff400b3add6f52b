"""Two-finger grippers from MJCF files (e.g. Menagerie's Robotiq 2F-85 linkage).

Details: docs/model.md (core/mjcf_gripper.py).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import re
from pathlib import Path
from typing import NamedTuple

import mujoco
import numpy as np

from mjx_pick.core import cache, urdf_gripper
from mjx_pick.core.config import ConfigError, check_range, from_mapping
from mjx_pick.kernels.types import DriveMap

PREFIX = "gripper/"  # names of the attached gripper's elements in the scene
N_SAMPLES = 61  # stroke samples of the quasi-static close
SETTLE_STEPS = 300  # physics steps per sample (1 ms): joint speeds end below 1e-3 rad/s
GEOMETRY_FIELDS = ("stroke_mm", "finger_width_mm", "finger_depth_mm", "pad_height_mm")


@dataclasses.dataclass(frozen=True)
class MjcfGripper:
    """The ``[mjcf]`` table of a gripper TOML: what in the MJCF file is what.

    file: path of the MJCF file (relative paths: relative to the TOML).
    mount_body: the body whose subtree is the gripper (attached to the scene's arm).
    mount_quat: its orientation in the scene's gripper frame (w, x, y, z): the pads must
      end up below it, closing along x.
    pad_left_geoms / pad_right_geoms: the pad geoms of each finger (all on one body per
      finger); the object touches these and nothing else.
    actuator: the actuator that closes the fingers (a position servo: fixed gain, affine
      bias, on a joint or a tendon).
    link_contacts: let the other collision geoms (links) touch the object too.
    actuator_kp / actuator_kv / actuator_forcerange: overrides of that servo's stiffness
      (force per unit length of its transmission), damping and symmetric force limit, in
      the actuator's units; None keeps the file's. The control range still means the
      same positions.
    """

    file: str
    mount_body: str
    pad_left_geoms: tuple[str, ...]
    pad_right_geoms: tuple[str, ...]
    actuator: str
    mount_quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    actuator_kp: float | None = None
    actuator_kv: float | None = None
    actuator_forcerange: float | None = None
    # also let the file's other collision geoms (the link meshes) touch the object: one
    # contact pair per link geom and object piece. Off by default: MJX compiles every
    # pair's mesh-mesh collision (benchmarks/probes/linkage.py links measures the cost), and
    # the table force is then the object's external force less the pads' AND the links'
    link_contacts: bool = False
    # the URDF this model is made from (``mjx_pick.core.urdf_gripper``): file is then the
    # URDF, and the names above are those the URDF import gives (see from_urdf)
    urdf: urdf_gripper.UrdfGripper | None = None

    def __post_init__(self):
        o = "gripper.mjcf"
        if isinstance(self.urdf, dict):  # from a saved config (JSON)
            urdf = from_mapping(urdf_gripper.UrdfGripper, self.urdf, where=f"{o}.urdf")
            object.__setattr__(self, "urdf", urdf)
        for side in ("pad_left_geoms", "pad_right_geoms"):
            value = getattr(self, side)
            if isinstance(value, str):
                object.__setattr__(self, side, (value,))
            elif not value:
                raise ConfigError(
                    f"{o}.{side} is empty: a two-finger gripper needs at least one pad geom "
                    "on each finger"
                )
        shared = set(self.pad_left_geoms) & set(self.pad_right_geoms)
        if shared:
            raise ConfigError(
                f"{o}: geom(s) {', '.join(sorted(shared))} are named for both fingers: "
                "pad_left_geoms and pad_right_geoms must be the two different fingers"
            )
        if len(self.mount_quat) != 4 or not np.any(np.asarray(self.mount_quat, float)):
            raise ConfigError(f"{o}.mount_quat = {self.mount_quat!r} must be 4 numbers, not all 0")
        for name in ("actuator_kp", "actuator_forcerange"):
            if getattr(self, name) is not None:
                check_range(o, name, getattr(self, name), 0, lo_open=True)
        if self.actuator_kv is not None:
            check_range(o, "actuator_kv", self.actuator_kv, 0)


class PadFrame(NamedTuple):
    """Where a pad's flat face lies in its own body, for collision boxes built over it:
    the centre of its geoms' bounding box in the body's frame (m), and the rotation
    (w, x, y, z) that takes the scene's gripper axes (x the closing axis, y across the
    pad, z up) into the body's, measured with the gripper fully open."""

    centre_m: tuple[float, float, float]
    quat: tuple[float, float, float, float]


@dataclasses.dataclass(frozen=True, eq=False)
class Kinematics:
    """A quasi-static close of an MJCF gripper, K samples from fully open to closed.

    All arrays (K,) unless said, in the scene's gripper frame, SI units, ascending in
    travel. travel: each pad's mean closing travel from fully open; opening: the gap
    between the pads' inner faces; pad_centre_z / pad_bottom_z: height of the pads'
    centre / lowest point relative to the gripper frame (negative: below it).
    """

    travel: np.ndarray
    opening: np.ndarray
    travel_left: np.ndarray
    travel_right: np.ndarray
    pad_centre_z: np.ndarray
    pad_bottom_z: np.ndarray
    q_left: np.ndarray  # left finger joint
    q_right: np.ndarray
    length: np.ndarray  # actuator length
    stiffness_n_per_m: np.ndarray  # pad force per m of target lead (the servo's)
    force_limit_n: np.ndarray  # largest pad force the actuator's force limit gives
    joint_names: tuple[str, ...]  # the gripper's joints (unprefixed)
    joint_qpos: np.ndarray  # (K, J) their positions
    pad_width_m: float  # along y
    pad_depth_m: float  # along x
    pad_height_m: float  # along z
    finger_joints: tuple[str, str]  # (left, right), unprefixed
    pad_bodies: tuple[str, str]
    ctrl_per_length: float
    ctrl_at_zero_length: float
    mass_kg: float  # the whole gripper
    finger_mass_kg: float  # the bodies moving with one pad's finger joint
    # (left, right); None where a pad geom is not a box (a curved or meshed pad has no
    # flat face to cut the rubber-like collision box from)
    pad_frames: tuple[PadFrame, PadFrame] | None = None

    @property
    def stroke_m(self) -> float:
        return float(self.opening[0])

    def drive_map(self) -> DriveMap:
        """The kernels' static tables."""

        def tup(a):
            return tuple(float(v) for v in a)

        ql, tl = _ascending(self.q_left, self.travel_left)
        qr, tr = _ascending(self.q_right, self.travel_right)
        return DriveMap(
            q_left=tup(ql),
            travel_left=tup(tl),
            q_right=tup(qr),
            travel_right=tup(tr),
            travel=tup(self.travel),
            length=tup(self.length),
            stiffness_n_per_m=tup(self.stiffness_n_per_m),
            ctrl_per_length=float(self.ctrl_per_length),
            ctrl_at_zero_length=float(self.ctrl_at_zero_length),
        )

    def travel_at_opening(self, opening_m):
        """Mean pad travel (m) at the given pad gaps (m), any shape."""
        return np.interp(opening_m, self.opening[::-1], self.travel[::-1])

    def pad_centre_drop_m(self, opening_m):
        """How far the pads' centre has descended from fully open at that gap, m (>= 0
        for a linkage whose pads swing down as they close)."""
        t = self.travel_at_opening(opening_m)
        return self.pad_centre_z[0] - np.interp(t, self.travel, self.pad_centre_z)

    def height_compensation_m(self, grasp_gap_m):
        """Starting lift (m) that puts the pads' centre at its fully-open height when the
        pads close to grasp_gap_m (the object's width between them): the paper's height
        compensation, the vertical travel between fully open and that gap."""
        return self.pad_centre_drop_m(grasp_gap_m)

    def joint_positions(self, travel_m) -> np.ndarray:
        """(N, J) gripper joint positions at mean pad travels (N,), m: a closed linkage
        (loop constraints satisfied) at each starting opening."""
        t = np.atleast_1d(np.asarray(travel_m, float))
        return np.stack(
            [
                np.interp(t, self.travel, self.joint_qpos[:, j])
                for j in range(len(self.joint_names))
            ],
            axis=1,
        )


def _ascending(x, y):
    """(x, y) sorted by x, for a lookup by x (np/jnp.interp need ascending x)."""
    order = np.argsort(x)
    return np.asarray(x)[order], np.asarray(y)[order]


def from_urdf(urdf: urdf_gripper.UrdfGripper, base_dir: Path) -> MjcfGripper:
    """The MJCF-path spec of a URDF gripper (its file resolved relative to base_dir and
    checked against the URDF): its mount body, pad geoms and servo as the import names
    them."""
    urdf = urdf_gripper.resolve(urdf, base_dir)
    return MjcfGripper(
        file=urdf.file,
        mount_body=urdf_gripper.root_link(urdf),
        pad_left_geoms=urdf_gripper.pad_geoms(urdf, "left"),
        pad_right_geoms=urdf_gripper.pad_geoms(urdf, "right"),
        actuator=urdf_gripper.SERVO,
        mount_quat=urdf.mount_quat,
        link_contacts=urdf.link_contacts,
        urdf=urdf,
    )


# each MjcfGripper field a URDF gripper's TOML sets under its own key ([urdf])
URDF_KEYS = {
    "file": "file",
    "mount_body": "mount_link",
    "mount_quat": "mount_quat",
    "pad_left_geoms": "pad_left_links",
    "pad_right_geoms": "pad_right_links",
    "actuator": "joint",
    "link_contacts": "link_contacts",
}


def in_urdf_words(text: str, urdf) -> str:
    """An MJCF gripper's error as a URDF gripper's TOML names things: its [urdf] keys
    (``gripper.mjcf.mount_quat`` is ``[urdf] mount_quat``), never the MJCF fields the
    URDF import made, of which a user's file says nothing."""

    def key(m: re.Match) -> str:
        field = m[1]
        if field in URDF_KEYS:
            return f"[urdf] {URDF_KEYS[field]}"
        return f"[urdf] file {urdf.file!r}'s model (its {field}, made by the URDF import)"

    text = re.sub(r"gripper\.mjcf\.file = '[^']*'", f"[urdf] file = {urdf.file!r}", text)
    return re.sub(r"gripper\.mjcf\.(\w+)", key, text).replace("gripper.mjcf:", "[urdf]:")


def resolve(mjcf: MjcfGripper, base_dir: Path) -> MjcfGripper:
    """The spec with its file made absolute (relative to base_dir) and checked."""
    path = Path(mjcf.file)
    if not path.is_absolute():
        path = (base_dir / path).resolve()
    if not path.is_file():
        raise ConfigError(f"gripper.mjcf.file = {mjcf.file!r}: no such file ({path})")
    return dataclasses.replace(mjcf, file=str(path))


def _names(spec_items) -> list[str]:
    return sorted(e.name for e in spec_items if e.name)


def _missing(kind: str, field: str, name: str, known: list[str]) -> ConfigError:
    shown = ", ".join(known[:30]) + (" ..." if len(known) > 30 else "")
    return ConfigError(
        f"gripper.mjcf.{field} = {name!r}: the MJCF has no {kind} of that name; "
        f"its named {kind}s: {shown or '(none)'}"
    )


def gripper_spec(mjcf: MjcfGripper, option: mujoco.MjOption | None = None) -> mujoco.MjSpec:
    """The gripper's MjSpec, ready to attach: its geoms never collide, bodies are held
    against gravity (the arm carries the gripper; the linkage is measured without it),
    the actuator overrides applied, and its options replaced by the scene's."""
    spec = _load(mjcf)
    act = _named_parts(spec, mjcf)
    _absolute_asset_paths(spec, mjcf)
    for name, geom in zip(_link_names(spec, mjcf), _link_geoms(spec, mjcf), strict=True):
        geom.name = name
    for geom in spec.geoms:
        geom.contype = 0
        geom.conaffinity = 0
    for body in spec.bodies:
        body.gravcomp = 1.0
    _override_servo(act, mjcf)
    if mjcf.urdf is not None:
        # a URDF's <mimic> is a rigid coupling; MuJoCo's default equality (a 20 ms time
        # constant) lets the mimicking finger lag and overshoot the driven one by
        # millimetres as the drive starts: make it the stiffest MuJoCo integrates
        # stably, two time steps
        step = option.timestep if option is not None else spec.option.timestep
        for eq in spec.equalities:
            eq.solref = [2.0 * step, 1.0]
    # the scene's solver options win: copy them so attaching raises no conflict
    if option is not None:
        for name in _SCENE_OPTIONS:
            setattr(spec.option, name, getattr(option, name))
    return spec


# the solver options an attached gripper takes from the scene
_SCENE_OPTIONS = (
    "timestep",
    "impratio",
    "cone",
    "integrator",
    "iterations",
    "ls_iterations",
    "tolerance",
    "noslip_iterations",
    "gravity",
)


def _named_parts(spec: mujoco.MjSpec, mjcf: MjcfGripper):
    """The spec's actuator that closes the fingers, once the mount body, every pad geom
    and that actuator are found in it (ConfigError naming the first that is missing)."""
    if spec.body(mjcf.mount_body) is None:
        raise _missing("body", "mount_body", mjcf.mount_body, _names(spec.bodies))
    for field in ("pad_left_geoms", "pad_right_geoms"):
        for name in getattr(mjcf, field):
            if spec.geom(name) is None:
                raise _missing("geom", field, name, _names(spec.geoms))
    act = spec.actuator(mjcf.actuator)
    if act is None:
        raise _missing("actuator", "actuator", mjcf.actuator, _names(spec.actuators))
    return act


def _absolute_asset_paths(spec: mujoco.MjSpec, mjcf: MjcfGripper) -> None:
    """Make the spec's mesh and texture files absolute: the scene's MJCF text (saved with
    every run) then loads anywhere."""
    folder = Path(mjcf.file).parent
    for mesh in spec.meshes:
        if mesh.file:
            mesh.file = str((folder / spec.meshdir / mesh.file).resolve())
    for texture in spec.textures:
        if texture.file:
            texture.file = str((folder / spec.texturedir / texture.file).resolve())


def _override_servo(act, mjcf: MjcfGripper) -> None:
    """Apply the ``actuator_kp`` / ``actuator_kv`` / ``actuator_forcerange`` overrides to
    the closing actuator (act, a spec's position servo)."""
    # keep the ctrl -> reference-length mapping (gain / kp) while changing kp
    kp_old = -act.biasprm[1]
    if mjcf.actuator_kp is not None and kp_old > 0:
        act.gainprm[0] = act.gainprm[0] * mjcf.actuator_kp / kp_old
        act.biasprm[0] = act.biasprm[0] * mjcf.actuator_kp / kp_old
        act.biasprm[1] = -mjcf.actuator_kp
    if mjcf.actuator_kv is not None:
        act.biasprm[2] = -mjcf.actuator_kv
    if mjcf.actuator_forcerange is not None:
        act.forcerange = [-mjcf.actuator_forcerange, mjcf.actuator_forcerange]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE


def _load(mjcf: MjcfGripper) -> mujoco.MjSpec:
    """The gripper's file as MuJoCo reads it (a URDF through ``urdf_gripper``)."""
    if mjcf.urdf is not None:
        return urdf_gripper.model_spec(mjcf.urdf)
    try:
        return mujoco.MjSpec.from_file(mjcf.file)
    except Exception as err:  # noqa: BLE001 - MuJoCo's parse errors are ValueErrors
        raise ConfigError(f"gripper.mjcf.file = {mjcf.file!r} does not load: {err}") from err


def _link_geoms(spec: mujoco.MjSpec, mjcf: MjcfGripper) -> list:
    """The file's collision geoms (contype or conaffinity set) other than the pads."""
    pads = set(mjcf.pad_left_geoms) | set(mjcf.pad_right_geoms)
    return [g for g in spec.geoms if (g.contype or g.conaffinity) and g.name not in pads]


def _link_names(spec: mujoco.MjSpec, mjcf: MjcfGripper) -> list[str]:
    return [g.name or f"link{k}" for k, g in enumerate(_link_geoms(spec, mjcf))]


@functools.cache
def link_geoms(mjcf: MjcfGripper) -> tuple[str, ...]:
    """Names (unprefixed) of the gripper's link collision geoms, as attached (unnamed
    ones are named link0, link1, ...)."""
    spec = _load(mjcf)
    return tuple(_link_names(spec, mjcf))


def attach(scene: mujoco.MjSpec, mjcf: MjcfGripper, parent_body: str, pos=(0.0, 0.0, 0.0)):
    """Attach the gripper under scene's parent_body (names get PREFIX)."""
    g = gripper_spec(mjcf, scene.option)
    frame = scene.body(parent_body).add_frame(pos=list(pos), quat=list(mjcf.mount_quat))
    frame.attach_body(g.body(mjcf.mount_body), PREFIX, "")


def _check_position_servo(m: mujoco.MjModel, a: int, name: str):
    """The actuator must be a position servo: force = gain*ctrl + b0 - kp*length - kv*vel."""
    if int(m.actuator_gaintype[a]) != int(mujoco.mjtGain.mjGAIN_FIXED) or int(
        m.actuator_biastype[a]
    ) != int(mujoco.mjtBias.mjBIAS_AFFINE):
        raise ConfigError(
            f"gripper.mjcf.actuator = {name!r} is not a position servo (fixed gain, affine "
            "bias): the force controller sets its reference position; use a <position> or "
            "<general gaintype='fixed' biastype='affine'> actuator"
        )
    if not (m.actuator_biasprm[a, 1] < 0 and m.actuator_gainprm[a, 0] != 0):
        raise ConfigError(
            f"gripper.mjcf.actuator = {name!r} has no position stiffness (biasprm[1] = "
            f"{m.actuator_biasprm[a, 1]:g}, gainprm[0] = {m.actuator_gainprm[a, 0]:g}): "
            "it cannot hold a reference position"
        )
    if int(m.actuator_trntype[a]) not in (
        int(mujoco.mjtTrn.mjTRN_JOINT),
        int(mujoco.mjtTrn.mjTRN_TENDON),
    ):
        raise ConfigError(f"gripper.mjcf.actuator = {name!r} acts on neither a joint nor a tendon")


def _pad_body(m: mujoco.MjModel, geoms: tuple[str, ...], field: str) -> int:
    bodies = {int(m.geom_bodyid[m.geom(PREFIX + g).id]) for g in geoms}
    if len(bodies) != 1:
        names = ", ".join(m.body(b).name[len(PREFIX) :] for b in sorted(bodies))
        raise ConfigError(
            f"gripper.mjcf.{field} lie on several bodies ({names}): the pad force is "
            "measured on one body per finger; name the geoms of one pad body"
        )
    return bodies.pop()


def _ancestor_joints(m: mujoco.MjModel, body: int) -> list[int]:
    out = []
    while body > 0:
        start, n = m.body_jntadr[body], m.body_jntnum[body]
        out += list(range(start, start + n))
        body = m.body_parentid[body]
    return out


def _drive_joints(m: mujoco.MjModel, a: int) -> set[int]:
    """Joints the actuator moves directly (its joint, or its fixed tendon's joints)."""
    if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT):
        return {int(m.actuator_trnid[a, 0])}
    t = m.actuator_trnid[a, 0]
    adr, num = m.tendon_adr[t], m.tendon_num[t]
    return {
        int(m.wrap_objid[i])
        for i in range(adr, adr + num)
        if int(m.wrap_type[i]) == int(mujoco.mjtWrap.mjWRAP_JOINT)
    }


_HINGE_OR_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


def _finger_joint(
    m: mujoco.MjModel, d: mujoco.MjData, driven: set[int], side: str, act: str
) -> int:
    """The joint on that side's finger (its body at -x for the left, +x for the right)
    that the actuator drives, directly, by its tendon, or through a joint equality (a
    finger mirrored from the other). In a closed linkage the pad hangs from a passive
    chain, so "on that side" is decided by position, not by the pad's ancestors."""
    coupled = set(driven)
    for e in range(m.neq):
        if int(m.eq_type[e]) == int(mujoco.mjtEq.mjEQ_JOINT):
            j1, j2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            if j1 in driven or j2 in driven:
                coupled |= {j1, j2}
    sign = -1.0 if side == "left" else 1.0
    for j in sorted(coupled):
        if int(m.jnt_type[j]) in _HINGE_OR_SLIDE and sign * d.xanchor[j, 0] > 0:
            return j
    raise ConfigError(
        f"gripper.mjcf.actuator = {act!r} does not drive the {side} finger: none of the "
        f"joints it moves (directly, by its tendon or through a joint equality) lies on the "
        f"{side} side ({'-x' if side == 'left' else '+x'}) of the gripper"
    )


def _pad_box(m: mujoco.MjModel, d: mujoco.MjData, geoms: list[int]) -> np.ndarray:
    """(2, 3) world AABB (min, max) of the geoms' bounding boxes."""
    corners = []
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    for g in geoms:
        centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
        local = centre + signs * half
        corners.append(d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T)
    c = np.concatenate(corners)
    return np.stack([c.min(axis=0), c.max(axis=0)])


def _pad_frame(m: mujoco.MjModel, d: mujoco.MjData, geoms: list[int], body: int):
    """The PadFrame of a pad's geoms on their body at the current state; None unless
    every geom is a box."""
    if any(int(m.geom_type[g]) != int(mujoco.mjtGeom.mjGEOM_BOX) for g in geoms):
        return None
    lo, hi = _pad_box(m, d, geoms)
    rot = d.xmat[body].reshape(3, 3)  # body -> gripper frame
    centre = rot.T @ (0.5 * (lo + hi) - d.xpos[body])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.T.flatten())
    return PadFrame(tuple(float(v) for v in centre), tuple(float(v) for v in quat))


def _bench_model(mjcf: MjcfGripper) -> mujoco.MjModel:
    """The gripper alone, mounted like in a scene (gripper frame at the origin)."""
    bench = mujoco.MjSpec.from_string(
        '<mujoco><option timestep="0.001" integrator="implicitfast" gravity="0 0 0"/>'
        '<worldbody><body name="gripper"/></worldbody></mujoco>'
    )
    attach(bench, mjcf, "gripper")
    try:
        return bench.compile()
    except Exception as err:  # noqa: BLE001 - compile errors are ValueErrors
        raise ConfigError(f"gripper.mjcf.file = {mjcf.file!r} does not compile: {err}") from err


@functools.cache
def characterise(mjcf: MjcfGripper) -> Kinematics:
    """Close the gripper quasi-statically on the MuJoCo C engine and tabulate it.

    The control is stepped from the open end of its range to the closed end in
    N_SAMPLES steps, SETTLE_STEPS physics steps each (no gravity, no object): the
    linkage's own loop constraints and springs set every joint. Raises ConfigError
    naming the field when the model lacks what a two-finger gripper needs.

    The close is a pure function of the compiled gripper, the names of its pads and
    actuator and this module's code: it is kept in the on-disk cache
    (``mjx_pick.core.cache``) under a digest of the compiled model in MuJoCo's binary
    form (every file, include and override it was made from), and a later process
    reads it back bit for bit instead of closing the gripper again.
    """
    m = _bench_model(mjcf)
    key = {
        "model_sha256": cache.digest(_model_bytes(m)),
        "actuator": mjcf.actuator,
        "pad_left_geoms": list(mjcf.pad_left_geoms),
        "pad_right_geoms": list(mjcf.pad_right_geoms),
        "n_samples": N_SAMPLES,
        "settle_steps": SETTLE_STEPS,
        "code_sha256": cache.code_digest(__name__),
        "mujoco_version": mujoco.__version__,
    }
    arrays = cache.memo("gripper_close", key, lambda: _kinematics_arrays(_close(m, mjcf)))
    return _kinematics_of(arrays)


def _model_bytes(m: mujoco.MjModel) -> np.ndarray:
    """The compiled model in MuJoCo's binary format (uint8): the same bytes for the same
    model in every process."""
    buf = np.empty(mujoco.mj_sizeModel(m), np.uint8)
    mujoco.mj_saveModel(m, None, buf)
    return buf


def _kinematics_arrays(kin: Kinematics) -> dict[str, np.ndarray]:
    """kin as named arrays for the cache: its arrays as they are, every other field
    (floats, names, pad frames) in one JSON text, which reads a float back exactly."""
    arrays, rest = {}, {}
    for f in dataclasses.fields(kin):
        value = getattr(kin, f.name)
        if isinstance(value, np.ndarray):
            arrays[f.name] = value
        else:
            rest[f.name] = value
    arrays["fields_json"] = np.frombuffer(json.dumps(rest).encode(), np.uint8)
    return arrays


def _kinematics_of(arrays: dict[str, np.ndarray]) -> Kinematics:
    """The Kinematics of :func:`_kinematics_arrays`' arrays (computed or read back)."""
    rest = json.loads(arrays["fields_json"].tobytes())
    frames = rest.pop("pad_frames")
    if frames is not None:
        frames = tuple(PadFrame(tuple(c), tuple(q)) for c, q in frames)
    for name in ("joint_names", "finger_joints", "pad_bodies"):
        rest[name] = tuple(rest[name])
    named = {f.name for f in dataclasses.fields(Kinematics)} - set(rest) - {"pad_frames"}
    return Kinematics(**{n: arrays[n] for n in named}, **rest, pad_frames=frames)


def _close(m: mujoco.MjModel, mjcf: MjcfGripper) -> Kinematics:
    """:func:`characterise`'s close on the gripper's bench model m."""
    d = mujoco.MjData(m)
    a = m.actuator(PREFIX + mjcf.actuator).id
    _check_position_servo(m, a, mjcf.actuator)
    left = [m.geom(PREFIX + g).id for g in mjcf.pad_left_geoms]
    right = [m.geom(PREFIX + g).id for g in mjcf.pad_right_geoms]
    body_l = _pad_body(m, mjcf.pad_left_geoms, "pad_left_geoms")
    body_r = _pad_body(m, mjcf.pad_right_geoms, "pad_right_geoms")
    lo, hi = m.actuator_ctrlrange[a] if m.actuator_ctrllimited[a] else (-1.0, 1.0)

    def settle(ctrl):
        d.ctrl[a] = ctrl
        for _ in range(SETTLE_STEPS):
            mujoco.mj_step(m, d)
        mujoco.mj_forward(m, d)
        return _pad_box(m, d, left), _pad_box(m, d, right)

    c_open, c_closed = _closing_direction(mjcf, m, d, settle, lo, hi)
    mujoco.mj_resetData(m, d)
    settle(c_open)
    frames = (_pad_frame(m, d, left, body_l), _pad_frame(m, d, right, body_r))
    mujoco.mj_resetData(m, d)
    mujoco.mj_forward(m, d)
    driven = _drive_joints(m, a)
    j_left = _finger_joint(m, d, driven, "left", mjcf.actuator)
    j_right = _finger_joint(m, d, driven, "right", mjcf.actuator)
    jids = list(range(m.njnt))
    rows = _stroke_samples(m, d, a, settle, (c_open, c_closed), (j_left, j_right), jids)
    return _tabulate(m, mjcf, a, rows, (j_left, j_right), (body_l, body_r), frames)


def _tabulate(m: mujoco.MjModel, mjcf: MjcfGripper, a: int, rows, fingers, bodies, frames):
    """The :class:`Kinematics` of the stroke samples rows (:func:`_stroke_samples`), kept
    where the pads close steadily. a: the closing actuator's id; fingers: the (left,
    right) finger joints' ids; bodies: the pads' bodies' ids; frames: their PadFrames
    (None in either: not a box pad)."""
    j_left, j_right = fingers
    body_l, body_r = bodies
    travel_l, travel_r, opening, keep = _steady_stroke(rows, mjcf.actuator)
    travel = 0.5 * (travel_l + travel_r)
    length = np.array([r[6] for r in rows])
    kp = -m.actuator_biasprm[a, 1]
    gain = m.actuator_gainprm[a, 0]
    stiffness, force_limit = _pad_servo(m, a, travel, length)
    extents = rows[0][8]
    depth = float(min(extents[0][0], extents[1][0]))
    width = float(min(extents[0][1], extents[1][1]))
    height = float(min(extents[0][2], extents[1][2]))
    finger_bodies = {b for b in range(m.nbody) if j_left in _ancestor_joints(m, b)}
    return Kinematics(
        travel=travel[keep],
        opening=opening[keep],
        travel_left=travel_l[keep],
        travel_right=travel_r[keep],
        pad_centre_z=np.array([r[2] for r in rows])[keep],
        pad_bottom_z=np.array([r[3] for r in rows])[keep],
        q_left=np.array([r[4] for r in rows])[keep],
        q_right=np.array([r[5] for r in rows])[keep],
        length=length[keep],
        stiffness_n_per_m=stiffness[keep],
        force_limit_n=force_limit[keep],
        joint_names=tuple(m.joint(j).name[len(PREFIX) :] for j in range(m.njnt)),
        joint_qpos=np.array([r[7] for r in rows])[keep],
        pad_width_m=width,
        pad_depth_m=depth,
        pad_height_m=height,
        finger_joints=(m.joint(j_left).name[len(PREFIX) :], m.joint(j_right).name[len(PREFIX) :]),
        pad_bodies=(m.body(body_l).name[len(PREFIX) :], m.body(body_r).name[len(PREFIX) :]),
        ctrl_per_length=float(kp / gain),
        ctrl_at_zero_length=float(-m.actuator_biasprm[a, 0] / gain),
        mass_kg=float(m.body_subtreemass[1]),
        finger_mass_kg=float(sum(m.body_mass[b] for b in finger_bodies)),
        pad_frames=None if None in frames else frames,
    )


def _steady_stroke(rows, actuator: str):
    """(left travel, right travel, opening, keep) of the stroke samples rows, m (K,)
    each, and which samples to keep: the monotonic part of the stroke with a gap >= 0;
    ConfigError when fewer than 5 remain."""
    xl = np.array([r[0] for r in rows])
    xr = np.array([r[1] for r in rows])
    opening = xr - xl
    travel_l, travel_r = xl - xl[0], xr[0] - xr
    travel = 0.5 * (travel_l + travel_r)
    # the closed end: the pads pass through each other (they never collide here); keep
    # the monotonic part of the stroke with a gap >= 0
    keep = (opening >= 0) & np.concatenate([[True], np.diff(travel) > 1e-6])
    keep &= np.cumprod(keep).astype(bool)
    if keep.sum() < 5:
        raise ConfigError(
            f"gripper.mjcf.actuator = {actuator!r}: the pads do not close steadily over "
            "its control range (fewer than 5 samples with a growing travel)"
        )
    return travel_l, travel_r, opening, keep


def _pad_servo(m: mujoco.MjModel, a: int, travel, length):
    """(stiffness N/m, force limit N) the actuator a gives each pad along the stroke
    ((K,) pad travels and actuator lengths, m): by virtual work."""
    kp = -m.actuator_biasprm[a, 1]
    # virtual work: the actuator force tau on its length L balances both pads' forces F
    # over their travels: tau dL = F (dx_l + dx_r) = 2 F dx
    dx_dl = np.gradient(travel, length)
    stiffness = kp / (2.0 * dx_dl**2)
    f_range = m.actuator_forcerange[a] if m.actuator_forcelimited[a] else (-np.inf, np.inf)
    force_limit = np.max(np.abs(f_range)) / (2.0 * np.abs(dx_dl))
    return stiffness, force_limit


def _closing_direction(mjcf: MjcfGripper, m, d, settle, lo: float, hi: float):
    """(control that opens, control that closes), from the pads at both ends of the
    control range; ConfigError when the actuator does not close the gripper along x,
    the pads are on the wrong sides, or they do not hang below the mount. settle(ctrl):
    the pads' boxes at rest under ctrl."""
    mujoco.mj_resetData(m, d)
    end_lo = settle(lo)
    mujoco.mj_resetData(m, d)
    end_hi = settle(hi)
    gap_lo = end_lo[1][0, 0] - end_lo[0][1, 0]
    gap_hi = end_hi[1][0, 0] - end_hi[0][1, 0]
    if abs(gap_hi - gap_lo) < 1e-3:
        raise ConfigError(
            f"gripper.mjcf.actuator = {mjcf.actuator!r} does not close the gripper: over its "
            f"control range [{lo:g}, {hi:g}] the gap between the pads changes by "
            f"{abs(gap_hi - gap_lo) * 1e3:.2f} mm along x (check the pad geoms and mount_quat: "
            "the fingers must close along the gripper's x axis)"
        )
    c_open, c_closed = (lo, hi) if gap_lo > gap_hi else (hi, lo)
    box_open = end_lo if gap_lo > gap_hi else end_hi
    if not (box_open[0][1, 0] < 0 < box_open[1][0, 0]):
        raise ConfigError(
            "gripper.mjcf: the left pads must lie at -x and the right pads at +x of the "
            f"gripper centre when open (left inner face at {box_open[0][1, 0] * 1e3:.1f} mm, "
            f"right at {box_open[1][0, 0] * 1e3:.1f} mm): swap pad_left_geoms and "
            "pad_right_geoms or turn mount_quat"
        )
    if box_open[0][0, 2] > 0 or box_open[1][0, 2] > 0:
        raise ConfigError(
            "gripper.mjcf.mount_quat: the pads must hang below the mount (the gripper "
            "approaches along -z); turn the gripper over"
        )
    return c_open, c_closed


def _stroke_samples(m, d, a: int, settle, ctrls, fingers, jids) -> list[tuple]:
    """N_SAMPLES rows at rest from the open control to the closed one (ctrls): pads'
    inner faces x, centre and bottom z, the finger joints' (fingers) and every joint's
    (jids) positions, the actuator length and the pads' extents; ConfigError when the
    gripper does not come to rest."""
    j_left, j_right = fingers
    rows = []
    for ctrl in np.linspace(*ctrls, N_SAMPLES):
        bl, br = settle(ctrl)
        rows.append(
            (
                bl[1, 0],  # left inner face x
                br[0, 0],  # right inner face x
                0.5 * (bl[0, 2] + bl[1, 2] + br[0, 2] + br[1, 2]) / 2,  # pad centre z
                min(bl[0, 2], br[0, 2]),
                d.qpos[m.jnt_qposadr[j_left]],
                d.qpos[m.jnt_qposadr[j_right]],
                d.actuator_length[a],
                [d.qpos[m.jnt_qposadr[j]] for j in jids],
                (bl[1] - bl[0], br[1] - br[0]),
            )
        )
        if np.max(np.abs(d.qvel)) > 1e-2:
            raise ConfigError(
                f"gripper.mjcf: the gripper did not come to rest at ctrl = {ctrl:g} "
                f"(|qvel| = {np.max(np.abs(d.qvel)):.3g}): its drive or loop constraints "
                "are unstable"
            )
    return rows
