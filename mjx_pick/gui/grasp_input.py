"""Tab 3's grasp sources as the CLI takes them (``evaluate --grasps``), and an uploaded
grasp file read before a run (no web framework)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.outputs.exchange import SUFFIXES

TOPDOWN, ANTIPODAL, FILE = "topdown", "antipodal", "file"
# what the page offers, in its words (the CLI's --grasps topdown|antipodal|FILE)
SOURCES = {
    TOPDOWN: "top-down pick-points (the paper's)",
    ANTIPODAL: "antipodal grasps on the part's surface (approaches from above)",
    FILE: "grasps from a file (ACRONYM, GraspGen, isaac_grasp, CSV of poses)",
}
# the grasp files the library reads, by suffix (``outputs.exchange``)
FILE_SUFFIXES = tuple(SUFFIXES.values())


def source_args(source: str, path: Path | None = None, depth_mm: float | None = None) -> list[str]:
    """The CLI arguments of a grasp source: none for top-down pick-points (the CLI's
    default), ``--grasps antipodal``, or ``--grasps FILE`` with ``--depth-mm`` where
    the page gives one."""
    if source == TOPDOWN:
        return []
    if source == ANTIPODAL:
        return ["--grasps", ANTIPODAL]
    argv = ["--grasps", str(path)]
    return argv + ([] if depth_mm is None else ["--depth-mm", repr(float(depth_mm))])


def recorded_source(argv: list[str]) -> tuple[str, str | None, float | None]:
    """(source, file, depth_mm) of a run's CLI arguments (its log's first line)."""
    from mjx_pick.gui.jobs import flag_value

    given = flag_value(argv, "--grasps")
    depth = flag_value(argv, "--depth-mm")
    depth_mm = float(depth) if depth is not None else None
    if given in (None, TOPDOWN):
        return TOPDOWN, None, None
    if given == ANTIPODAL:
        return ANTIPODAL, None, None
    return FILE, given, depth_mm


def read_grasp_file(path: Path, name: str):
    """(the file's GraspLabels, its grasps, how many of them do not say their depth) of
    a grasp file, read as the run will read it (``outputs.exchange.read_labels``);
    ConfigError naming the file by name (the uploaded file's, not where the page
    stored it)."""
    from mjx_pick.outputs.exchange import read_labels

    try:
        labels = read_labels(path)
    except ConfigError as err:
        raise ConfigError(str(err).replace(str(path), name)) from None
    n = len(labels.transforms)
    if n == 0:
        raise ConfigError(f"{name} holds no grasps")
    depth = labels.depth_m
    missing = n if depth is None else int(np.isnan(np.asarray(depth, float)).sum())
    return labels, n, missing


def check_grasp_file(
    obj, gripper, path: Path, name: str, depth_mm: float | None
) -> tuple[int, int]:
    """The grasps of a grasp file for a run on obj with gripper, read once and checked
    before any work as the run will take them: (how many, how many do not say their
    depth -- with none given for them, nothing more is checked). Once every depth is
    known (its own, or depth_mm for all), the grasp centres must lie near the part (a
    file in another unit or frame is refused, ``grasp_sources.to_object_frame``).
    ConfigError naming the file by name. Which grasps are feasible the run says (it
    needs the scene)."""
    from mjx_pick.studies.grasp_sources import check_source, file_centres

    labels, n, missing = read_grasp_file(path, name)
    if missing and depth_mm is None:
        return n, missing
    try:
        check_source(str(path), depth_mm)
        file_centres(obj, path, depth_mm, gripper.tcp_offset_mm, name, labels)
    except ConfigError as err:
        raise ConfigError(str(err).replace(str(path), name)) from None
    return n, 0
