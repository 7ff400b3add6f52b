"""Pick-points as gripper poses for a robot, optionally in a frame of the user's."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from mjx_pick.core.config import ConfigError

__all__ = ["frame_matrix", "robot_picks"]


def _rot_z(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def frame_matrix(frame) -> np.ndarray:
    """4x4 transform (mm) from (x_mm, y_mm, z_mm, roll_deg, pitch_deg, yaw_deg)."""
    from scipy.spatial.transform import Rotation

    values = [float(v) for v in frame]
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise ConfigError(
            f"frame = {frame!r} must be 6 finite numbers: x_mm, y_mm, z_mm, roll_deg, "
            "pitch_deg, yaw_deg (the object frame's pose in your frame)"
        )
    t = np.eye(4)
    t[:3, :3] = Rotation.from_euler("xyz", values[3:], degrees=True).as_matrix()
    t[:3, 3] = values[:3]
    return t


def in_doubt_reasons(row: dict) -> list[str]:
    """Why a results row's label is in doubt: "by a hair" (|label_margin| < the
    summary's band), "a small move changes it" (label_stable false: evaluate's
    --stability-um), "half the step changes it" (label_converged false: --step-check);
    [] when none applies or was checked."""
    from mjx_pick.core.metrics import MARGINAL_BAND

    margin = row.get("label_margin")
    reasons = []
    if margin is not None and np.isfinite(margin) and abs(margin) < MARGINAL_BAND:
        reasons.append("by a hair")
    if row.get("label_stable") is False:
        reasons.append("a small move changes it")
    if row.get("label_converged") is False:
        reasons.append("half the step changes it")
    return reasons


def robot_picks(
    table: pa.Table,
    pick_height_mm: float,
    k: int = 10,
    frame=None,
    robust: pa.Table | None = None,
    pad_height_mm: float = 0.0,
) -> list[dict]:
    """The top-k pick-points (by robust probability when given, else by score among
    successes, those whose label is in doubt last) as gripper poses.

    A success's label is in doubt when it was decided within ``metrics.MARGINAL_BAND``
    of a threshold (``label_margin``), or when a check the run made changed it (the
    table's ``label_stable``, ``label_converged``): a robot should try it after the
    successes that are clear. Each entry says which (``label_in_doubt``).

    A pick-point is the object's pose in the gripper frame; the robot needs the
    gripper's pose in the object frame (origin at the centre of mass, on the table; z
    up) -- its inverse, at the pick height -- or, with frame (the object frame's pose in
    the user's frame, see frame_matrix), in the user's frame. The gripper frame is this
    project's: x the closing axis, z up (the gripper approaches along -z). Its height is
    the fingertips' pick height plus the pick's height compensation (a linkage's pads
    descend as they close; the table's ``height_compensation_mm``, 0 for a parallel jaw).
    A grasp given as a pose keeps its tilt (``_gripper_pose``; pad_height_mm: the pads'
    height, from their centre to the fingertips twice).
    """
    from scipy.spatial.transform import Rotation

    rows = table.to_pylist()
    by_id = {r["pick_id"]: r for r in rows}
    doubt = {r["pick_id"]: in_doubt_reasons(r) for r in rows}
    order, prob = _pick_order(table, rows, by_id, doubt, robust)
    user = frame_matrix(frame) if frame is not None else None
    out = []
    for pid in order[:k]:
        r = by_id[pid]
        # a linkage starts raised so its pads meet the part at the grasp height
        raise_mm = float(r.get("height_compensation_mm") or 0.0)
        t = _gripper_pose(r, pick_height_mm + raise_mm, user, pad_height_mm)
        q = Rotation.from_matrix(t[:3, :3]).as_quat()  # x, y, z, w
        entry = {
            "pick_id": int(pid),
            "object_in_gripper": {"x_mm": r["x_mm"], "y_mm": r["y_mm"], "yaw_deg": r["yaw_deg"]},
            "gripper_pose": {
                "frame": "user" if user is not None else "object",
                "position_mm": [round(float(v), 4) for v in t[:3, 3]],
                "quaternion_wxyz": [round(float(v), 6) for v in (q[3], q[0], q[1], q[2])],
                "matrix": [[round(float(v), 6) for v in row] for row in t],
            },
            "opening_mm": r["opening_mm"],
            "height_compensation_mm": raise_mm,
            "score": r["score"],
            "success": r["success"],
            "label_margin": r.get("label_margin"),
            "label_in_doubt": doubt[pid],
            "success_probability": prob[pid]["robust_p"] if pid in prob else None,
            "success_probability_ci": [prob[pid]["robust_ci_low"], prob[pid]["robust_ci_high"]]
            if pid in prob
            else None,
        }
        out.append(entry)
    return out


def _pick_order(table: pa.Table, rows: list[dict], by_id: dict, doubt: dict, robust):
    """(pick_ids best first, {pick_id: robust row}): robust's order and rows where given
    (pick-points of table only), else table's successes by score, clear ones first, then
    those whose label is in doubt (doubt: {pick_id: reasons}), and no robust rows."""
    if robust is not None:
        order = [r["pick_id"] for r in robust.to_pylist() if r["pick_id"] in by_id]
        prob = {r["pick_id"]: r for r in robust.to_pylist()}
        return order, prob
    from mjx_pick.core.metrics import best_successes

    success = np.asarray(table["success"])
    best = [rows[i]["pick_id"] for i in best_successes(success, table["score"], len(success))]
    order = [pid for pid in best if not doubt[pid]]
    order += [pid for pid in best if doubt[pid]]  # each part by score
    return order, {}


def _gripper_pose(
    r: dict, height_mm: float, user: np.ndarray | None, pad_height_mm: float = 0.0
) -> np.ndarray:
    """4x4 transform (mm) of the gripper in the object frame for results row r (the
    object's x_mm, y_mm, yaw_deg in the gripper frame), at height_mm above the table;
    in the user's frame when user (4x4, the object frame's pose there) is given. A grasp
    given as a pose (r's ``grasp_pose``, its frame at the pads' centre) keeps its tilt:
    the frame's origin at its fingertips (pad_height_mm / 2 along the approach), raised
    along the gripper's z by the row's height compensation, as a pick-point's is."""
    if r.get("grasp_pose") is not None:
        centre = np.asarray(r["grasp_pose"], float).reshape(4, 4)
        rot = centre[:3, :3] @ np.diag([1.0, -1.0, -1.0])  # E -> this project's frame
        raise_mm = float(r.get("height_compensation_mm") or 0.0)
        pos = 1e3 * centre[:3, 3] + rot @ np.array([0.0, 0.0, raise_mm - 0.5 * pad_height_mm])
    else:
        rot = _rot_z(-r["yaw_deg"])  # gripper axes in the object frame
        pos = -rot @ np.array([r["x_mm"], r["y_mm"], 0.0]) + np.array([0, 0, height_mm])
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = rot, pos
    if user is not None:
        t = user @ t
    return t
