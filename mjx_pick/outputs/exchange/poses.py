"""A run's pick-points as gripper poses in the object's frame, in the exchange formats' axes.

Details: docs/outputs.md (outputs/exchange/poses.py).
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

import numpy as np
import trimesh

from mjx_pick.core.config import ConfigError
from mjx_pick.core.grasps import GraspBatch, poses
from mjx_pick.outputs.reporting.run import Run

# the results table's columns a pose needs
NEEDED = ("pick_id", "x_mm", "y_mm", "yaw_deg", "success", "score")


@dataclasses.dataclass(frozen=True, eq=False)
class GraspLabels:
    """Grasps of one object as an exchange file holds them.

    transforms: (N, 4, 4) gripper base poses in the object's frame, m, the exchange
      axes (approach +z, closing x). success: (N,) bool. score: (N,) eq. (2)'s grasp
      quality, NaN where a simulation diverged (or where the file has none). object_file:
      the object's mesh as the file names it; object_scale: the factor that takes the
      mesh's units to metres. depth_m: (N,) the grasp centre's distance from the base
      along +z. pick_id: (N,) mjx_pick's pick-point ids (None where the file has none).
    """

    transforms: np.ndarray
    success: np.ndarray
    score: np.ndarray
    object_file: str
    object_scale: float
    depth_m: np.ndarray | None = None
    pick_id: np.ndarray | None = None


def pick_poses(run: Run, depth_mm: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((N, 4, 4) poses, (N,) depths in m) of a run's pick-points; see the module
    docstring. depth_mm: the base's distance behind the grasp centre, None for the
    gripper's own."""
    table = run.table
    missing = [c for c in NEEDED if c not in table.column_names]
    if depth_mm is None and run.gripper.mjcf is not None:
        missing += [c for c in ("height_compensation_mm",) if c not in table.column_names]
    if missing:
        raise ConfigError(
            f"{run.path}/results.parquet has no column(s) {', '.join(missing)}: it is not "
            "an evaluate run's table (written by an old version, or by another command); "
            "evaluate again"
        )
    scene = run.config.get("scene") or {}
    if "fingertip_height_mm" not in scene:
        raise ConfigError(
            f"{run.path}/config.json has no scene.fingertip_height_mm (made by an old "
            "version, or damaged): evaluate again"
        )
    x, y, yaw = (np.asarray(table[c], float) for c in ("x_mm", "y_mm", "yaw_deg"))
    if "grasp_pose" in table.column_names:  # grasps given as poses: their grasp frames
        centre = np.asarray(table["grasp_pose"].to_pylist(), float).reshape(-1, 4, 4)
    else:  # pick-points: the vertical grasps at the run's grasp height
        z_tcp_mm = float(scene["fingertip_height_mm"]) + 0.5 * run.gripper.pad_height_mm
        n = len(x)
        picks = GraspBatch(
            table["pick_id"].to_numpy(), x, y, yaw, *(np.zeros(n) for _ in range(4)), {}, n
        )
        centre = poses(picks, z_tcp_mm)
    if depth_mm is not None:
        depth = np.full(len(x), float(depth_mm))
    elif run.gripper.mjcf is not None:
        from mjx_pick.core.mjcf_gripper import characterise

        mount = -1e3 * float(characterise(run.gripper.mjcf).pad_centre_z[0])
        comp = np.nan_to_num(np.asarray(table["height_compensation_mm"], float))
        depth = mount + comp
    else:
        depth = np.zeros(len(x))
    offset = float(run.gripper.tcp_offset_mm)
    if depth_mm is None:  # the file's depth reaches the gripper's tool centre point
        depth = depth + offset
    # the base lies depth behind the tool centre point, which lies tcp_offset_mm beyond
    # the grasp centre (the pads' centre) along E's z
    behind = depth - offset
    out = centre.copy()
    out[:, :3, 3] -= (behind * 1e-3)[:, None] * centre[:, :3, 2]
    return out, depth * 1e-3


def object_mesh(run: Run) -> trimesh.Trimesh:
    """The object's mesh as simulated, in its frame (m): the ``visual`` mesh of the run's
    scene.xml (a photo part's extruded silhouette, a mesh part as posed and centred)."""
    path = run.path / "scene.xml"
    if not path.is_file():
        raise ConfigError(f"{run.path} has no scene.xml (made by an old version): evaluate again")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        raise ConfigError(f"{path} is damaged (not XML: {err})") from err
    mesh = root.find("asset/mesh[@name='visual']")
    if mesh is None or not mesh.get("vertex") or not mesh.get("face"):
        raise ConfigError(f"{path} holds no object mesh named 'visual' with vertices and faces")
    vertices = np.array(mesh.get("vertex").split(), float).reshape(-1, 3)
    faces = np.array(mesh.get("face").split(), int).reshape(-1, 3)
    return trimesh.Trimesh(vertices, faces, process=False)
