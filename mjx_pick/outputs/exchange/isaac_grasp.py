"""Isaac's ``isaac_grasp`` YAML (format_version 1.0): per grasp ``confidence``,
``position`` and ``orientation`` {w, xyz} of the gripper frame in the object's frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from mjx_pick.core.config import ConfigError, read_text
from mjx_pick.outputs.exchange import SUFFIXES
from mjx_pick.outputs.exchange.poses import GraspLabels

SUFFIX = SUFFIXES["isaac-grasp"]


def write(labels: GraspLabels, extra: dict) -> str:
    """The file's text. confidence: the grasp's score where it succeeded, 0 where it
    failed (the format's grasps are ones to try); each grasp's ``success``, ``score``,
    ``failure`` and ``depth_m`` are mjx_pick's extras, and so are ``object_file`` and
    ``object_scale`` (the names GraspDataGen's isaac_grasp files use)."""
    quats = Rotation.from_matrix(labels.transforms[:, :3, :3]).as_quat()  # x, y, z, w
    grasps = {}
    for k, pid in enumerate(labels.pick_id):
        score = float(labels.score[k])
        ok = bool(labels.success[k])
        grasps[f"grasp_{int(pid)}"] = {
            "confidence": round(score, 6) if ok and np.isfinite(score) else 0.0,
            "position": [round(float(v), 9) for v in labels.transforms[k, :3, 3]],
            "orientation": {
                "w": round(float(quats[k, 3]), 9),
                "xyz": [round(float(v), 9) for v in quats[k, :3]],
            },
            "success": ok,
            "score": round(score, 6) if np.isfinite(score) else None,
            "failure": str(extra["failure"][k]),
            "depth_m": round(float(labels.depth_m[k]), 9),
        }
    doc = {
        "format": "isaac_grasp",
        "format_version": 1.0,
        "object_frame": f"{extra['object']}: {extra['object_frame']}",
        "gripper_frame": f"{extra['gripper']} base: {extra['frame']}",
        "object_file": labels.object_file,
        "object_scale": float(labels.object_scale),
        "mjx_pick_run": str(extra["run"]),
        "grasps": grasps,
    }
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)


def read(path: Path) -> GraspLabels:
    """An isaac_grasp file by its published fields: success where mjx_pick's extra says
    so, else confidence > 0."""
    try:
        doc = yaml.safe_load(read_text(path, "isaac_grasp YAML"))
    except yaml.YAMLError as err:
        raise ConfigError(f"{path} is not a YAML file: {err}") from err
    if not isinstance(doc, dict) or doc.get("format") != "isaac_grasp" or "grasps" not in doc:
        raise ConfigError(f"{path} is not an isaac_grasp file (format: isaac_grasp, grasps)")
    names = list(doc["grasps"])
    try:
        rows = [doc["grasps"][n] for n in names]
        pos = np.array([r["position"] for r in rows], float).reshape(-1, 3)
        wxyz = np.array([[r["orientation"]["w"], *r["orientation"]["xyz"]] for r in rows])
        conf = np.array([float(r["confidence"]) for r in rows])
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(f"{path}: a grasp lacks position, orientation or confidence") from err
    transforms = np.tile(np.eye(4), (len(rows), 1, 1))
    if rows:
        transforms[:, :3, :3] = Rotation.from_quat(np.roll(wxyz, -1, axis=1)).as_matrix()
    transforms[:, :3, 3] = pos
    success = np.array([r.get("success", c > 0) for r, c in zip(rows, conf, strict=True)], bool)
    score = np.array([np.nan if r.get("score") is None else r["score"] for r in rows], float)
    ids = [n.removeprefix("grasp_") for n in names]
    return GraspLabels(
        transforms=transforms,
        success=success,
        score=score,
        object_file=str(doc.get("object_file", "")),
        object_scale=float(doc.get("object_scale", 1.0)),
        depth_m=np.array([r.get("depth_m", np.nan) for r in rows], float),
        pick_id=np.array(ids, np.int64) if all(i.isdigit() for i in ids) else None,
    )
