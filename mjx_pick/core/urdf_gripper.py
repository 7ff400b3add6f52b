"""Two-finger grippers from URDF files: MuJoCo's URDF import plus the servo a URDF lacks.

Details: docs/model.md (core/urdf_gripper.py).
"""

from __future__ import annotations

import dataclasses
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from mjx_pick.core.config import ConfigError, check_range, read_text

SERVO = "urdf_servo"  # the name of the actuator added on the joint
_MOVING = ("revolute", "prismatic")


@dataclasses.dataclass(frozen=True)
class UrdfGripper:
    """The ``[urdf]`` table of a gripper TOML: what in the URDF file is what.

    file: the URDF (relative to the TOML); its meshes relative to it, absolute, or
      ``package://NAME/...`` under an ancestor folder named NAME.
    pad_left_links / pad_right_links: each finger's pad links (their collision
      geometry is all the object touches).
    joint: the revolute or prismatic joint the servo drives (``<mimic>`` joints and
      ``mimic`` follow it). servo_kp / servo_kv / servo_forcerange: the servo's
      stiffness, damping and symmetric force limit (N m/rad, N m s/rad, N m; or N/m,
      N s/m, N for a prismatic joint).
    drive_armature: the drive's inertia reflected at the joint (kg m^2 or kg; a URDF
      has no field for it); linkage_armature: the same on every other moving joint,
      which keeps ``<mimic>`` couplings stiff (docs/model.md).
    mount_link / mount_quat: the link whose subtree is the gripper ("": the root) and
      its orientation (w, x, y, z) in the scene's gripper frame (pads below it, closing
      along x). mimic: couplings the URDF lacks, {joint: multiplier} (offset 0).
    link_contacts: let the other links' collision geoms touch the object too.
    """

    file: str
    pad_left_links: tuple[str, ...]
    pad_right_links: tuple[str, ...]
    joint: str
    servo_kp: float
    servo_kv: float
    servo_forcerange: float
    drive_armature: float
    linkage_armature: float
    mount_link: str = ""
    mount_quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    mimic: tuple[tuple[str, float], ...] | None = None
    link_contacts: bool = False

    def __post_init__(self):
        o = "gripper.urdf"
        for side in ("pad_left_links", "pad_right_links"):
            value = getattr(self, side)
            if isinstance(value, str):
                object.__setattr__(self, side, (value,))
            elif not value:
                raise ConfigError(
                    f"{o}.{side} is empty: a two-finger gripper needs a pad link on each finger"
                )
        shared = set(self.pad_left_links) & set(self.pad_right_links)
        if shared:
            raise ConfigError(
                f"{o}: link(s) {', '.join(sorted(shared))} are named for both fingers: "
                "pad_left_links and pad_right_links must be the two different fingers"
            )
        if isinstance(self.mimic, dict):  # a TOML table; pairs from saved JSON
            pairs = self.mimic.items()
        else:
            pairs = self.mimic or ()
        try:
            mimic = tuple(sorted((str(j), float(k)) for j, k in pairs))
        except (TypeError, ValueError) as err:
            raise ConfigError(
                f"{o}.mimic = {self.mimic!r} must be a table of joint = multiplier"
            ) from err
        for joint, k in mimic:
            if not math.isfinite(k) or k == 0:
                raise ConfigError(f"{o}.mimic.{joint} = {k!r} must be a finite, non-zero number")
        if self.joint in dict(mimic):
            raise ConfigError(f"{o}.mimic names the driven joint {self.joint!r} itself")
        object.__setattr__(self, "mimic", mimic)
        if len(self.mount_quat) != 4 or not np.any(np.asarray(self.mount_quat, float)):
            raise ConfigError(f"{o}.mount_quat = {self.mount_quat!r} must be 4 numbers, not all 0")
        check_range(o, "servo_kp", self.servo_kp, 0, lo_open=True)
        check_range(o, "servo_kv", self.servo_kv, 0)
        check_range(o, "servo_forcerange", self.servo_forcerange, 0, lo_open=True)
        check_range(o, "drive_armature", self.drive_armature, 0)
        check_range(o, "linkage_armature", self.linkage_armature, 0)


def resolve(urdf: UrdfGripper, base_dir: Path) -> UrdfGripper:
    """The spec with its file made absolute (relative to base_dir) and checked against
    the URDF: every named link and joint exists, every collision mesh file is there."""
    path = Path(urdf.file)
    if not path.is_absolute():
        path = (base_dir / path).resolve()
    if not path.is_file():
        raise ConfigError(f"[urdf] file = {urdf.file!r}: no such file ({path})")
    urdf = dataclasses.replace(urdf, file=str(path))
    _Robot.read(urdf.file).check(urdf)
    return urdf


def root_link(urdf: UrdfGripper) -> str:
    """The mount link: the table's, or the URDF's root (the link no joint is a child of)."""
    return urdf.mount_link or _Robot.read(urdf.file).root()


def pad_geoms(urdf: UrdfGripper, side: str) -> tuple[str, ...]:
    """Names of a finger's pad geoms in the model (side "left" or "right")."""
    robot = _Robot.read(urdf.file)
    links = urdf.pad_left_links if side == "left" else urdf.pad_right_links
    return tuple(geom_name(link, k) for link in links for k in range(len(robot.collisions(link))))


def geom_name(link: str, k: int) -> str:
    """The name given to the k-th collision geom of a link."""
    return f"{link}_collision{k}"


def model_spec(urdf: UrdfGripper) -> mujoco.MjSpec:
    """The gripper as MuJoCo's URDF import makes it, with its collision geoms named, the
    TOML's couplings and the position servo on the joint added. ConfigError when the
    file does not load."""
    robot = _Robot.read(urdf.file)
    robot.check(urdf)
    try:
        spec = mujoco.MjSpec.from_string(robot.mujoco_text())
    except Exception as err:  # noqa: BLE001 - MuJoCo's parse errors are ValueErrors
        raise ConfigError(f"[urdf] file = {urdf.file!r} does not load: {err}") from err
    for body in spec.bodies:
        geoms = list(body.geoms)
        want = len(robot.collisions(body.name)) if body.name in robot.links else 0
        if len(geoms) != want:
            raise ConfigError(
                f"[urdf] file = {urdf.file!r}: MuJoCo made {len(geoms)} geom(s) of link "
                f"{body.name!r}, whose URDF has {want} collision element(s)"
            )
        for k, geom in enumerate(geoms):
            geom.name = geom_name(body.name, k)
    for follower, multiplier in urdf.mimic:
        spec.add_equality(
            type=mujoco.mjtEq.mjEQ_JOINT,
            name1=follower,
            name2=urdf.joint,
            data=[0.0, multiplier] + [0.0] * (mujoco.mjNEQDATA - 2),
        )
    lo, hi = robot.limits(urdf.joint)
    for joint in spec.joints:
        joint.armature = urdf.linkage_armature
    spec.joint(urdf.joint).armature = urdf.drive_armature
    kp, kv = urdf.servo_kp, urdf.servo_kv
    spec.add_actuator(
        name=SERVO,
        target=urdf.joint,
        trntype=mujoco.mjtTrn.mjTRN_JOINT,
        gaintype=mujoco.mjtGain.mjGAIN_FIXED,
        biastype=mujoco.mjtBias.mjBIAS_AFFINE,
        gainprm=[kp] + [0.0] * 9,
        biasprm=[0.0, -kp, -kv] + [0.0] * 7,
        ctrlrange=[lo, hi],
        ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE,
        forcerange=[-urdf.servo_forcerange, urdf.servo_forcerange],
        forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE,
    )
    return spec


class _Robot:
    """A URDF file's elements, read with ElementTree (names in messages, mesh paths)."""

    def __init__(self, path: Path, root: ET.Element):
        self.path = path
        self.tree = root
        self.links = {e.get("name"): e for e in root.findall("link")}
        self.joints = {e.get("name"): e for e in root.findall("joint")}

    @classmethod
    def read(cls, file: str) -> _Robot:
        path = Path(file)
        text = read_text(path, "[urdf] file")
        try:
            root = _parse(text)
        except ET.ParseError as err:
            raise ConfigError(f"[urdf] file = {file!r} is not an XML file: {err}") from err
        if root.tag != "robot":
            raise ConfigError(
                f"[urdf] file = {file!r} is not a URDF: its root element is "
                f"<{root.tag}>, not <robot>"
            )
        return cls(path, root)

    def collisions(self, link: str) -> list[ET.Element]:
        return self.links[link].findall("collision")

    def root(self) -> str:
        tags = (j.find("child") for j in self.joints.values())
        children = {c.get("link") for c in tags if c is not None}
        roots = [name for name in self.links if name not in children]
        if len(roots) != 1:
            raise ConfigError(
                f"[urdf] file = {str(self.path)!r} has {len(roots)} root links "
                f"({', '.join(roots) or 'none'}); name the gripper's with mount_link"
            )
        return roots[0]

    def limits(self, joint: str) -> tuple[float, float]:
        limit = self.joints[joint].find("limit")
        lo, hi = (None, None) if limit is None else (limit.get("lower"), limit.get("upper"))
        try:
            lo_f, hi_f = float(lo), float(hi)
        except (TypeError, ValueError):
            lo_f = hi_f = math.nan
        if not (math.isfinite(lo_f) and math.isfinite(hi_f) and lo_f < hi_f):
            raise ConfigError(
                f"[urdf] joint = {joint!r} has no <limit lower=... upper=...> with "
                f"lower < upper (lower={lo}, upper={hi}): its range is the servo's control range"
            )
        return lo_f, hi_f

    def check(self, urdf: UrdfGripper) -> None:
        """ConfigError naming the first link, joint or mesh of the spec that is missing."""
        for field in ("pad_left_links", "pad_right_links"):
            for link in getattr(urdf, field):
                if link not in self.links:
                    raise _missing("link", field, link, self.links)
                if not self.collisions(link):
                    raise ConfigError(
                        f"[urdf] {field}: link {link!r} has no <collision> geometry; "
                        "the pads touch the object through their collision geoms"
                    )
        if urdf.mount_link and urdf.mount_link not in self.links:
            raise _missing("link", "mount_link", urdf.mount_link, self.links)
        if urdf.joint not in self.joints:
            raise _missing("joint", "joint", urdf.joint, self.joints)
        kind = self.joints[urdf.joint].get("type")
        if kind not in _MOVING:
            raise ConfigError(
                f"[urdf] joint = {urdf.joint!r} is a {kind} joint: the servo drives a "
                "revolute or prismatic joint"
            )
        self.limits(urdf.joint)
        for follower, _ in urdf.mimic:
            if follower not in self.joints:
                raise _missing("joint", f"mimic.{follower}", follower, self.joints)
            if self.joints[follower].get("type") not in _MOVING:
                raise ConfigError(
                    f"[urdf] mimic.{follower}: joint {follower!r} is a "
                    f"{self.joints[follower].get('type')} joint, not revolute or prismatic"
                )
        for link, element in self.links.items():
            for collision in element.findall("collision"):
                mesh = collision.find("geometry/mesh")
                if mesh is not None:
                    self.mesh_path(link, mesh.get("filename", ""))

    def mesh_path(self, link: str, filename: str) -> Path:
        """A collision mesh's file, absolute; ConfigError naming the link and the mesh."""
        if filename.startswith("package://"):
            package, _, rest = filename[len("package://") :].partition("/")
            folder = next((p for p in self.path.parents if p.name == package), None)
            path = None if folder is None else folder / rest
            where = f"no folder named {package!r} above {self.path.parent}"
        elif filename.startswith("file://"):
            path = Path(filename[len("file://") :])
            where = str(path)
        else:
            path = (self.path.parent / filename).resolve()
            where = str(path)
        if path is None or not path.is_file():
            raise ConfigError(
                f"[urdf] file = {str(self.path)!r}: link {link!r}'s collision mesh "
                f"{filename!r} is missing ({where})"
            )
        return path.resolve()

    def mujoco_text(self) -> str:
        """The URDF as MuJoCo should read it: collision mesh paths absolute, visual
        geometry dropped, every link a body (the pads' links keep their names)."""
        root = ET.fromstring(ET.tostring(self.tree))
        for link in root.findall("link"):
            for visual in link.findall("visual"):
                link.remove(visual)
            for mesh in link.findall("collision/geometry/mesh"):
                mesh.set("filename", str(self.mesh_path(link.get("name"), mesh.get("filename"))))
        # the file's own MuJoCo extension (balanceinertia, ...) stays; these settings win
        ext = root.find("mujoco")
        if ext is None:
            ext = ET.SubElement(root, "mujoco")
        compiler = ext.find("compiler")
        if compiler is None:
            compiler = ET.SubElement(ext, "compiler")
        compiler.attrib.pop("meshdir", None)
        compiler.attrib.update(
            {"discardvisual": "true", "fusestatic": "false", "strippath": "false"}
        )
        return ET.tostring(root, encoding="unicode")


def _parse(text: str) -> ET.Element:
    """A URDF's root element, other tools' extensions left out: URDFs often use a
    prefix they never declare (``<drake:collision_filter_group>``), which XML refuses;
    such prefixes are declared here, and every prefixed element is dropped (no URDF
    element has a prefix)."""
    prefixes = set(re.findall(r"<\s*/?\s*([A-Za-z_][\w.-]*):", text)) - {"xml"}
    declared = set(re.findall(r"xmlns:([A-Za-z_][\w.-]*)\s*=", text))
    extra = "".join(f' xmlns:{p}="urn:undeclared:{p}"' for p in sorted(prefixes - declared))
    if extra:
        # on the root element, the first tag that is no declaration or comment
        text = re.sub(r"(<(?![?!])[A-Za-z_][\w.:-]*)", lambda m: m[1] + extra, text, count=1)
    root = ET.fromstring(text)
    for parent in root.iter():
        for child in [c for c in parent if isinstance(c.tag, str) and c.tag.startswith("{")]:
            parent.remove(child)
    return root


def _missing(kind: str, field: str, name: str, known) -> ConfigError:
    names = sorted(n for n in known if n)
    shown = ", ".join(names[:30]) + (" ..." if len(names) > 30 else "")
    return ConfigError(
        f"[urdf] {field} = {name!r}: the URDF has no {kind} of that name; "
        f"its {kind}s: {shown or '(none)'}"
    )
