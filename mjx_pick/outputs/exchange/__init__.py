"""A run's labels in the field's grasp formats: ACRONYM HDF5, GraspGen JSON, isaac_grasp YAML.

Each pick-point becomes the gripper's pose in the object's frame (``poses``: the axes
and the base the formats use), with its success and score; the object's mesh as
simulated is written beside the file, which names it (scale 1: metres). docs/formats.md
gives the frames and every field.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import TYPE_CHECKING

from mjx_pick.core.config import ConfigError, check_range, write_atomic

if TYPE_CHECKING:
    from mjx_pick.outputs.exchange.poses import GraspLabels

__all__ = ["FORMATS", "SUFFIXES", "export_labels", "object_mesh_path", "read_labels"]

# format name -> its module (SUFFIX, write, read); imported on use, so that the CLI's
# parser lists the names without loading MuJoCo, h5py or YAML
FORMATS = {
    "acronym": "acronym",
    "graspgen": "graspgen",
    "isaac-grasp": "isaac_grasp",
    "csv": "csv_poses",
}
# format name -> the suffix of its files (each module's SUFFIX): known without importing it
SUFFIXES = {"acronym": ".h5", "graspgen": ".json", "isaac-grasp": ".yaml", "csv": ".csv"}
FRAME = (
    "approach along +z, fingers close along x, origin at the gripper's base, the grasp "
    "centre depth_m along +z from it"
)


def _format(name: str):
    if name not in FORMATS:
        raise ConfigError(
            f"format = {name!r} is not a grasp format: choose one of {', '.join(FORMATS)}"
        )
    return importlib.import_module(f"mjx_pick.outputs.exchange.{FORMATS[name]}")


def object_mesh_path(labels_path: str | os.PathLike) -> Path:
    """Where the part's mesh goes beside a grasp file: ``<stem>_object.obj``."""
    path = Path(labels_path)
    return path.with_name(f"{path.stem}_object.obj")


def default_path(run_dir: str | os.PathLike, fmt: str) -> Path:
    """Where ``export_labels`` writes a format by default: grasps_<format>.<suffix> in the
    run folder."""
    if fmt not in SUFFIXES:
        _format(fmt)  # the error naming the formats
    return Path(run_dir) / f"grasps_{fmt.replace('-', '_')}{SUFFIXES[fmt]}"


def export_labels(
    run_dir: str | os.PathLike,
    fmt: str,
    out: str | os.PathLike | None = None,
    *,
    depth_mm: float | None = None,
    overwrite: bool = False,
) -> dict[str, Path]:
    """Write an evaluate run's pick-points in a grasp format, and the object's mesh.

    Args:
      run_dir: an evaluate output folder.
      fmt: "acronym" (HDF5), "graspgen" (JSON) or "isaac-grasp" (YAML).
      out: the file to write; default ``default_path(run_dir, fmt)``. The object's mesh
        goes beside it as ``<out's stem>_object.obj`` (m).
      depth_mm: the gripper base's distance behind the grasp centre along the approach
        (GraspGen's ``depth`` of the gripper the labels are for); None: the simulated
        gripper's own (``poses``).
      overwrite: replace an existing file (otherwise refused).

    Returns:
      {"labels": the file, "mesh": the object's mesh}.
    """
    from mjx_pick.outputs.exchange.poses import object_mesh, pick_poses
    from mjx_pick.outputs.reporting.run import Run
    from mjx_pick.outputs.rundir import read_manifest

    module = _format(fmt)
    if (read_manifest(run_dir) or {}).get("command") == "evaluate-set":
        return _export_set(run_dir, fmt, out, depth_mm, overwrite)
    if depth_mm is not None:
        check_range("export", "depth_mm", depth_mm, 0, 2000)
    path = Path(out) if out is not None else default_path(run_dir, fmt)
    if path.suffix.lower() != module.SUFFIX:
        raise ConfigError(f"out = {str(path)!r}: a file of format {fmt} ends in {module.SUFFIX}")
    mesh_path = object_mesh_path(path)
    run = Run.load(run_dir)
    for p in (path, mesh_path):
        if p.exists() and not overwrite:
            raise ConfigError(f"{p} exists: choose another --out, or --overwrite to replace it")
    transforms, depth = pick_poses(run, depth_mm)
    labels = _grasp_labels(run, transforms, depth, mesh_path.name)
    extra = _run_fields(run)
    write_atomic(mesh_path, object_mesh(run).export(file_type="obj"))
    write_atomic(path, module.write(labels, extra))
    return {"labels": path, "mesh": mesh_path}


def _export_set(run_dir, fmt: str, out, depth_mm, overwrite: bool) -> dict[str, Path]:
    """A set of parts' labels: each part's file in its own run folder (objects/<part>/),
    beside its mesh. {"<part>": the file, "<part>_mesh": its mesh}."""
    if out is not None:
        raise ConfigError(
            f"{run_dir} holds a set of parts: each part's labels go into its own folder "
            "(objects/<part>/); leave out --out"
        )
    written = {}
    folder = Path(run_dir) / "objects"
    for part in sorted(p for p in folder.iterdir() if p.is_dir()):
        files = export_labels(part, fmt, depth_mm=depth_mm, overwrite=overwrite)
        written[part.name], written[f"{part.name}_mesh"] = files["labels"], files["mesh"]
    return written


def _grasp_labels(run, transforms, depth_m, mesh_name: str) -> GraspLabels:
    """The run's pick-points as GraspLabels: transforms (N, 4, 4) and depth_m (N,), m,
    from ``poses.pick_poses``; mesh_name, the object's mesh file beside the labels."""
    from mjx_pick.outputs.exchange.poses import GraspLabels

    table = run.table
    return GraspLabels(
        transforms=transforms,
        success=table["success"].to_numpy(zero_copy_only=False).astype(bool),
        score=table["score"].to_numpy(zero_copy_only=False).astype(float),
        object_file=mesh_name,
        object_scale=1.0,
        depth_m=depth_m,
        pick_id=table["pick_id"].to_numpy(),
    )


def _run_fields(run) -> dict:
    """What a format's file records besides the labels: the gripper, the object (its
    mass, kg), the frames, the run folder and each pick-point's failure reason."""
    table = run.table
    obj = run.config.get("object") or {}
    return {
        "gripper": run.gripper.name,
        "object": obj.get("name", ""),
        "object_frame": "origin at the centre of mass on the table, z up",
        "frame": FRAME,
        "run": str(run.path.resolve()),
        "mass_kg": None if obj.get("mass_g") is None else float(obj["mass_g"]) * 1e-3,
        "failure": table["failure"].to_pylist()
        if "failure" in table.column_names
        else [""] * table.num_rows,
    }


def read_labels(path: str | os.PathLike, fmt: str | None = None) -> GraspLabels:
    """A grasp file read by its format's published fields (fmt: by the file's suffix
    when None)."""
    path = Path(path)
    if fmt is None:
        by_suffix = {suffix: name for name, suffix in SUFFIXES.items()}
        if path.suffix.lower() not in by_suffix:
            raise ConfigError(
                f"{path}: say its format ({', '.join(FORMATS)}); its suffix names none"
            )
        fmt = by_suffix[path.suffix.lower()]
    module = _format(fmt)
    if not path.is_file():
        raise ConfigError(f"{path} does not exist")
    return module.read(path)
