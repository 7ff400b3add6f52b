"""GraspGen's JSON grasp file: ``object.file``, ``object.scale``, ``grasps.transforms``
(N 4x4 matrices of the gripper's base link), ``grasps.object_in_gripper`` (N booleans)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError, read_text
from mjx_pick.outputs.exchange import SUFFIXES
from mjx_pick.outputs.exchange.poses import GraspLabels

SUFFIX = SUFFIXES["graspgen"]


def write(labels: GraspLabels, extra: dict) -> str:
    """The file's text; extra: mjx_pick's own values (an ``mjx_pick`` object that
    GraspGen's loader ignores)."""
    score = [None if not np.isfinite(s) else float(s) for s in labels.score]
    doc = {
        "object": {"file": labels.object_file, "scale": float(labels.object_scale)},
        "grasps": {
            "transforms": np.round(labels.transforms, 9).tolist(),
            "object_in_gripper": [bool(s) for s in labels.success],
        },
        "mjx_pick": {
            **{k: str(extra[k]) for k in ("gripper", "object", "frame", "run")},
            "pick_id": [int(p) for p in labels.pick_id],
            "score": score,
            "failure": list(extra["failure"]),
            "depth_m": [float(d) for d in labels.depth_m],
        },
    }
    return json.dumps(doc)


def read(path: Path) -> GraspLabels:
    """A GraspGen grasp file by its published fields (mjx_pick's extras where present)."""
    text = read_text(path, "GraspGen JSON")  # outside the try: its ConfigError is a ValueError
    try:
        doc = json.loads(text)
        obj, grasps = doc["object"], doc["grasps"]
        transforms = np.asarray(grasps["transforms"], float)
        success = np.asarray(grasps["object_in_gripper"], bool)
        file, scale = obj["file"], float(obj["scale"])
    except KeyError as err:
        raise ConfigError(
            f"{path} is not a GraspGen grasp file: it has no {err.args[0]!r} (a GraspGen file "
            "holds object.file, object.scale, grasps.transforms, grasps.object_in_gripper)"
        ) from None
    except json.JSONDecodeError as err:
        raise ConfigError(
            f"{path} is not a GraspGen grasp file: not JSON ({err.msg}, line {err.lineno})"
        ) from None
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{path} is not a GraspGen grasp file: {err}") from None
    ours = doc.get("mjx_pick") or {}
    score = ours.get("score")
    return GraspLabels(
        transforms=transforms.reshape(-1, 4, 4),
        success=success,
        score=np.array([np.nan if s is None else s for s in score], float)
        if score is not None
        else np.full(len(success), np.nan),
        object_file=file,
        object_scale=scale,
        depth_m=np.asarray(ours["depth_m"], float) if "depth_m" in ours else None,
        pick_id=np.asarray(ours["pick_id"], np.int64) if "pick_id" in ours else None,
    )
