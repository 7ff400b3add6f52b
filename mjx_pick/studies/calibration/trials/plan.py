"""Round 1 of a trials folder: candidates from the run, their information, the sheet."""

from __future__ import annotations

import dataclasses

from mjx_pick.core.config import (
    ConfigError,
    check_range,
    to_dict,
    write_json,
    write_parquet,
)
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.settings import Settings
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
from mjx_pick.studies.options import RunOptions, split_fields


@dataclasses.dataclass(frozen=True)
class TrialsPlan:
    """What :func:`plan_trials` plans (how it runs: ``options.RunOptions``: out, the
    trials folder; seed, backend, batch_size, overwrite).

    Attributes:
      n: pick-points to try; repeats: trials per pick-point (the paper: 5).
      params: the contact parameters whose uncertainty decides what is informative
        (``parameters.PARAMS``; aliases allowed).
      draws: parameter draws S from their prior; placements: R placements per draw,
        jittered by jitter_mm (x, y) and jitter_deg (yaw) -- the error of placing the
        object on the template.
      pool: candidates simulated (stratified over the run's successes and failures);
        info_share: the share of n chosen by information (the rest: best / worst).
      blind: leave the simulation's predictions out of trials.csv (the person at the
        robot does not see them; they stay in trials.json).
      bounds, priors: {name: (lo, hi)} and {name: (mean, sd)} as ``calibrate`` takes
        them: the draws come from the prior (default: weak, half the bounds).
    """

    n: int = 12
    repeats: int = 5
    params: str | tuple = "pad_friction"
    draws: int = 6
    placements: int = 3
    jitter_mm: float = 1.0
    jitter_deg: float = 2.0
    pool: int = 32
    info_share: float = 0.5
    blind: bool = False
    bounds: dict | None = None
    priors: dict | None = None

    def check(self) -> None:
        """Every number in its range (a ConfigError naming the first that is not)."""
        check_range("trials", "n", self.n, 1, 1000)
        check_range("trials", "repeats", self.repeats, 1, 1000)
        check_range("trials", "draws", self.draws, 2, 1000)
        check_range("trials", "placements", self.placements, 1, 1000)
        check_range("trials", "jitter_mm", self.jitter_mm, 0, 50)
        check_range("trials", "jitter_deg", self.jitter_deg, 0, 90)
        check_range("trials", "pool", self.pool, self.n, 100_000)
        check_range("trials", "info_share", self.info_share, 0, 1)

    def record(self, seed: int) -> dict:
        """The plan's options as trials.json keeps them."""
        placements = 1 if self.jitter_mm == 0 and self.jitter_deg == 0 else self.placements
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out.pop("params")
        out.update(placements=placements, seed=seed)
        out["bounds"] = {k: list(map(float, v)) for k, v in (self.bounds or {}).items()}
        out["priors"] = {k: list(map(float, v)) for k, v in (self.priors or {}).items()}
        return {k: out[k] for k in _RECORD_ORDER}


# trials.json's order of the plan's options
_RECORD_ORDER = (
    "n", "repeats", "draws", "placements", "jitter_mm", "jitter_deg", "pool", "info_share",
    "seed", "blind", "bounds", "priors",
)  # fmt: skip


def plan_trials(
    run_dir,
    obj: ObjectModel,
    options: RunOptions | None = None,
    *,
    request: TrialsPlan | None = None,
    write_templates: TemplateWriter | None = None,
    **fields,
) -> dict:
    """Plan round 1 of trials of the pick-points of an evaluate run.

    Args:
      run_dir: a finished evaluate folder of obj (its settings are used throughout).
      options: how it runs (``options.RunOptions``): out, the trials folder (claimed for
        the ``trials`` command); seed, backend, batch_size, overwrite.
      request: what it plans (:class:`TrialsPlan`); fields: fields of either by name.
      write_templates: called as write_templates(out, plan, round) before the folder
        is marked complete (``calibration.trials.loop`` passes the 1:1 PDF writer).

    Returns:
      the plan (``trials.json``). Simulates at most pool x (1 + draws) x placements
      pick-points (placements that cannot be grasped are not simulated).
    """
    req, opts = split_fields(TrialsPlan, request, options, fields)
    opts.only("trials plan", "seed", "backend", "batch_size", "out", "overwrite")
    if opts.out is None:
        raise ConfigError("trials plan needs out: the trials folder")
    req.check()
    names = canonical_params(req.params)
    src = read_run(run_dir, obj)
    record = req.record(opts.seed)
    request = {"run": src.config.get("config_key"), "object": obj.summary(), "params": names}
    request.update(record)
    key = config_hash(request)
    out_dir = claim(opts.out, COMMAND, key, overwrite=opts.overwrite, settings=request)
    sims = Simulations(obj, src.settings, opts.backend, opts.batch_size)
    rnd = _first_round(obj, src, sims, names, record)
    plan = _plan_record(src, obj, names, record, rnd)
    write_parquet(out_dir / CANDIDATES, src.table)
    write_json(out_dir / PLAN, plan)
    header = [c for c in SHEET_COLUMNS if not (req.blind and c in SIM_COLUMNS)]
    write_sheet(out_dir / SHEET, header, [sheet_row(p) for p in rnd["picks"]])
    if write_templates is not None:
        write_templates(out_dir, plan, rnd)
    finish(out_dir, command=COMMAND, config=request, seed=opts.seed, **sims.runner.describe())
    return plan


def _first_round(obj: ObjectModel, src, sims: Simulations, names, record: dict) -> dict:
    """Round 1: the run's candidates, their information under the prior's draws, the
    pick-points chosen (``choosing.new_round``)."""
    space = _space(obj, src.settings, sims, names, record["bounds"], record["priors"])
    return new_round(
        sims,
        src.table,
        (),
        number=1,
        n=record["n"],
        repeats=record["repeats"],
        names=names,
        nominal={},
        draws=parameter_draws(space, record["draws"], record["seed"]),
        planned_with="the evaluate run's settings",
        placements=record["placements"],
        jitter_mm=record["jitter_mm"],
        jitter_deg=record["jitter_deg"],
        pool=record["pool"],
        seed=record["seed"],
        info_share=record["info_share"],
        pick_config=src.pick_config,
        predictions_from_table=True,
    )


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
