"""Pick-point files: the CSV a user edits and hands back with ``--picks``.

``write_picks`` draws feasible pick-points and writes them with two pictures (the first
pick-point under the gripper, and candidates coloured by the check that rejected them);
``read_picks_csv`` reads such a file back (any CSV with x_mm, y_mm, yaw_deg columns).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import ConfigError, to_dict, write_atomic
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.objects import ObjectModel
from mjx_pick.outputs import plots
from mjx_pick.outputs.rundir import claim, config_hash, finish

__all__ = ["read_picks_csv", "write_picks"]

# candidates drawn for the rejection picture
_N_CANDIDATES = 2000


def write_picks(
    obj: ObjectModel,
    gripper: GripperSpec,
    n: int,
    *,
    seed: int = 0,
    config: pp.PickConfig | None = None,
    out: str | Path,
    overwrite: bool = False,
) -> pp.PickBatch:
    """n feasible pick-points (``pickpoints.generate_normal``) written to out/:
    picks.csv (pick_id, x_mm, y_mm, yaw_deg, opening_mm, coverage), pick_0.png and
    candidates.png (candidates from the configured ranges, by rejection reason).

    out is owned like every command's folder (``rundir.claim``): one written by
    another command or another request is refused unless overwrite. Nothing is
    simulated. Returns the pick-points.
    """
    config = config or pp.PickConfig()
    request = {"object": obj.summary(), "gripper": to_dict(gripper), "picks": to_dict(config)}
    request.update(n=n, seed=seed)
    folder = claim(out, "picks", config_hash(request), overwrite=overwrite, settings=request)
    picks = pp.generate_normal(obj, gripper, n, seed=seed, config=config)
    lines = ["pick_id,x_mm,y_mm,yaw_deg,opening_mm,coverage"]
    lines += [
        f"{i},{x:.4f},{y:.4f},{w:.4f},{o:.4f},{c:.4f}"
        for i, x, y, w, o, c in zip(
            picks.pick_id,
            picks.x_mm,
            picks.y_mm,
            picks.yaw_deg,
            picks.opening_mm,
            picks.coverage,
            strict=True,
        )
    ]
    write_atomic(folder / "picks.csv", "\n".join(lines) + "\n")
    plots.draw_pick(
        obj,
        gripper,
        picks.x_mm[0],
        picks.y_mm[0],
        picks.yaw_deg[0],
        picks.opening_mm[0],
        folder / "pick_0.png",
    )
    rng = np.random.default_rng(seed)
    checker = pp.FeasibilityChecker(obj, gripper, config)
    cx, cy, cyaw = pp.draw_block(rng, *checker.ranges(), config, _N_CANDIDATES)
    labels = np.asarray(pp.REASONS)[checker(cx, cy, cyaw)["reason"]]
    plots.draw_candidates(obj, cx, cy, cyaw, folder / "candidates.png", labels=labels)
    finish(folder, command="picks", config=request, seed=seed)  # nothing simulated
    return picks


def read_picks_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """User pick-points: a CSV with columns x_mm, y_mm, yaw_deg (a header row)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"picks file {str(path)!r} does not exist")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        need = ("x_mm", "y_mm", "yaw_deg")
        missing = [c for c in need if c not in (reader.fieldnames or [])]
        if missing:
            raise ConfigError(
                f"picks file {path.name}: missing column(s) {', '.join(missing)}; "
                f"found {reader.fieldnames}"
            )
        rows = []
        for i, row in enumerate(reader, start=2):
            try:
                rows.append([float(row[c]) for c in need])
            except (TypeError, ValueError) as err:
                raise ConfigError(f"picks file {path.name}, row {i}: {err}") from err
    if not rows:
        raise ConfigError(f"picks file {path.name} has no rows")
    a = np.asarray(rows, float)
    if not np.isfinite(a).all():
        bad = int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0]) + 2
        raise ConfigError(f"picks file {path.name}, row {bad}: values must be finite")
    return a[:, 0], a[:, 1], a[:, 2]
