"""Round 1 of a trials folder: candidates from the run, their information, the sheet."""

from __future__ import annotations

from mjx_pick.core.config import (
    check_range,
    to_dict,
    write_json,
    write_parquet,
)
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.settings import Settings
from mjx_pick.engine.registry import AUTO
from mjx_pick.outputs.rundir import claim, config_hash, finish
from mjx_pick.studies.calibration.parameters import (
    ParamSpace,
    canonical_params,
    param_space,
    start_values,
)
from mjx_pick.studies.calibration.trials.choosing import new_round
from mjx_pick.studies.calibration.trials.runs import (
    Simulations,
    parameter_draws,
    read_run,
)
from mjx_pick.studies.calibration.trials.sheet import (
    CANDIDATES,
    COMMAND,
    PLAN,
    SHEET,
    SHEET_COLUMNS,
    SIM_COLUMNS,
    TemplateWriter,
    sheet_row,
    write_sheet,
)


def plan_trials(
    run_dir,
    obj: ObjectModel,
    out,
    *,
    n: int = 12,
    repeats: int = 5,
    params="pad_friction",
    draws: int = 6,
    placements: int = 3,
    jitter_mm: float = 1.0,
    jitter_deg: float = 2.0,
    pool: int = 32,
    info_share: float = 0.5,
    seed: int = 0,
    blind: bool = False,
    bounds: dict | None = None,
    priors: dict | None = None,
    backend: str = AUTO,
    batch_size: int | None = None,
    overwrite: bool = False,
    write_templates: TemplateWriter | None = None,
) -> dict:
    """Plan round 1 of trials of the pick-points of an evaluate run.

    Args:
      run_dir: a finished evaluate folder of obj (its settings are used throughout).
      out: the trials folder (claimed for the ``trials`` command).
      n: pick-points to try; repeats: trials per pick-point (the paper: 5).
      params: the contact parameters whose uncertainty decides what is informative
        (``parameters.PARAMS``; aliases allowed); draws: parameter draws S from their
        prior; placements: R placements per draw, jittered by jitter_mm (x, y) and
        jitter_deg (yaw) -- the error of placing the object on the template.
      pool: candidates simulated (stratified over the run's successes and failures);
        info_share: the share of n chosen by information (the rest: best / worst).
      blind: leave the simulation's predictions out of trials.csv (the person at the
        robot does not see them; they stay in trials.json).
      bounds, priors: {name: (lo, hi)} and {name: (mean, sd)} as ``calibrate`` takes
        them: the draws come from the prior (default: weak, half the bounds), and the
        fit uses both. A prior that says what is already known about a parameter makes
        the plan spend its trials where the remaining doubt lies.
      write_templates: called as write_templates(out, plan, round) before the folder
        is marked complete (``mjx_pick.studies.calibration.trials.loop`` passes the 1:1 PDF writer).

    Returns:
      the plan (``trials.json``). Simulates at most pool x (1 + draws) x placements
      pick-points (placements that cannot be grasped are not simulated).
    """
    check_range("trials", "n", n, 1, 1000)
    check_range("trials", "repeats", repeats, 1, 1000)
    check_range("trials", "draws", draws, 2, 1000)
    check_range("trials", "placements", placements, 1, 1000)
    check_range("trials", "jitter_mm", jitter_mm, 0, 50)
    check_range("trials", "jitter_deg", jitter_deg, 0, 90)
    check_range("trials", "pool", pool, n, 100_000)
    check_range("trials", "info_share", info_share, 0, 1)
    names = canonical_params(params)
    src = read_run(run_dir, obj)
    if jitter_mm == 0 and jitter_deg == 0:
        placements = 1  # every placement would be the template pose
    options = {
        "n": n,
        "repeats": repeats,
        "draws": draws,
        "placements": placements,
        "jitter_mm": jitter_mm,
        "jitter_deg": jitter_deg,
        "pool": pool,
        "info_share": info_share,
        "seed": seed,
        "blind": blind,
        "bounds": {k: list(map(float, v)) for k, v in (bounds or {}).items()},
        "priors": {k: list(map(float, v)) for k, v in (priors or {}).items()},
    }
    request = {"run": src.config.get("config_key"), "object": obj.summary(), "params": names}
    request.update(options)
    out_dir = claim(out, COMMAND, config_hash(request), overwrite=overwrite, settings=request)
    sims = Simulations(obj, src.settings, backend, batch_size)
    space = _space(obj, src.settings, sims, names, options["bounds"], options["priors"])
    z_draws = parameter_draws(space, draws, seed)
    rnd = new_round(
        sims,
        src.table,
        (),
        number=1,
        n=n,
        repeats=repeats,
        names=names,
        nominal={},
        draws=z_draws,
        planned_with="the evaluate run's settings",
        placements=placements,
        jitter_mm=jitter_mm,
        jitter_deg=jitter_deg,
        pool=pool,
        seed=seed,
        info_share=info_share,
        pick_config=src.pick_config,
        predictions_from_table=True,
    )
    plan = _plan_record(src, obj, names, options, rnd)
    write_parquet(out_dir / CANDIDATES, src.table)
    write_json(out_dir / PLAN, plan)
    header = [c for c in SHEET_COLUMNS if not (blind and c in SIM_COLUMNS)]
    write_sheet(out_dir / SHEET, header, [sheet_row(p) for p in rnd["picks"]])
    if write_templates is not None:
        write_templates(out_dir, plan, rnd)
    meta = sims.runner.describe()
    finish(out_dir, command=COMMAND, config=request, seed=seed, **meta)
    return plan


def _plan_record(src, obj: ObjectModel, names, options: dict, rnd: dict) -> dict:
    """trials.json: the evaluate run planned from, the object, the settings every round
    simulates with, the plan's options and its first round."""
    s = src.settings
    return {
        "format": 1,
        "run": {
            "path": str(src.path.resolve()),
            "config_key": src.config.get("config_key"),
            "backend": src.config.get("backend"),
            "pick_points": src.table.num_rows,
        },
        "object": obj.summary(),
        "settings": {
            "gripper": to_dict(s.gripper),
            "contact": to_dict(s.contact),
            "solver": to_dict(s.solver),
            "grasp": to_dict(s.grasp),
            "picks": to_dict(src.pick_config),
        },
        "params": list(names),
        **options,
        "rounds": [rnd],
    }


def _space(obj, settings: Settings, sims: Simulations, names, bounds, priors) -> ParamSpace:
    start = start_values(names, settings, sims.scene)
    return param_space(
        names,
        settings,
        obj.mass_kg,
        bounds,
        start=start,
        priors=priors,
        grip_force_n=[settings.grasp.grip_force_n],
    )
