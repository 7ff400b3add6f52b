"""A finished evaluate folder, loaded once for every part of a report."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import shapely
import shapely.affinity
import shapely.errors

from mjx_pick.core.config import ConfigError, from_mapping
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.kernels import types as kt

__all__ = ["Run"]


# what every report reads of an evaluate results table
RESULT_COLUMNS = ("pick_id", "x_mm", "y_mm", "yaw_deg", "opening_mm", "success", "score", "failure")


@dataclasses.dataclass
class Run:
    """An evaluate output folder, read back."""

    path: Path
    table: pa.Table
    traces: pa.Table | None
    config: dict
    summary: dict
    outline: shapely.Polygon  # object silhouette, mm, object frame
    gripper: GripperSpec

    @classmethod
    def load(cls, run_dir: str | os.PathLike) -> Run:
        path = Path(run_dir)
        need = ("results.parquet", "config.json", "summary.json")
        missing = [n for n in need if not (path / n).is_file()]
        if missing:
            raise ConfigError(
                f"{path} is not an evaluate output folder: missing {', '.join(missing)}"
            )
        config = read_json(path / "config.json")
        wkt = config.get("object", {}).get("outline_wkt") if isinstance(config, dict) else None
        if not wkt or "gripper" not in config:
            raise ConfigError(
                f"{path}/config.json has no object outline or gripper (made by an old version, "
                "or damaged)"
            )
        traces = (
            read_parquet(path / "traces.parquet") if (path / "traces.parquet").is_file() else None
        )
        try:
            outline = shapely.from_wkt(wkt)
        except shapely.errors.ShapelyError as err:
            raise ConfigError(f"{path}/config.json: the object outline is damaged: {err}") from err
        summary = read_json(path / "summary.json")
        if not isinstance(summary, dict):
            raise ConfigError(f"{path}/summary.json is not a summary (damaged)")
        table = read_parquet(path / "results.parquet")
        absent = [c for c in RESULT_COLUMNS if c not in table.column_names]
        if absent:
            raise ConfigError(
                f"{path}/results.parquet has no {', '.join(absent)} column(s): it is not an "
                "evaluate results table (damaged, or written by another program)"
            )
        if table.num_rows == 0:
            raise ConfigError(f"{path}/results.parquet has no pick-points: nothing to report")
        return cls(
            path=path,
            table=_success_labelled(table),
            traces=traces,
            config=config,
            summary=_success_counted(summary),
            outline=outline,
            gripper=from_mapping(GripperSpec, config["gripper"]),
        )

    def trace(self, pick_id: int) -> dict[str, np.ndarray]:
        """One pick-point's trace: TRACE_FIELDS columns (T,), phase as names; for a grasp
        given as a pose, ``gripper_tilt_wxyz`` (4,) too (``core.grasps``)."""
        if self.traces is None:
            raise ConfigError(f"{self.path} has no traces.parquet (evaluate with n_traces > 0)")
        ids = np.asarray(self.traces["pick_id"])
        rows = self.traces.filter(pa.array(ids == pick_id))
        if rows.num_rows == 0:
            raise ConfigError(f"pick-point {pick_id} was not traced in {self.path}")
        trace = {name: np.asarray(rows[name]) for name in rows.column_names}
        if "grasp_pose" in self.table.column_names:  # a grasp given as a pose: its tilt
            from mjx_pick.core.grasps import decompose

            pose = np.asarray(self.row(pick_id)["grasp_pose"], float).reshape(1, 4, 4)
            trace["gripper_tilt_wxyz"] = decompose(pose)["tilt_quat"][0]
        return trace

    def traced(self) -> list[tuple[int, str]]:
        """(pick_id, 'best' | 'worst') of every traced pick-point, best first."""
        if self.traces is None:
            return []
        ids = np.asarray(self.traces["pick_id"])
        ranks = np.asarray(self.traces["rank"].to_pylist(), dtype=object)
        seen = {}
        for i, r in zip(ids, ranks, strict=True):
            seen.setdefault(int(i), r)
        return sorted(seen.items(), key=lambda kv: kv[1] != "best")

    def row(self, pick_id: int) -> dict:
        ids = np.asarray(self.table["pick_id"])
        k = int(np.flatnonzero(ids == pick_id)[0])
        return {name: self.table[name][k].as_py() for name in self.table.column_names}


def _success_labelled(table: pa.Table) -> pa.Table:
    """A results table whose successes read "success" (older runs wrote "none")."""
    if "failure" not in table.column_names:
        return table
    labels = np.asarray(table["failure"].to_pylist(), dtype=object)
    old = labels == kt.OLD_SUCCESS_LABEL
    if not old.any():
        return table
    labels[old] = kt.SUCCESS
    k = table.column_names.index("failure")
    return table.set_column(k, "failure", pa.array(labels.tolist(), pa.string()))


def _success_counted(summary: dict) -> dict:
    """A summary whose outcome counts name success "success" (older runs: "none")."""
    failures = summary.get("failures")
    if isinstance(failures, dict) and kt.OLD_SUCCESS_LABEL in failures:
        summary["failures"] = {
            (kt.SUCCESS if k == kt.OLD_SUCCESS_LABEL else k): v for k, v in failures.items()
        }
    return summary


def read_json(path: Path):
    """A run folder's JSON file; a damaged one is a ConfigError naming it."""
    try:
        return json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(
            f"{path} is damaged (not JSON: {err}); run the command that wrote it again"
        ) from err


def read_parquet(path: Path) -> pa.Table:
    """A run folder's Parquet table; a damaged one is a ConfigError naming it."""
    try:
        return pq.read_table(path)
    except (pa.ArrowException, OSError) as err:
        raise ConfigError(
            f"{path} is damaged (not a Parquet table: {err}); run the command that wrote it again"
        ) from err
