"""Tab 4's 3-D replay data: a run's body shapes and a trace's body poses, packed for the
browser (``page/replay3d.js`` poses them in NiceGUI's three.js scene)."""

from __future__ import annotations

import base64
import os
from pathlib import Path

import numpy as np

from mjx_pick.core.gripper import GripperSpec
from mjx_pick.outputs.plots import FAILURE_COLOUR
from mjx_pick.outputs.reporting.body_poses import BodyShape, body_track, scene_shapes

# the body drawn in FAILURE_COLOUR when a pick-point failed
OUTCOME_BODY = "object"


def packed(values: np.ndarray, dtype) -> str:
    """An array's bytes as base64 text (little-endian, C order), as the browser reads it
    into a typed array."""
    return base64.b64encode(
        np.ascontiguousarray(values, np.dtype(dtype).newbyteorder("<"))
    ).decode()


def hex_colour(rgba) -> str:
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgba[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


class SceneReplay:
    """A run's scene for replays: its compiled model and shown bodies, loaded once per
    scene.xml, and the poses of any trace of it.

    Args:
      scene_xml: the run's ``scene.xml`` (the simulated model).
      gripper: the run's gripper (an MJCF gripper's linkage is posed from the traced
        pad travel).
    """

    def __init__(self, scene_xml: str | os.PathLike, gripper: GripperSpec | None):
        import mujoco

        self.scene_xml = Path(scene_xml)
        self.gripper = gripper
        self.stamp = _stamp(self.scene_xml)
        self.model = mujoco.MjModel.from_xml_path(str(self.scene_xml))
        self.shapes: list[BodyShape] = scene_shapes(self.model)

    def is_for(self, scene_xml: str | os.PathLike, gripper: GripperSpec | None) -> bool:
        """Whether this is the scene of scene_xml as it is on disk now, with gripper (a
        run folder written again is another scene)."""
        path = Path(scene_xml)
        return path == self.scene_xml and gripper == self.gripper and _stamp(path) == self.stamp

    def shapes_payload(self) -> dict:
        """{"bodies": [{"name", "geoms": [{"name", "vertices", "faces", "color",
        "opacity"}]}]}: vertices float32 (V, 3) m and faces uint32 (F, 3), base64, in the
        body's frame; the world body (the table) first."""
        return {
            "bodies": [
                {
                    "name": body.name,
                    "geoms": [
                        {
                            "name": g.name,
                            "vertices": packed(g.vertices, np.float32),
                            "faces": packed(g.faces, np.uint32),
                            "color": hex_colour(g.rgba),
                            "opacity": round(float(g.rgba[3]), 3),
                        }
                        for g in body.geoms
                    ],
                }
                for body in self.shapes
            ]
        }

    def track_payload(self, trace: dict, failed: bool) -> dict:
        """{"t": (T,) s, "position": (T, B, 3) m, "quat_wxyz": (T, B, 4), float32 base64;
        "bodies": names (B,), the order of shapes_payload; "colours": {body: colour} of
        bodies drawn apart (the object of a failed pick-point in FAILURE_COLOUR)}."""
        track = body_track(self.model, trace, self.shapes, self.gripper)  # model untouched
        return {
            "t": packed(track.t_s, np.float32),
            "position": packed(track.position_m, np.float32),
            "quat_wxyz": packed(track.quat_wxyz, np.float32),
            "bodies": list(track.bodies),
            "colours": {OUTCOME_BODY: FAILURE_COLOUR} if failed else {},
        }


def _stamp(path: Path) -> tuple[int, int] | None:
    """(modification time ns, size) of a file, None if it is gone."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size


def row_at(t_s: np.ndarray, t: float) -> int:
    """The row of a trace whose time is nearest t, s (the times ascend): the row the
    browser shows for a slider at t (which holds the times as float32)."""
    t_s = np.asarray(t_s, np.float32).astype(float)
    k = int(np.clip(np.searchsorted(t_s, t), 0, len(t_s) - 1))
    if k > 0 and t - t_s[k - 1] < t_s[k] - t:
        k -= 1
    return k
