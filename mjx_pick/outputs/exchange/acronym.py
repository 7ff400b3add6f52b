"""ACRONYM's HDF5 grasp file: ``grasps/transforms`` (N, 4, 4), ``grasps/qualities/flex/
object_in_gripper`` (N,), ``object/file``, ``object/scale`` (acronym_tools' field list)."""

from __future__ import annotations

import io
from pathlib import Path

import h5py
import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.outputs.exchange import SUFFIXES
from mjx_pick.outputs.exchange.poses import GraspLabels

SUFFIX = SUFFIXES["acronym"]


def write(labels: GraspLabels, extra: dict) -> bytes:
    """The file's bytes; extra: mjx_pick's own values (an ``mjx_pick`` group and
    attributes that ACRONYM's readers ignore)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f["grasps/transforms"] = np.asarray(labels.transforms, np.float64)
        # ACRONYM's labels are 0/1 numbers (its tools select success == 1)
        f["grasps/qualities/flex/object_in_gripper"] = labels.success.astype(np.int64)
        f["grasps/qualities/mjx_pick/score"] = np.asarray(labels.score, np.float64)
        f["object/file"] = labels.object_file
        f["object/scale"] = float(labels.object_scale)
        if extra.get("mass_kg") is not None:
            f["object/mass"] = float(extra["mass_kg"])
        f["mjx_pick/pick_id"] = np.asarray(labels.pick_id, np.int64)
        f["mjx_pick/depth_m"] = np.asarray(labels.depth_m, np.float64)
        f["mjx_pick/failure"] = np.asarray(extra["failure"], dtype=h5py.string_dtype())
        for key in ("gripper", "object", "frame", "run"):
            f.attrs[f"mjx_pick_{key}"] = str(extra[key])
    return buffer.getvalue()


def read(path: Path) -> GraspLabels:
    """An ACRONYM grasp file by its published fields (mjx_pick's extras where present)."""
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise ConfigError(f"{path} is not an HDF5 file: {err}") from err
    with f:
        need = ("grasps/transforms", "grasps/qualities/flex/object_in_gripper", "object/file")
        missing = [k for k in need + ("object/scale",) if k not in f]
        if missing:
            raise ConfigError(f"{path} is not an ACRONYM grasp file: no {', '.join(missing)}")
        transforms = np.asarray(f["grasps/transforms"][()], float)
        success = np.asarray(f["grasps/qualities/flex/object_in_gripper"][()]) == 1
        score_key = "grasps/qualities/mjx_pick/score"
        score = f[score_key][()] if score_key in f else np.full(len(success), np.nan)
        file = f["object/file"][()]
        return GraspLabels(
            transforms=transforms,
            success=success,
            score=np.asarray(score, float),
            object_file=file.decode("utf-8") if isinstance(file, bytes) else str(file),
            object_scale=float(f["object/scale"][()]),
            depth_m=f["mjx_pick/depth_m"][()] if "mjx_pick/depth_m" in f else None,
            pick_id=f["mjx_pick/pick_id"][()] if "mjx_pick/pick_id" in f else None,
        )
