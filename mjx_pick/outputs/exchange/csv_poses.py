"""A CSV of grasp poses: ``grasp_pose`` (16 numbers, row-major, m: the gripper base in the
object's frame, the exchange axes), optional ``depth_mm``, ``pick_id``, ``success``, ``score``."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError, read_text
from mjx_pick.core.grasps import pose_numbers, rigid_poses
from mjx_pick.outputs.exchange import SUFFIXES
from mjx_pick.outputs.exchange.poses import GraspLabels

SUFFIX = SUFFIXES["csv"]
COLUMNS = ("pick_id", "grasp_pose", "depth_mm", "success", "score", "failure")


def write(labels: GraspLabels, extra: dict) -> str:
    """The file's text: a row per grasp, the pose's 16 numbers separated by spaces."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(COLUMNS)
    for k in range(len(labels.transforms)):
        score = float(labels.score[k])
        w.writerow(
            [
                int(labels.pick_id[k]),
                " ".join(f"{v:.9g}" for v in labels.transforms[k].ravel()),
                f"{1e3 * float(labels.depth_m[k]):.6f}",
                int(bool(labels.success[k])),
                f"{score:.6f}" if np.isfinite(score) else "",
                str(extra["failure"][k]),
            ]
        )
    return out.getvalue()


def read(path: Path) -> GraspLabels:
    """A CSV of grasp poses; every error names the row and the column."""
    text = read_text(path, "grasp poses CSV")
    rows = list(csv.DictReader(io.StringIO(text)))
    if not rows:
        raise ConfigError(f"{path} holds no grasp rows (a header and one row per grasp)")
    if "grasp_pose" not in rows[0]:
        raise ConfigError(
            f"{path} has no column grasp_pose (its columns: {', '.join(rows[0])}): give each "
            "grasp's 4x4 pose as 16 numbers separated by spaces, row-major, in metres"
        )
    values = []
    for line, row in enumerate(rows, start=2):
        values.append(pose_numbers(row.get("grasp_pose"), f"{path} line {line}, column grasp_pose"))
    lines = [f"line {i}" for i in range(2, len(rows) + 2)]
    transforms = rigid_poses(values, f"{path}, column grasp_pose", lines)

    def column(name, parse, default):
        out = []
        for line, row in enumerate(rows, start=2):
            cell = (row.get(name) or "").strip()
            if not cell:
                out.append(default)
                continue
            try:
                out.append(parse(cell))
            except ValueError:
                raise ConfigError(
                    f"{path} line {line}, column {name}: {cell!r} is not a number"
                ) from None
        return out

    depth = column("depth_mm", float, np.nan) if "depth_mm" in rows[0] else None
    ids = column("pick_id", int, None) if "pick_id" in rows[0] else None
    if ids is not None and None in ids:
        ids = None
    return GraspLabels(
        transforms=transforms,
        success=np.array(column("success", lambda c: float(c) != 0, False), bool),
        score=np.array(column("score", float, np.nan), float),
        object_file="",
        object_scale=1.0,
        depth_m=None if depth is None else np.asarray(depth, float) * 1e-3,
        pick_id=None if ids is None else np.asarray(ids, np.int64),
    )
