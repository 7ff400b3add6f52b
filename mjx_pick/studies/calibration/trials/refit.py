"""The fit of the tried rows, the agreement before and after, and the next round."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from mjx_pick.core.config import (
    ConfigError,
    check_range,
    write_atomic,
    write_json,
)
from mjx_pick.core.metrics import mcnemar_p
from mjx_pick.core.objects import ObjectModel, check_same_object
from mjx_pick.engine.registry import AUTO
from mjx_pick.kernels import types as kt
from mjx_pick.outputs.rundir import read_manifest, remove_run
from mjx_pick.studies.calibration.identify import Z95
from mjx_pick.studies.calibration.parameters import (
    canonical_params,
)
from mjx_pick.studies.calibration.trials.agreement import (
    _confusion_md,
    _row_detail,
    _rows_md,
    _summary_md,
    agreement,
)
from mjx_pick.studies.calibration.trials.choosing import new_round
from mjx_pick.studies.calibration.trials.runs import (
    Simulations,
    parameter_draws,
    plan_settings,
)
from mjx_pick.studies.calibration.trials.sheet import (
    CANDIDATES,
    PLAN,
    SHEET,
    TemplateWriter,
    load_plan,
    read_sheet,
    sheet_row,
    tried_rows,
    write_sheet,
)
from mjx_pick.studies.options import RunOptions, split_fields


@dataclasses.dataclass
class TrialFit:
    """A fit of the tried rows and what it changed.

    before / after: :func:`agreement` of the tried rows re-simulated at the starting
    (the run's) and at the fitted parameters; mcnemar_p: exact McNemar test that the
    fit changed how often the simulation is right; rerun_differs: tried rows whose
    re-simulation at the start disagrees with the prediction they were planned with
    (borderline simulations); next_round: the round proposed (None: none proposed);
    report: what ``fit-round<r>/agreement.json`` holds (with ``at_optimum``: the
    agreement at the fit's optimum where a parameter was not identified)."""

    result: object  # calibration.fit.CalibrationResult
    before: dict
    after: dict
    mcnemar_p: float
    rerun_differs: int
    out_dir: Path
    next_round: dict | None
    notes: list[str]
    report: dict


@dataclasses.dataclass(frozen=True)
class TrialsFit:
    """What :func:`fit_trials` fits (the fit's own settings: ``fit.FitRequest``; how it
    runs: ``options.RunOptions``: seed, backend, overwrite, resume).

    Attributes:
      params: the parameters to fit (None: the plan's).
      partial: fit the tried rows while others are still blank.
      bounds, priors, temperature_mm: as ``Problem`` (bounds and priors: default the
        plan's, for the parameters it names).
      next_n: pick-points of the next round (0: none), chosen as the plan chose, with
        the fitted parameters as the nominal ones and draws from the fit's intervals
        (the prior's spread for a parameter the data did not identify).
    """

    params: str | tuple | None = None
    partial: bool = False
    bounds: dict | None = None
    priors: dict | None = None
    temperature_mm: float | None = None
    next_n: int = 6


def fit_trials(
    folder,
    obj: ObjectModel,
    options: RunOptions | None = None,
    *,
    request: TrialsFit | None = None,
    log=None,
    write_templates: TemplateWriter | None = None,
    **fields,
) -> TrialFit:
    """Fit the tried rows, re-simulate them with the fitted parameters, compare the
    agreement before and after, and propose the next round.

    Args:
      folder: a trials folder; obj: its object (checked against the plan).
      options: how it runs; request: what it fits (:class:`TrialsFit`); fields: fields
        of either, or of ``fit.FitRequest`` (steps: 40 unless given), by name.
      log: as ``calibrate``'s; write_templates: as :func:`plan_trials`'s, for the next
        round.

    Writes ``fit-round<r>/`` (r: the last round with a tried row): calibrate's files
    plus agreement.json and agreement.md; appends the next round to the sheet and the
    plan (replacing a proposed round none of whose rows was tried yet).
    """
    from mjx_pick.studies.calibration.fit import FitRequest, calibrate

    fit_names = {f.name for f in dataclasses.fields(FitRequest)}
    fit = dataclasses.replace(
        FitRequest(steps=40), **{k: fields.pop(k) for k in fit_names & set(fields)}
    )
    req, opts = split_fields(TrialsFit, request, options, fields)
    opts.only("trials fit", "seed", "backend", "overwrite", "resume", "progress")
    check_range("trials", "next", req.next_n, 0, 1000)
    folder = Path(folder)
    trial = _open_trials(folder, obj, req, opts)
    res = calibrate(
        trial.problem,
        dataclasses.replace(opts, backend=AUTO, out=trial.out_dir, overwrite=False),
        request=fit,
        log=log,
    )
    before, after, optimum, rerun = _agreements(trial.problem, res, trial.names, trial.tried)
    report = _fit_report(trial.names, res, trial.tried, before, after, optimum, rerun)
    write_json(trial.out_dir / "agreement.json", report)
    write_atomic(trial.out_dir / "agreement.md", fit_md(report, trial.plan))
    notes = report["notes"]
    next_round = _next_round(trial, obj, res, req.next_n, opts.backend, notes, write_templates)
    return TrialFit(
        res,
        before,
        after,
        report["mcnemar_p"],
        report["rerun_differs"],
        trial.out_dir,
        next_round,
        notes,
        report,
    )


@dataclasses.dataclass(frozen=True)
class _OpenTrials:
    """A trials folder opened for a fit: its plan, the rows tried, the settings and
    pick configuration they were planned with, the fit's folder and its Problem."""

    folder: Path
    plan: dict
    names: list
    tried: object
    settings: object
    pick_config: object
    last: int  # the last round with a tried row
    out_dir: Path
    problem: object


def _open_trials(folder: Path, obj: ObjectModel, req: TrialsFit, opts: RunOptions) -> _OpenTrials:
    """The fit's inputs, every one checked before anything is simulated."""
    from mjx_pick.studies.calibration.problem import Problem

    plan = load_plan(folder)
    check_same_object(plan["object"], obj, f"trials folder {folder}")
    names = canonical_params(req.params or plan["params"])
    tried = tried_rows(folder, plan, req.partial)
    settings, pick_config = plan_settings(plan, folder)
    bounds = {**_named(plan.get("bounds"), names), **(req.bounds or {})}
    priors = {**_named(plan.get("priors"), names), **(req.priors or {})}
    last = max(e["round"] for e in tried.entries)
    out_dir = _fit_folder(folder, last, opts.overwrite, opts.resume)
    problem = Problem(
        obj,
        tried.outcomes,
        names,
        settings,
        temperature_mm=req.temperature_mm,
        bounds=bounds,
        priors=priors,
        pick_config=pick_config,
        backend=opts.backend,
    )
    return _OpenTrials(folder, plan, names, tried, settings, pick_config, last, out_dir, problem)


def _next_round(trial: _OpenTrials, obj, res, next_n: int, backend, notes, write_templates):
    """The next round proposed from the fit (None: none), added to the folder's plan
    and sheet (its templates printed by write_templates); a note on why not, if any."""
    if not next_n:
        return None
    next_round, note = _propose(
        trial.folder,
        obj,
        trial.plan,
        trial.problem,
        res,
        trial.settings,
        trial.pick_config,
        trial.last + 1,
        next_n,
        backend,
    )
    if note:
        notes.append(note)
    if next_round is not None:
        _add_round(trial.folder, trial.plan, next_round)
        if write_templates is not None:
            write_templates(trial.folder, trial.plan, next_round)
    return next_round


def _fit_folder(folder: Path, last: int, overwrite: bool, resume: bool) -> Path:
    """Where round last's fit is written, ``fit-round<last>/``: an earlier fit there is
    continued (resume), replaced (overwrite: only a fit's folder) or refused."""
    out_dir = folder / f"fit-round{last}"
    if out_dir.exists() and not resume:
        if not overwrite:
            raise ConfigError(
                f"{out_dir} holds an earlier fit of round {last}: pass --overwrite to replace "
                "it (or --resume to continue it)"
            )
        if (read_manifest(out_dir) or {}).get("command") != "calibrate":
            raise ConfigError(f"{out_dir} was not written by a fit: move it away first")
        remove_run(out_dir)  # the files that fit recorded writing
    return out_dir


def _agreements(problem, res, names, tried) -> tuple[dict, dict, list, int]:
    """The tried rows re-simulated at the start, at the fitted values and (when a
    parameter was not identified) at the fit's optimum, each against the outcomes.
    Returns (agreement before, after, [at the optimum] or [], how many re-simulated
    predictions at the start differ from the planned ones)."""
    space = problem.space
    fitted = space.theta([res.values[n] for n in names])
    vectors = [problem.start_theta(), fitted]
    if res.not_identified:  # the optimum too, to show what the data could not pin
        vectors.append(space.theta([res.optimum[n] for n in names]))
    sim = problem.simulate(np.stack(vectors))
    o = tried.outcomes
    names_of = np.asarray(kt.FAILURES, dtype=object)
    before, after, *optimum = (
        agreement(
            sim["success"][j],
            o.trials,
            o.successes,
            [
                # re-simulated at the template pose only: no placement fraction
                {**_row_detail(e), "sim_p": None, "sim_failure": str(names_of[f])}
                for e, f in zip(tried.entries, sim["failure"][j], strict=True)
            ],
        )
        for j in range(len(vectors))
    )
    planned = np.array([e["sim_success"] for e in tried.entries])
    return before, after, optimum, int(np.sum(planned != sim["success"][0]))


def _fit_report(names, res, tried, before, after, optimum, rerun_differs) -> dict:
    """agreement.json: the fit, the agreement before and after it, McNemar's p of the
    change, and notes on how to read them."""
    right_before = np.array([r["agrees"] for r in before["rows"]])
    right_after = np.array([r["agrees"] for r in after["rows"]])
    p_change = mcnemar_p(right_after, right_before)
    notes = [
        "in-sample: the fit saw these outcomes, so the agreement after it is optimistic; "
        "the next round, predicted before its trials, is the honest test",
        f"exact McNemar p = {p_change:.3g} that the fit changed how often the simulation "
        f"is right ({before['correct']} -> {after['correct']} of {before['pick_points']})",
    ]
    if rerun_differs:
        notes.append(
            f"{rerun_differs} tried pick-point(s) re-simulated at the run's parameters "
            "predict the opposite of their planned prediction: borderline simulations"
        )
    if res.not_identified:
        notes.append(
            f"not identified by these trials: {', '.join(res.not_identified)} (kept at "
            "the start, so the agreement after counts only what was identified; at the "
            f"fit's optimum {optimum[0]['correct']} of {optimum[0]['pick_points']} would "
            "agree); the next round looks for pick-points that tell the values around "
            "the optimum apart"
        )
    return {
        "parameters": list(names),
        "initial": res.initial,
        "fitted": res.values,
        "optimum": res.optimum,
        "intervals": {k: (res.identifiability or {}).get(k, {}).get("interval") for k in names},
        "not_identified": list(res.not_identified),
        "rows": len(tried.outcomes),
        "before": before,
        "after": after,
        "at_optimum": optimum[0] if optimum else None,
        "mcnemar_p": p_change,
        "rerun_differs": rerun_differs,
        "notes": notes,
    }


def _named(table: dict | None, names) -> dict:
    """The entries of a plan's {name: (a, b)} table for the parameters in names."""
    return {k: tuple(v) for k, v in (table or {}).items() if canonical_params([k])[0] in names}


def _propose(folder, obj, plan, problem, res, settings, pick_config, number, n, backend):
    """The next round (or None and why not).

    Its predictions are the fitted parameters' (contact.toml's: a parameter the data did
    not identify stays at its start). Its draws, which decide what is informative, come
    from where the data left the doubt: a Gaussian in z around the fit's optimum with
    the spread of its 95 % interval (identify.py) where that is narrower than the
    prior's, else the prior's -- for a parameter not identified too, since its local
    interval is still the best guide to where the next trials should look."""
    existing = [r for r in plan["rounds"] if r["round"] == number]
    _, rows = read_sheet(folder)
    tried_ids = {int(r["pick_id"]) for r in rows if r["successes"] != ""}
    if existing and any(p["pick_id"] in tried_ids for p in existing[0]["picks"]):
        return None, f"round {number} is planned and partly tried already: no new proposal"
    space = problem.space
    names = list(space.names)
    centre = space.z([(res.optimum or res.values)[k] for k in names])
    sd = np.array(space.prior_sd, float)
    ident = res.identifiability or {}
    for i, k in enumerate(names):
        half = (ident.get(k) or {}).get("half_width_z")
        if half:
            sd[i] = min(sd[i], half / Z95)
    draws = parameter_draws(space, plan["draws"], plan["seed"] + number, centre, sd)
    sims = Simulations(obj, settings, backend)
    table = pq.read_table(Path(folder) / CANDIDATES)
    keep = {p["pick_id"] for r in plan["rounds"] if r["round"] != number for p in r["picks"]}
    rnd = new_round(
        sims,
        table,
        keep,
        number=number,
        n=n,
        repeats=plan["repeats"],
        names=names,
        nominal=dict(res.values),
        draws=draws,
        planned_with=f"the fit of fit-round{number - 1}",
        placements=plan["placements"],
        jitter_mm=plan["jitter_mm"],
        jitter_deg=plan["jitter_deg"],
        pool=plan["pool"],
        info_share=plan["info_share"],
        seed=plan["seed"] + number,
        pick_config=pick_config,
        predictions_from_table=False,
    )
    rnd["draws_from"] = {
        "centre": dict(zip(names, map(float, space.natural(centre)), strict=True)),
        "sd_z": dict(zip(names, map(float, sd), strict=True)),
    }
    return rnd, None


def _add_round(folder, plan: dict, rnd: dict) -> None:
    """Put a round into the plan and its rows at the end of the sheet (an untried round
    of the same number is replaced; tried rows are never touched)."""
    folder = Path(folder)
    header, rows = read_sheet(folder)
    old = {p["pick_id"] for r in plan["rounds"] if r["round"] == rnd["round"] for p in r["picks"]}
    rows = [r for r in rows if int(r["pick_id"]) not in old]
    plan["rounds"] = [r for r in plan["rounds"] if r["round"] != rnd["round"]] + [rnd]
    write_json(folder / PLAN, plan)
    write_sheet(folder / SHEET, header, rows + [sheet_row(p) for p in rnd["picks"]])


def fit_md(report: dict, plan: dict) -> str:
    """agreement.md of a fit: the parameters, then the agreement before and after."""
    lines = [
        f"# Trials fit: {plan['object']['name']} / {plan['settings']['gripper']['name']}",
        "",
        f"{report['rows']} tried pick-points. Parameters (start -> fitted):",
        "",
    ]
    for k in report["parameters"]:
        iv = report["intervals"].get(k)
        said = [f"95 % {iv[0]:.4g}-{iv[1]:.4g}"] if iv else []
        if k in report["not_identified"]:
            said = ["not identified: kept at the start", f"optimum {report['optimum'][k]:.4g}"]
            said += [f"95 % {iv[0]:.4g}-{iv[1]:.4g}"] if iv else []
        extra = f" ({'; '.join(said)})" if said else ""
        lines.append(f"* {k}: {report['initial'][k]:.4g} -> {report['fitted'][k]:.4g}{extra}")
    sections = [
        ("before", "Before: the run's parameters"),
        ("after", "After: the fitted parameters (contact.toml)"),
        ("at_optimum", "At the fit's optimum (not used: a parameter was not identified)"),
    ]
    for key, title in sections:
        a = report.get(key)
        if a:
            lines += ["", f"## {title}", "", *_confusion_md(a), "", *_summary_md(a)]
    lines += ["", "## Notes", "", *[f"* {n}" for n in report["notes"]]]
    lines += ["", "## Per pick-point, after the fit", "", *_rows_md(report["after"]["rows"])]
    return "\n".join(lines) + "\n"
