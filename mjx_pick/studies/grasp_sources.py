"""Where a study's grasps come from: top-down pick-points, antipodal grasps on the part's
mesh, or a grasp file of the field's formats. Every study draws them here.

Details: docs/formats.md ("Grasps").
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from mjx_pick.core import numbers
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.antipodal import AntipodalConfig, generate_antipodal, rejected_words
from mjx_pick.core.config import ConfigError
from mjx_pick.core.grasp_checks import GraspChecker
from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.scene import Scene
from mjx_pick.core.settings import Settings
from mjx_pick.engine.inputs import scene_of
from mjx_pick.outputs.exchange import SUFFIXES, read_labels

TOPDOWN, ANTIPODAL = "topdown", "antipodal"
# how far a grasp centre may lie outside the part's bounding box before the file and the
# mesh are taken to disagree (a unit or a frame): a gripper's reach, generously
FAR_FROM_PART_M = 0.2


def check_source(source: str, depth_mm: float | None = None) -> str:
    """The grasp source a user named, checked before any work: "topdown", "antipodal",
    or an existing grasp file whose suffix names a format (``outputs.exchange``)."""
    if not isinstance(source, str | os.PathLike) or not str(source).strip():
        raise ConfigError(
            f"grasps = {source!r} is not allowed: choose 'topdown', 'antipodal' or a grasp file"
        )
    if str(source) in (TOPDOWN, ANTIPODAL):
        if depth_mm is not None:
            raise ConfigError(
                f"depth_mm (--depth-mm) is for grasps read from a file, not grasps = {source!r}"
            )
        return str(source)
    path = Path(source)
    if path.suffix.lower() not in SUFFIXES.values():
        raise ConfigError(
            f"grasps = {str(source)!r} is neither 'topdown', 'antipodal' nor a grasp file "
            f"(ACRONYM .h5, GraspGen .json, isaac_grasp .yaml, a CSV of poses .csv)"
        )
    if not path.is_file():
        raise ConfigError(f"grasps file {str(path)!r} does not exist")
    numbers.check_optional("depth_mm", depth_mm)
    return str(path)


def source_key(run) -> dict | None:
    """A grasp source in a configuration key (run: ``RunOptions``): None for top-down
    pick-points (their keys as before), the antipodal settings, or a file's digest (its
    bytes, not its name) and the depth given for it."""
    from mjx_pick.core.cache import file_digest
    from mjx_pick.core.config import to_dict

    if run.grasps == TOPDOWN:
        return None
    if run.grasps == ANTIPODAL:
        return {"antipodal": to_dict(run.antipodal or AntipodalConfig())}
    return {"file": file_digest(run.grasps), "depth_mm": run.depth_mm}


def draw_grasps(
    obj: ObjectModel,
    settings: Settings,
    n: int,
    seed: int = 0,
    pick_config: pp.PickConfig | None = None,
    source: str = TOPDOWN,
    *,
    antipodal: AntipodalConfig | None = None,
    depth_mm: float | None = None,
    scene: Scene | None = None,
    device: str | None = None,
) -> GraspBatch:
    """A study's grasps for obj under settings: n top-down pick-points (``pickpoints``),
    n antipodal grasps on the part's mesh (``core.antipodal``), or every grasp of a file
    (:func:`file_grasps`, n unused). scene: the compiled scene, when the caller has it
    (the grasp checks need one; built here otherwise). device: the Warp device that
    checks top-down candidates (``pickpoints.FeasibilityChecker``; None: numpy)."""
    config = pick_config or pp.PickConfig()
    if source == TOPDOWN:
        return pp.generate_normal(
            obj, settings.gripper, n, seed, config, settings.grasp, device=device
        )
    scene = scene if scene is not None else scene_of(obj, settings)
    if source == ANTIPODAL:
        return generate_antipodal(scene, n, seed, antipodal, config.safety_zone_mm)
    return file_grasps(scene, source, depth_mm, config.safety_zone_mm)


def file_grasps(
    scene: Scene,
    path: str | os.PathLike,
    depth_mm: float | None = None,
    safety_zone_mm: float = 5.0,
) -> GraspBatch:
    """The feasible grasps of a grasp file (any format ``outputs.exchange`` reads) on the
    scene's part: each file pose is the gripper's base in the mesh file's frame (m);
    its grasp centre lies depth along the approach (the file's own ``depth_m`` where it
    has one, else depth_mm); the mesh's import maps them into the object frame
    (``ObjectModel.mesh_to_object_m``). The infeasible are left out, counted by reason
    (``GraspBatch.rejected``) and warned of; none feasible is an error."""
    labels, centres = file_centres(scene.object, path, depth_mm, scene.gripper.tcp_offset_mm)
    n = len(centres)
    if n == 0:
        raise ConfigError(f"grasps file {str(path)!r} holds no grasps")
    ids = labels.pick_id if labels.pick_id is not None else np.arange(n)
    batch = GraspChecker(scene, safety_zone_mm).batch(ids, centres, mode="file")
    if len(batch) == 0:
        raise ConfigError(
            f"none of the {n} grasps of {path} is feasible for {scene.gripper.name} on "
            f"{scene.object.name!r}: {rejected_words(batch.rejected)}"
        )
    if len(batch) < n:
        warnings.warn(
            f"{n - len(batch)} of the {n} grasps of {path} are infeasible and left out "
            f"({rejected_words(batch.rejected)})",
            stacklevel=2,
        )
    return batch


def file_centres(
    obj: ObjectModel,
    path: str | os.PathLike,
    depth_mm: float | None,
    tcp_offset_mm: float = 0.0,
    where: str | None = None,
    labels=None,
):
    """(the file's GraspLabels, their grasp frames (N, 4, 4) in obj's object frame):
    a grasp file read (``outputs.exchange``; labels: the file as read already), each
    pose's grasp centre found (:func:`grasp_centres`) and mapped by the mesh's import
    (:func:`to_object_frame`). where: the file as errors name it (default: "grasps file
    PATH")."""
    where = where or f"grasps file {path}"
    labels = labels if labels is not None else read_labels(path)
    centres = grasp_centres(labels.transforms, labels.depth_m, depth_mm, where, tcp_offset_mm)
    return labels, to_object_frame(obj, centres, where)


def grasp_centres(
    transforms, depth_m, depth_mm: float | None, where: str, tcp_offset_mm: float = 0.0
) -> np.ndarray:
    """(N, 4, 4) grasp frames, origin at the pads' centre: the base poses transforms
    moved along their z (the approach) by depth to the tool centre point, less the
    gripper's tcp_offset_mm (``GripperSpec``). depth_m: (N,) each grasp's own, m (None
    or NaN: none given); depth_mm: the user's, for every grasp (wins). A grasp without
    either is an error."""
    t = np.asarray(transforms, float)
    n = len(t)
    if depth_mm is not None:
        depth = np.full(n, float(depth_mm) * 1e-3)
    else:
        depth = np.full(n, np.nan) if depth_m is None else np.asarray(depth_m, float)
        if np.isnan(depth).any():
            raise ConfigError(
                f"{where}: {int(np.isnan(depth).sum())} of {n} grasps do not say how far the "
                "grasp centre lies from the gripper's base along the approach: give it "
                "(--depth-mm, depth_mm; 0 where the poses are the grasp centres)"
            )
    out = t.copy()
    out[:, :3, 3] += (depth - float(tcp_offset_mm) * 1e-3)[:, None] * t[:, :3, 2]
    return out


def to_object_frame(obj: ObjectModel, centres: np.ndarray, where: str) -> np.ndarray:
    """Grasp frames (N, 4, 4) in the mesh file's frame (m) -> the object frame; refused
    when they lie far from the part (a unit or frame that disagrees with the mesh's)."""
    m = getattr(obj, "mesh_to_object_m", None)
    out = centres if m is None else np.asarray(m, float) @ centres
    lo, hi = obj.mesh.bounds
    outside = np.maximum(np.maximum(lo - out[:, :3, 3], out[:, :3, 3] - hi), 0.0)
    far = np.linalg.norm(outside, axis=1)
    if np.any(far > FAR_FROM_PART_M):
        i = int(np.argmax(far))
        raise ConfigError(
            f"{where}: {int((far > FAR_FROM_PART_M).sum())} of {len(out)} grasp centres lie "
            f"more than {FAR_FROM_PART_M * 1e3:.0f} mm from the part (the farthest, grasp "
            f"{i}, {far[i]:.3g} m): the grasps' unit or frame disagrees with the mesh's "
            "(check the mesh's --unit, and that the poses are in the mesh's own frame, m)"
        )
    return out
