"""Pick-point files: the CSV a user edits and hands back with ``--picks``.

``write_picks`` draws feasible pick-points and writes them with two pictures (the first
pick-point under the gripper, and candidates coloured by the check that rejected them);
``read_picks_csv`` reads such a file back (any CSV with x_mm, y_mm, yaw_deg columns).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from mjx_pick.core import numbers
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import ConfigError, open_csv, to_dict, write_atomic
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.objects import ObjectModel
from mjx_pick.outputs.rundir import claim, config_hash, finish

__all__ = ["UserPicks", "read_picks_csv", "write_picks"]

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
) -> pp.GraspBatch:
    """n feasible pick-points (``pickpoints.generate_normal``) written to out/:
    picks.csv (pick_id, x_mm, y_mm, yaw_deg, opening_mm, coverage), pick_0.png and
    candidates.png (candidates from the configured ranges, by rejection reason).

    out is owned like every command's folder (``rundir.claim``): one written by
    another command or another request is refused unless overwrite. Nothing is
    simulated. Returns the pick-points.
    """
    config = config or pp.PickConfig()
    pp.check_raster(obj, config)  # before any allocation or folder
    pp.check_stroke(obj, gripper, config)  # a part no pose fits: refused before the draws
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
    # here: its figures load matplotlib, which an evaluate that reads a picks file needs not
    from mjx_pick.outputs import plots

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


# the columns a pick-point file may have: the pose (required), the user's own pick_id,
# and what write_picks adds (recomputed by the feasibility checks, so only read over)
PICK_COLUMNS = ("x_mm", "y_mm", "yaw_deg")
OPTIONAL_COLUMNS = ("pick_id", "opening_mm", "coverage")


class UserPicks(NamedTuple):
    """Pick-points read from a CSV: each row's id (its pick_id column, else its index
    among the data rows, from 0), pose, and line number in the file (for messages)."""

    pick_id: np.ndarray
    x_mm: np.ndarray
    y_mm: np.ndarray
    yaw_deg: np.ndarray
    line: np.ndarray


def read_picks_csv(path: str | Path) -> UserPicks:
    """User pick-points: a CSV with a header row and columns x_mm, y_mm, yaw_deg, and
    optionally pick_id (whole numbers >= 0, each once; default: the row's index among
    the data rows, from 0), opening_mm and coverage (as ``write_picks`` writes them; not
    used). Results keep each row's pick_id. Another column, a repeated pick_id or a
    repeated pose is an error naming it. A UTF-8 byte-order mark (Excel) is accepted."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"picks file {str(path)!r} does not exist")
    allowed = PICK_COLUMNS + OPTIONAL_COLUMNS
    with open_csv(path, "picks") as fh:
        reader = csv.DictReader(fh)
        found = [c.strip() if isinstance(c, str) else c for c in reader.fieldnames or []]
        reader.fieldnames = found
        missing = [c for c in PICK_COLUMNS if c not in found]
        if missing:
            raise ConfigError(
                f"picks file {path.name}: missing column(s) {', '.join(missing)}; found {found}"
            )
        unknown = [c for c in found if c not in allowed]
        if unknown:
            raise ConfigError(
                f"picks file {path.name}: unknown column(s) {', '.join(map(str, unknown))}; "
                f"allowed: {', '.join(allowed)} (a setting such as grip_force_n is a "
                "flag or a settings file, not a column)"
            )
        repeated = sorted({c for c in found if found.count(c) > 1})
        if repeated:
            raise ConfigError(f"picks file {path.name}: column(s) {repeated} repeated")
        has_id = "pick_id" in found
        rows, ids, lines = [], [], []
        for k, row in enumerate(reader):
            line = reader.line_num
            if None in row:
                raise ConfigError(f"picks file {path.name}, line {line}: more cells than columns")
            # each cell by its input's rule (core.numbers): finite, within the reach of
            # any part on any gripper, a yaw within one turn either side
            where = f"picks file {path.name}, line {line}: "
            rows.append([numbers.INPUTS[c].parse(c, row[c] or "", where) for c in PICK_COLUMNS])
            ids.append(_pick_id(row["pick_id"], path, line) if has_id else k)
            lines.append(line)
    if not rows:
        raise ConfigError(f"picks file {path.name} has no rows")
    a = np.asarray(rows, float)
    lines = np.asarray(lines, np.int64)
    if not np.isfinite(a).all():
        bad = lines[int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0])]
        raise ConfigError(f"picks file {path.name}, line {bad}: values must be finite")
    ids = np.asarray(ids, np.int64)
    _refuse_repeats(path, "pick_id", ids, lines)
    # one pose, one row: a yaw and the same yaw a turn on (10 and 370 deg) are one pose
    poses = [(x, y, round(yaw % 360.0, 9) % 360.0) for x, y, yaw in a]
    _refuse_repeats(path, "pose (x_mm, y_mm, yaw_deg; a yaw and yaw + 360 are one)", poses, lines)
    return UserPicks(ids, a[:, 0], a[:, 1], a[:, 2], lines)


def _pick_id(text, path: Path, line: int) -> int:
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value == int(value) and 0 <= value < 2**62):
        raise ConfigError(
            f"picks file {path.name}, line {line}: pick_id = {text!r} must be a whole number >= 0"
        )
    return int(value)


def _refuse_repeats(path: Path, what: str, values, lines: np.ndarray) -> None:
    first: dict = {}
    repeats = []
    for v, line in zip(values, lines, strict=True):
        if v in first:
            repeats.append(f"line {line} repeats line {first[v]}")
        else:
            first[v] = int(line)
    if repeats:
        shown = "; ".join(repeats[:6]) + (" ..." if len(repeats) > 6 else "")
        raise ConfigError(
            f"picks file {path.name}: {len(repeats)} repeated {what}: {shown}; "
            "each pick-point once (a repeat would be counted twice)"
        )
