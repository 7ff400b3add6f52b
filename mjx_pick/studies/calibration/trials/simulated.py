"""Trials filled with outcomes simulated under hidden parameters (tests, benchmarks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import (
    ConfigError,
)
from mjx_pick.core.objects import ObjectModel, check_same_object
from mjx_pick.engine.registry import AUTO
from mjx_pick.studies.calibration.parameters import (
    canonical_params,
)
from mjx_pick.studies.calibration.trials.runs import Simulations, plan_settings
from mjx_pick.studies.calibration.trials.sheet import (
    SHEET,
    check_rows,
    load_plan,
    read_sheet,
    write_sheet,
)


def synthetic_trials(
    folder,
    obj: ObjectModel,
    hidden: dict,
    *,
    jitter_mm: float | None = None,
    jitter_deg: float | None = None,
    seed: int = 1,
    backend: str = AUTO,
) -> int:
    """SYNTHETIC outcomes for validation: fill every untried row of the sheet as a real
    cell whose contact parameters are `hidden` ({name: value}, ``parameters.PARAMS``)
    would: each of a row's trials is the simulation at a placement jittered by
    jitter_mm / jitter_deg (default: the plan's placing error; both 0: every trial at
    the template pose). Returns the rows filled."""
    folder = Path(folder)
    plan = load_plan(folder)
    check_same_object(plan["object"], obj, f"trials folder {folder}")
    hidden = {canonical_params([k])[0]: float(v) for k, v in hidden.items()}
    settings, pick_config = plan_settings(plan, folder)
    header, rows = read_sheet(folder)
    entries = check_rows(folder, plan, rows)
    todo = [i for i, r in enumerate(rows) if r["successes"] == ""]
    if not todo:
        return 0
    from mjx_pick.studies.robust import placements as place

    sims = Simulations(obj, settings, backend)
    picks = pp.FeasibilityChecker(obj, settings.gripper, pick_config, settings.grasp).batch(
        [entries[i]["pick_id"] for i in todo],
        [entries[i]["x_mm"] for i in todo],
        [entries[i]["y_mm"] for i in todo],
        [entries[i]["yaw_deg"] for i in todo],
        "trials",
    )
    if len(picks) != len(todo):
        raise ConfigError("a planned pick-point is no longer feasible with the plan's settings")
    m = max(int(float(rows[i]["trials"])) for i in todo)
    sx = plan["jitter_mm"] if jitter_mm is None else jitter_mm
    sy = plan["jitter_deg"] if jitter_deg is None else jitter_deg
    placed = place(obj, picks, settings, m, sx, sy, seed, pick_config)
    success = np.zeros(len(todo) * m, bool)
    if len(placed.draws):
        success[placed.ok] = sims.run(placed.draws, [hidden])["success"][0]
    success = success.reshape(len(todo), m)
    for j, i in enumerate(todo):
        t = int(float(rows[i]["trials"]))
        rows[i]["successes"] = str(int(success[j, :t].sum()))
    write_sheet(folder / SHEET, header, rows)
    return len(todo)
