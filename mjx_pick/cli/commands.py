"""One function per subcommand: it turns the parsed options into one library call and
prints what came back. No simulation, file or results logic lives here."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from mjx_pick.cli.clock import process_age_s
from mjx_pick.cli.inputs import (
    PICK_FLAGS,
    SETTINGS_FLAGS,
    base_settings,
    check_contact_file,
    design_bounds,
    given,
    grippers,
    inputs_of,
    name_ranges,
    object_of,
    objects,
    pick_config,
    run_options,
)
from mjx_pick.core.config import ConfigError
from mjx_pick.core.escape import shell_word
from mjx_pick.engine import registry
from mjx_pick.outputs.progress import echo


def confirm_duration(args, what: str, simulations: int, grasp=None, solver=None, backend=None):
    """Before any simulation: a run estimated longer than a few minutes on this machine
    (``studies.duration``) is refused unless --yes, saying how long; with --yes, the
    estimate is said as it starts."""
    from mjx_pick.outputs.rundir import check_folder
    from mjx_pick.studies import duration

    check_folder(getattr(args, "out", None))  # a folder it cannot use: said first
    backend = backend or getattr(args, "backend", registry.AUTO)
    est = duration.estimate(simulations, grasp, solver, backend, ray=getattr(args, "ray", None))
    line = duration.refuse_long(est, what, args.yes)
    if line:
        print(f"mjx-pick: {line}", file=sys.stderr)


def start_engine(args) -> None:
    """A command that simulates in this process on a backend that drives CUDA devices
    through Warp (named, or 'auto''s first choice) starts Warp now, beside its own
    imports and the part's preparation (``devices.start_warp``: the driver's and the
    GPUs' start, a fixed cost of every run, overlaps them)."""
    name = getattr(args, "backend", registry.AUTO)
    first = registry.auto_order()[0] if name == registry.AUTO else registry.ENTRIES.get(name)
    if first is not None and first.cuda_devices and not getattr(args, "ray", None):
        from mjx_pick.engine.devices import start_warp

        start_warp()


def cmd_evaluate(args) -> int:
    t0 = time.perf_counter()
    start_engine(args)
    from mjx_pick.studies.evaluation import evaluate
    from mjx_pick.studies.object_sets import is_object_set

    if is_object_set(args.object):
        return _evaluate_set(args)

    t1 = time.perf_counter()
    obj, gripper, contact, solver, grasp, picks_cfg = inputs_of(args)
    check_contact_file(args, obj, gripper, grasp, solver)
    size = dict(n=_grasps_in(args), picks=args.picks, until=args.until, max_n=args.max)
    size.update(min_force=args.min_force, stability_um=args.stability_um)
    count = _count("evaluate", size, step_check=args.step_check)
    confirm_duration(args, "this evaluate", count, grasp, solver)
    # what the run cannot see: imports (the CLI's and the study's) and object preparation
    before = getattr(args, "started_s", None)
    costs = {
        "import_s": (before or 0.0) + t1 - t0,
        "object_s": time.perf_counter() - t1,
    }
    ev = evaluate(
        obj,
        gripper,
        run_options(args, picks_cfg),
        picks=args.picks,
        contact=contact,
        solver=solver,
        grasp=grasp,
        n_traces=args.traces,
        until=args.until,
        min_score=args.min_score,
        max_n=args.max,
        chunk_size=args.chunk_size,
        min_force=args.min_force,
        stability_um=args.stability_um,
        step_check=args.step_check,
        skip_infeasible=args.skip_infeasible,
        fixed_costs=costs,
    )
    if ev.already_complete:
        print(f"{args.out} holds this run complete: nothing to resume, nothing simulated")
    total = process_age_s() if before is not None else None
    print_summary(ev.summary, args.out, total, traced=ev.traces is not None)
    return 0


def _grasps_in(args) -> int:
    """The grasps an evaluate simulates at most: a grasp file's (every grasp in it),
    else --n."""
    from mjx_pick.studies.grasp_sources import ANTIPODAL, TOPDOWN, check_source

    source = check_source(args.grasps, args.depth_mm)
    if source in (TOPDOWN, ANTIPODAL):
        return args.n
    from mjx_pick.outputs.exchange import read_labels

    return len(read_labels(source).transforms)


def _evaluate_set(args) -> int:
    """evaluate on a folder of meshes or a manifest: each part into OUT/objects/<part>/."""
    from mjx_pick.cli.inputs import DEFAULT_GRIPPER, set_object_options, settings
    from mjx_pick.core.gripper import load_gripper
    from mjx_pick.core.metrics import rate_text
    from mjx_pick.studies.object_sets import evaluate_set, read_parts

    parts = read_parts(
        args.object,
        mass_g=args.mass_g,
        density_kg_m3=args.density_kg_m3,
        unit=args.unit,
        pose=args.pose,
    )
    gripper = load_gripper(args.gripper_file or args.gripper or DEFAULT_GRIPPER)
    contact, solver, (grasp, given), picks_cfg = settings(args)
    grasp, note = grasp.fitted_to(gripper, keep=given)
    if note:
        print(f"mjx-pick: note: {note}", file=sys.stderr)
    each = _count("evaluate", dict(n=args.n, picks=None, until=None, max_n=None))
    confirm_duration(args, f"this evaluate of {len(parts)} parts", each * len(parts), grasp, solver)
    res = evaluate_set(
        parts,
        gripper,
        run_options(args, picks_cfg),
        object_options=set_object_options(args),
        contact=contact,
        solver=solver,
        grasp=grasp,
        n_traces=args.traces,
        chunk_size=args.chunk_size,
    )
    for name, s in res.summaries.items():
        print(f"{name}: {rate_text(s['successes'], s['n'])}")
    if args.out:
        print(
            f"results in {args.out}/ (results.parquet: every part's rows, an object column; "
            f"summary.json; objects/<part>/: each part's run folder)"
        )
    return 0


def _count(study: str, sizes: dict, **more) -> int:
    """The simulations a study's sizes make (``duration.count``)."""
    from mjx_pick.studies import duration

    return duration.count(study, **sizes, **more)


def _print_rows(rows: list[dict], keys: list[str]) -> None:
    width = {k: max(len(k), *(len(_fmt(r.get(k))) for r in rows)) for k in keys}
    print("  ".join(f"{k:<{width[k]}}" for k in keys))
    for r in rows:
        print("  ".join(f"{_fmt(r.get(k)):<{width[k]}}" for k in keys))


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.3f}"
    if isinstance(v, list | tuple) and len(v) == 2:
        return f"[{v[0]:.2f}, {v[1]:.2f}]"
    return str(v)


def cmd_sweep(args) -> int:
    start_engine(args)
    from mjx_pick.studies.sweeps import ParamSpec, sweep, variants

    if not args.param:
        raise ConfigError("sweep needs at least one --param NAME=LO:HI:N (`mjx-pick params`)")
    obj, base, picks_cfg = base_settings(args)
    params = [ParamSpec.parse(p) for p in args.param]
    count = len(variants(params, args.random, args.seed))
    echo(
        f"mjx-pick: sweep: {count} variant(s) x {args.n} pick-points = up to "
        f"{count * args.n:,} simulations (pick-points a variant makes infeasible are not "
        "simulated)",
        sys.stderr,
    )
    sims = _count("sweep", {"variants": count, "n": args.n})
    confirm_duration(args, "this sweep", sims, base.grasp, base.solver)
    res = sweep(
        obj,
        params,
        base,
        run_options(args, picks_cfg),
        random=args.random,
    )
    if res.already_complete:
        print(f"{args.out} holds this sweep complete: nothing to resume, nothing simulated")
    _print_rows(
        res.variants,
        [
            "variant",
            *[p.name for p in params],
            "n",
            "success_rate",
            "success_ci",
            "score_mean",
            "diverged",
        ],
    )
    t = res.timing
    print(
        f"{t['simulations']} simulations, {t['scenes']} scene(s): compile {t['compile_s']:.1f} s, "
        f"run {t['run_s']:.1f} s ({t['simulations_per_s']} per s)"
    )
    if args.out:
        print(f"results in {args.out}/ (results.parquet, variants.json, sweep.png, config.json)")
    return 0


def cmd_compare(args) -> int:
    start_engine(args)
    from mjx_pick.studies.comparison import compare, unequal_forces

    obj, base, picks_cfg = base_settings(args)
    chosen = grippers(args.grippers)
    sims = _count("compare", {"variants": len(chosen), "n": args.n})
    confirm_duration(args, "this comparison", sims, base.grasp, base.solver)
    res = compare(
        obj,
        chosen,
        base,
        run_options(args, picks_cfg),
        rank_by=args.rank_by,
    )
    if res.already_complete:
        print(f"{args.out} holds this comparison complete: nothing to resume, nothing simulated")
    _print_rows(
        res.ranking,
        [
            "rank",
            "gripper",
            "success_rate",
            "success_ci",
            "score_mean",
            "feasible",
            "grip_force_n",
            "p_vs_best",
        ],
    )
    note = unequal_forces(res.ranking)
    if note:
        print(f"note: {note}")
    if args.out:
        print(f"results in {args.out}/ (ranking.json, ranking.png, maps.png, results.parquet)")
    return 0


def cmd_design(args) -> int:
    start_engine(args)
    from mjx_pick.studies.comparison import design_search, sample_variants

    obj, base, picks_cfg = base_settings(args)
    bounds = design_bounds(args.bound or [])
    sample_variants(base.gripper, bounds, args.variants, args.seed)  # bounds refused first
    sizes = {"variants": args.variants, "rounds": args.rounds, "n": args.n}
    confirm_duration(args, "this design search", _count("design", sizes), base.grasp, base.solver)
    res = design_search(
        obj,
        bounds,
        base,
        run_options(args, picks_cfg),
        variants=args.variants,
        rounds=args.rounds,
        rank_by=args.rank_by,
    )
    if res.final.already_complete:
        print(f"{args.out} holds this design search complete: nothing to resume, nothing simulated")
    print(f"best variant: {res.best.name}")
    for field in bounds:
        print(f"  {field}: {getattr(res.best, field):g} (base {getattr(res.base, field):g})")
    _print_rows(
        res.final.ranking,
        ["rank", "gripper", "success_rate", "success_ci", "score_mean", "p_vs_best"],
    )
    if args.out:
        print(f"results in {args.out}/ (design.json, best_gripper.toml, ranking.png, maps.png)")
    return 0


def cmd_robust(args) -> int:
    start_engine(args)
    from mjx_pick.studies.robust import robust_best

    if args.n is None and not args.results:
        args.n = 200  # the pick-points it ranks (with --results: the run's own)

    if args.results and not given(args, SETTINGS_FLAGS + PICK_FLAGS):
        obj, base, picks_cfg = object_of(args), None, None  # the run's own settings
    else:
        obj, base, picks_cfg = base_settings(args)
        if args.results and not given(args, PICK_FLAGS):
            picks_cfg = None
        if args.results and not given(args, SETTINGS_FLAGS):
            base = None
    sizes = {"top_k": args.top_k, "m": args.m, "n": None if args.results else args.n}
    grasp, solver = (base.grasp, base.solver) if base is not None else (None, None)
    confirm_duration(args, "this robustness study", _count("robust", sizes), grasp, solver)
    if args.out and args.results and Path(args.out).resolve() == Path(args.results).resolve():
        print(f"mjx-pick: robust adds robustness.parquet and robustness.json to {args.out}")
    table = robust_best(
        obj,
        base,
        run_options(args, picks_cfg),
        results=args.results,
        top_k=args.top_k,
        m=args.m,
        sigma_xy_mm=args.sigma_xy_mm,
        sigma_yaw_deg=args.sigma_yaw_deg,
    )
    _print_rows(
        table.slice(0, 20).to_pylist(),
        ["rank", "pick_id", "x_mm", "y_mm", "yaw_deg", "robust_p", "robust_ci_low", "landed"],
    )
    if args.out:
        print(f"results in {args.out}/ (robustness.parquet, robustness.json)")
    return 0


def cmd_calibrate(args) -> int:
    from mjx_pick.studies import calibration as cal
    from mjx_pick.studies.validation import is_trials_file

    if is_trials_file(args.outcomes):
        return _calibrate_trials(args)
    if args.object is None:
        raise ConfigError(
            f"calibrate {args.outcomes}: give the object the outcomes were measured on "
            "(mjx-pick calibrate OUTCOMES OBJECT ...); a TRIALS.csv names its own"
        )
    obj, base, picks_cfg = base_settings(args)
    names = cal.canonical_params(args.params)
    problem, holdout = _calibration_problems(args, obj, base, picks_cfg, names)
    for note in problem.notes:  # said before the fit, and again in report.md
        print(f"mjx-pick: note: {note}", file=sys.stderr)
    rows = len(problem.row_of) + (len(holdout.row_of) if holdout is not None else 0)
    sizes = {"steps": args.steps, "vectors": _vectors_per_step(args, len(names)), "rows": rows}
    backend = registry.differentiable() if args.estimator == "jvp" else args.backend
    s = problem.settings
    confirm_duration(args, "this fit", _count("calibrate", sizes), s.grasp, s.solver, backend)
    res = _fit(args, problem, holdout)
    if not res.history:  # said from what happened: no step, so no fit
        print("mjx-pick: note: no estimator step was taken (--steps 0): the values are the start's")
    _print_fit(res, names)
    print(
        f"results in {args.out}/ (contact.toml, calibration.json, loss.png, report.md); "
        f"use: mjx-pick evaluate ... --contact {shell_word(f'{args.out}/contact.toml')}"
    )
    return 0


def _calibrate_trials(args) -> int:
    """calibrate on physical trials: fit on a split of the grasps, validate the rest at
    the starting and at the fitted contact parameters (heldout.json)."""
    import numpy as np

    from mjx_pick.cli.inputs import settings
    from mjx_pick.core.config import write_json
    from mjx_pick.studies import calibration as cal
    from mjx_pick.studies.options import RunOptions
    from mjx_pick.studies.validation import (
        read_trials,
        split_by_grasp,
        trial_outcomes,
        validate,
    )

    if args.object is not None:
        raise ConfigError(
            f"{args.outcomes} is a TRIALS.csv, which names its object: leave out {args.object!r}"
        )
    trials = read_trials(args.outcomes)
    contact, solver, (grasp, given), picks = settings(args)
    train, test = split_by_grasp(trials, args.split, args.seed)
    names = cal.canonical_params(args.params)
    unit = args.unit or "m"
    common = dict(grasp=grasp if given else None, keep_grasp=tuple(given), unit=unit)
    common.update(contact=contact, solver=solver)
    made = [
        trial_outcomes(trials, rows, safety_zone_mm=picks.safety_zone_mm, **common)
        for rows in (train, test)
    ]
    kw = dict(
        temperature_mm=args.temperature_mm,
        bounds=name_ranges(args.bounds, "--bounds"),
        priors=name_ranges(args.prior, "--prior"),
        replicates=1,
        force_mismatch=args.force_mismatch,
    )
    backend = registry.differentiable() if args.estimator == "jvp" else args.backend
    problem = cal.Problem(made[0][0], made[0][2], names, made[0][1], backend=backend, **kw)
    holdout = cal.Problem(made[1][0], made[1][2], names, made[1][1], backend=args.backend, **kw)
    res = _fit(args, problem, holdout)
    _print_fit(res, names)
    run = RunOptions(backend=args.backend, seed=args.seed)
    before = validate(trials, run, subset=test, **common).report
    common["contact"] = res.contact
    after = validate(trials, run, subset=test, **common).report
    split = {
        "fraction": args.split,
        "seed": args.seed,
        "train_trials": len(train),
        "test_trials": len(test),
        "train_grasps": int(len(np.unique(trials.grasp_index()[train]))),
        "test_grasps": int(len(np.unique(trials.grasp_index()[test]))),
    }
    doc = {"split": split, "fitted": res.values, "before": before, "after": after}
    if args.out:
        write_json(Path(args.out) / "heldout.json", doc)
    for label, r in (("held out, before", before), ("held out, after", after)):
        f, a = r["f1"], r["accuracy"]
        print(
            f"{label}: F1 {f['value']:.3f} ({f['ci95'][0]:.2f}-{f['ci95'][1]:.2f}), accuracy "
            f"{a['value']:.3f} on {r['n']} trials ({r['grasps']} grasps)"
        )
    if args.out:
        print(f"results in {args.out}/ (contact.toml, calibration.json, heldout.json)")
    return 0


def _vectors_per_step(args, params: int) -> int:
    """The parameter vectors an estimator simulates a step (``calibration.estimators``):
    CMA-ES its population (4 + 3 ln P, at least 8), the smoothed gradient its
    quadrature (1 + 2 samples P), random search its batch of 16, Levenberg-Marquardt a
    finite-difference Jacobian (P + 1), forward mode one."""
    import math

    return {
        "cma": max(8, 4 + int(3 * math.log(max(params, 1)))),
        "smoothed": 1 + 2 * args.samples * params,
        "random": 16,
        "lsq": params + 1,
    }.get(args.estimator, 1)


def _calibration_problems(args, obj, base, picks_cfg, names):
    """The fit's problem on --outcomes, and the held-out one on --holdout (or None)."""
    from mjx_pick.studies import calibration as cal

    kw = dict(
        temperature_mm=args.temperature_mm,
        pick_config=picks_cfg,
        bounds=name_ranges(args.bounds, "--bounds"),
        priors=name_ranges(args.prior, "--prior"),
        replicates=args.replicates,
        noise=cal.Noise(trace_window_s=args.trace_window_s),
        force_mismatch=args.force_mismatch,
    )
    # the forward-mode estimator differentiates the differentiable backend's physics
    backend = registry.differentiable() if args.estimator == "jvp" else args.backend
    problem = cal.Problem(obj, cal.read_outcomes(args.outcomes), names, base, backend=backend, **kw)
    holdout = None
    if args.holdout:
        holdout = cal.Problem(
            obj, cal.read_outcomes(args.holdout), names, base, backend=args.backend, **kw
        )
    return problem, holdout


def _fit(args, problem, holdout):
    """Run the estimator --estimator names, logging every --log-every steps."""
    from mjx_pick.studies import calibration as cal
    from mjx_pick.studies.options import RunOptions

    def log(entry):
        if entry["step"] % args.log_every == 0:
            values = ", ".join(f"{k} {v:.4g}" for k, v in entry["values"].items())
            blown = f"  ({entry['diverged']} rows diverged)" if entry.get("diverged") else ""
            echo(
                f"step {entry['step']:4d}  loss {entry['loss']:.4f}  best {entry['best_loss']:.4f}"
                f"  {values}{blown}"
            )

    # the fit's run options: its backend and pick-points are the problem's
    run = RunOptions(
        seed=args.seed, out=args.out, resume=args.resume, progress=not args.no_progress
    )
    common = dict(budget=args.budget, holdout=holdout, identify=not args.no_identify, log=log)
    if args.estimator == "lsq":
        if args.resume:
            raise ConfigError("--resume: estimator 'lsq' keeps no checkpoints; run it again")
        return cal.least_squares(problem, run, max_iters=args.steps, **common)
    return cal.calibrate(
        problem,
        run,
        steps=args.steps,
        learning_rate=args.lr,
        estimator=args.estimator,
        samples=args.samples,
        sigma=args.sigma,
        checkpoint_every=args.checkpoint_every,
        **common,
    )


def _print_fit(res, names) -> None:
    """Each parameter's start -> fit with its interval and identifiability, and the
    held-out accuracy before and after."""
    from mjx_pick.studies.calibration.outputs import bound_words

    ident = res.identifiability or {}
    for name in names:
        info = ident.get(name)
        words = bound_words(info) if info else ""  # what is true of its bounds, or ""
        where = ""
        if info and info.get("interval") is None:  # --no-identify: only the bound is known
            if words:
                where = (
                    f"  {words}: NOT identified (the bound stopped the search), kept at its start"
                )
            else:
                where = "  (no interval: --no-identify, identifiability not checked)"
        elif info:
            lo, hi = info["interval"]
            where = f"  (95 % {lo:.4g}-{hi:.4g})"
            if words:
                where += f"  {words}"
            if not info["identified"] and res.values[name] == res.initial[name]:
                where += "  NOT identified: kept at its start"
            elif not info["identified"]:
                where += (
                    "  NOT identified: its start lies outside the data's interval; "
                    "the interval's nearest end is written"
                )
        print(f"{name}: {res.initial[name]:.4g} -> {res.values[name]:.4g}{where}")
    for label, acc in (("before", res.accuracy_before), ("after", res.accuracy_after)):
        if acc:
            print(f"held-out accuracy {label}: {acc['correct']}/{acc['total']}")


def cmd_report(args) -> int:
    from mjx_pick.outputs.reporting import report

    frame = None
    if args.frame:
        try:
            frame = [float(v) for v in args.frame.split(",")]
        except ValueError as err:
            raise ConfigError(f"--frame {args.frame!r}: {err}") from err
    written = report(
        args.run,
        args.out,
        n=args.n,
        k=args.k,
        frame=frame,
        animations=not args.no_animations,
        anim_every=args.anim_every,
        progress=not args.no_progress,
    )
    print(f"report: {written['html']}")
    for key, what in (("forces", "force plots"), ("animations", "GIFs"), ("videos", "MP4s")):
        print(f"  {key}: {len(written[key])} {what}")
    print(f"  templates: {', '.join(written['templates'].values()) or 'none'}")
    for paper, why in written["templates_skipped"].items():
        print(f"  template on {paper} not written: {why}")
    print(f"  robot export: {written['robot_picks']}")
    return 0


def cmd_export(args) -> int:
    from mjx_pick.outputs.exchange import export_labels

    written = export_labels(
        args.run, args.format, args.out, depth_mm=args.depth_mm, overwrite=args.overwrite
    )
    if "labels" not in written:  # a set of parts: a file per part
        for name, path in written.items():
            if not name.endswith("_mesh"):
                print(f"{args.format}: {path} (object mesh: {written[name + '_mesh']})")
        return 0
    print(f"{args.format}: {written['labels']} (object mesh: {written['mesh']})")
    return 0


def cmd_validate(args) -> int:
    from mjx_pick.cli.inputs import settings
    from mjx_pick.studies.validation import read_trials, validate

    trials = read_trials(args.trials)
    contact, solver, (grasp, given), _ = settings(args)
    grasps = len(set(trials.grasp_index().tolist()))  # each grasp simulated once
    confirm_duration(args, "this validate", grasps, grasp, solver)
    v = validate(
        trials,
        run_options(args),
        contact=contact,
        solver=solver,
        grasp=grasp if given else None,
        keep_grasp=tuple(given),
        unit=args.unit,
    )
    print_validation(v.report, args.out)
    return 0


def print_validation(r: dict, out) -> None:
    """validate's figures: overall, per object, the checks' rejections."""

    def figure(f: dict, name: str) -> str:
        v, (lo, hi) = f[name]["value"], f[name]["ci95"]
        if v is None:
            return f"{name} -"
        ci = "" if lo is None else f" ({lo:.2f}-{hi:.2f})"
        return f"{name} {v:.3f}{ci}"

    c = r["confusion"]
    print(f"trials {r['n']} ({r['grasps']} grasps); real success rate {r['real_success_rate']:.3f}")
    print("  " + ", ".join(figure(r, k) for k in ("accuracy", "precision", "recall", "f1")))
    print(
        f"  confusion: tp {c['tp']}, fp {c['fp']}, fn {c['fn']}, tn {c['tn']} (95 % intervals: "
        "a bootstrap over grasps)"
    )
    for name, f in r["per_object"].items():
        print(f"  {name}: n {f['n']}, " + ", ".join(figure(f, k) for k in ("accuracy", "f1")))
    checks = r["checks"]
    if checks["rejected_trials"]:
        why = "; ".join(
            f"{v['trials']} {k} ({v['held_on_the_robot']} held)"
            for k, v in checks["by_reason"].items()
        )
        print(
            f"  rejected by the checks: {checks['rejected_trials']} trials, "
            f"{checks['rejected_that_held']} of them held on the robot: {why}"
        )
    if out:
        print(f"results in {out}/ (validation.json, trials.parquet)")


def print_summary(s: dict, out, total_s: float | None = None, traced: bool = True) -> None:
    """The evaluate summary's lines; total_s: the process's time so far, when known;
    traced: whether the run wrote traces.parquet (not with --traces 0)."""
    from mjx_pick.core.metrics import label_check_rows, rate_text
    from mjx_pick.kernels.types import SUCCESS

    rows = [
        ("object / gripper", f"{s['object']} / {s['gripper']}"),
        ("backend / device", f"{s['backend']} / {s['device']}"),
        ("pick-points", f"{s['n']} (candidates checked {s['candidates_checked']})"),
        ("success rate", rate_text(s["successes"], s["n"])),
        ("diverged", f"{s['diverged']}"),
        (
            "score mean / median",
            f"{s['score_mean']:.3f} / {s['score_quantiles'].get('p50', float('nan')):.3f}",
        ),
        (
            "failures",
            ", ".join(f"{k} {v}" for k, v in s["failures"].items() if v and k != SUCCESS) or "none",
        ),
        ("F_Gmin, eq. (1)", f"{s['f_gmin_n']:.3f} N (F_d = {s['grip_force_n']:g} N)"),
        ("compile / run", f"{s['compile_s']:.1f} s / {s['run_s']:.1f} s"),
    ]
    if s.get("time_s"):
        parts = ", ".join(f"{k} {v:.1f}" for k, v in s["time_s"].items())
        whole = f" (process {total_s:.1f} s)" if total_s is not None else ""
        rows.append(("time, s", parts + whole))
    rows += [
        ("pick-points per s", f"{s['picks_per_s']}"),
    ]
    rows += label_check_rows(s)
    cluster = s.get("cluster")
    if cluster:
        nodes = ", ".join(f"{k} {v['picks_per_s']:g}/s" for k, v in cluster["nodes"].items())
        rows.append(("cluster, per node", nodes or "-"))
        rows.append(("cluster, in all", f"{cluster['picks_per_s']} pick-points/s"))
        if cluster["chunks_rerun"]:
            rows.append(("chunks re-run", f"{cluster['chunks_rerun']} (an actor died)"))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    if out:
        files = ["results.parquet", "summary.json", "config.json"] + ["traces.parquet"] * traced
        print(f"results in {out}/ ({', '.join(files)})")


def cmd_picks(args) -> int:
    from mjx_pick.core.pickpoints import rejected_text
    from mjx_pick.studies.pickfiles import write_picks

    obj, gripper = objects(args)
    picks = write_picks(
        obj,
        gripper,
        args.n,
        seed=args.seed,
        config=pick_config(args),
        out=args.out,
        overwrite=args.overwrite,
    )
    print(
        f"{len(picks)} feasible pick-points of {picks.n_candidates} candidates; rejected: "
        f"{rejected_text(picks.rejected)}; written to {args.out}/ (picks.csv, pick_0.png, "
        "candidates.png)"
    )
    return 0


def cmd_presets(_args) -> int:
    from mjx_pick.core.gripper import load_gripper, preset_names

    for name in preset_names():
        g = load_gripper(name)
        print(
            f"{name:<16} stroke {g.stroke_mm:g} mm, finger {g.finger_width_mm:g} x "
            f"{g.finger_depth_mm:g} mm, force {g.force_min_n:g}-{g.force_max_n:g} N, "
            f"speed {g.speed_min_mm_s:g}-{g.speed_max_mm_s:g} mm/s"
        )
    return 0


_PARAM_SECTIONS = {
    "contact": "contact parameters (ContactParams; --contact FILE, --pad-friction, ...)",
    "grasp": "the pick procedure (GraspConfig; --grasp FILE, --grip-force-n, ...)",
    "gripper": "gripper geometry and ranges (GripperSpec; --gripper-file FILE)",
    "solver": "MuJoCo solver settings (SolverParams; --solver FILE, --timestep-s)",
    "picks": "pick-point generation (PickConfig; --safety-zone-mm, --min-coverage): "
    "set per run, not swept",
}


def cmd_params(args) -> int:
    from mjx_pick.studies.sweeps import describe_params

    rows = describe_params(args.prefix or "")
    for r in rows:
        d = r["default"]
        r["default"] = "none" if d is None else str(d) if isinstance(d, int) else f"{d:g}"
        if r["aliases"]:
            r["meaning"] += f" (alias: {', '.join(r['aliases'])})"
    keys = ("name", "default", "unit", "range")
    width = {k: max(len(k), *(len(str(r[k])) for r in rows)) for k in keys}
    print("sweep: --param NAME=LO:HI:N (grid), NAME=A,B,C (list), NAME=LO:HI (random)")
    section = None
    for r in rows:
        if r["name"].partition(".")[0] != section:
            section = r["name"].partition(".")[0]
            print(f"\n{section}: {_PARAM_SECTIONS[section]}")
            print("  " + "  ".join(f"{k:<{width[k]}}" for k in keys) + "  meaning")
        cells = "  ".join(f"{str(r[k]):<{width[k]}}" for k in keys)
        print(f"  {cells}  {r['meaning']}")
    return 0


def cmd_assets(_args) -> int:
    from mjx_pick.core.objects import asset_manifest

    for name, entry in sorted(asset_manifest().items()):
        print(
            f"{name:<12} {entry['description']} ({entry['thickness_mm']:g} mm, "
            f"{entry['mass_g']:.1f} g)"
        )
    return 0


def cmd_cache_info(_args) -> int:
    from mjx_pick.core import cache

    s = cache.info()
    mb = 2.0**20
    o, c = s["objects"], s["compiled"]
    state = "on" if s["enabled"] else f"off ({cache.ENV_SWITCH}={os.environ[cache.ENV_SWITCH]})"
    print(f"folder            {s['folder']} ({state})")
    print(
        f"object results    {o['entries']} entries, {o['bytes'] / mb:.1f} MB of "
        f"{o['limit_bytes'] / mb:.0f} MB (least recently used evicted beyond)"
    )
    print(
        f"compiled programs {c['files']} files, {c['bytes'] / mb:.1f} MB of "
        f"{c['limit_bytes'] / mb:.0f} MB (JAX's persistent compilation cache)"
    )
    print(
        f"move it: {cache.ENV_DIR}=FOLDER; size: {cache.ENV_MAX_MB}=MB (now "
        f"{s['limit_bytes'] / mb:.0f}); bypass: --no-cache or {cache.ENV_SWITCH}=0; "
        "empty it: mjx-pick cache clear"
    )
    return 0


def cmd_cache_clear(_args) -> int:
    from mjx_pick.core import cache

    done = cache.clear()
    print(
        f"cleared {cache.root()}: {done['objects']} object results, "
        f"{done['compiled_files']} compiled-program files ({done['compiled_bytes'] / 2**20:.1f} MB)"
    )
    return 0


def cmd_view(args) -> int:
    from mjx_pick.outputs.reporting.viewer import view

    view(args.run, args.pick, speed=args.speed, loop=args.loop)
    return 0


def cmd_gui(args) -> int:
    from mjx_pick import gui

    problem = gui.missing_framework()
    if problem:
        raise ConfigError(problem)
    if not 0 <= args.port <= 65535:
        raise ConfigError(f"--port {args.port}: allowed 0-65535")
    if not gui.is_loopback(args.host):
        print(
            f"mjx-pick gui: warning: listening on {args.host}: anyone who reaches this "
            "machine can use the GUI and read and write its work folder",
            file=sys.stderr,
        )
    busy = gui.port_problem(args.host, args.port)  # port 0: can the interface be used?
    if busy:
        raise ConfigError(f"--host {args.host} --port {args.port}: {busy}")
    port = args.port or gui.free_port(args.host)
    shown = "127.0.0.1" if args.host in ("0.0.0.0", "::") else args.host
    print(f"mjx-pick gui: http://{shown}:{port}/ (work folder {args.workdir}; Ctrl-C stops)")
    sys.stdout.flush()
    gui.serve(args.host, port, args.workdir, show=not args.no_browser and gui.has_browser())
    return 0


# ---------------------------------------------------------------------------- trials


def _print_notes(notes) -> None:
    for note in notes:
        print(f"  note: {note}")


def _print_agreement(label: str, a: dict) -> None:
    c = a["confusion"]
    lo, hi = a["accuracy_ci"]
    print(
        f"{label}: {a['correct']}/{a['pick_points']} pick-points agree "
        f"({a['accuracy']:.0%}, 95 % {lo:.0%}-{hi:.0%}; always '{a['baseline']['predict']}' "
        f"gets {a['baseline']['correct']})"
    )
    print("                      real success  real failure")
    print(
        f"  simulated success   {c['sim_success_real_success']:>12}  "
        f"{c['sim_success_real_failure']:>12}"
    )
    print(
        f"  simulated failure   {c['sim_failure_real_success']:>12}  "
        f"{c['sim_failure_real_failure']:>12}"
    )


def _print_round(rnd: dict) -> None:
    rows = [
        {
            "page": p["page"],
            "pick_id": p["pick_id"],
            "sim": "success" if p["sim_success"] else p["sim_failure"],
            "bits": p["info_bits"],
            "why": p["why"],
        }
        for p in rnd["picks"]
    ]
    _print_rows(rows, ["page", "pick_id", "sim", "bits", "why"])
    _print_notes(rnd["notes"])


def cmd_trials_plan(args) -> int:
    from mjx_pick.cli.inputs import object_of
    from mjx_pick.studies.calibration.trials import loop as trials

    plan = trials.plan(
        args.run,
        object_of(args),
        args.out,
        n=args.n,
        repeats=args.repeats,
        params=args.params,
        bounds=name_ranges(args.bounds, "--bounds"),
        priors=name_ranges(args.prior, "--prior"),
        draws=args.draws,
        placements=args.placements,
        jitter_mm=args.jitter_mm,
        jitter_deg=args.jitter_deg,
        pool=args.pool,
        info_share=args.info_share,
        seed=args.seed,
        blind=args.blind,
        paper=args.paper,
        backend=args.backend,
        batch_size=args.batch_size,
        overwrite=args.overwrite,
    )
    rnd = plan["rounds"][0]
    _print_round(rnd)
    print(
        f"{rnd['simulations']} simulations. Print {args.out}/templates_round1.pdf at actual "
        f"size; try each page {args.repeats} times; write the successes in "
        f"{args.out}/trials.csv (or: mjx-pick trials record {shell_word(args.out)})"
    )
    return 0


def cmd_trials_record(args) -> int:
    from mjx_pick.studies.calibration.trials import loop as trials

    if not sys.stdin.isatty():
        raise ConfigError(
            f"trials record asks at a terminal and stdin is not one: fill the successes "
            f"column of {args.trials}/trials.csv in an editor instead"
        )
    done = trials.record(args.trials, input)
    print(
        f"recorded {done['filled']} row(s), skipped {done['skipped']}; {done['left']} left "
        f"untried in {args.trials}/trials.csv"
    )
    return 0


def cmd_trials_agree(args) -> int:
    from mjx_pick.studies.calibration.trials import loop as trials

    res = trials.agree(args.trials, partial=args.partial)
    _print_agreement("simulation vs reality", res["overall"])
    _print_notes(res["overall"]["notes"])
    if len(res["by_round"]) > 1:
        for r, a in res["by_round"].items():
            print(
                f"  round {r} (predicted by {a['planned_with']}): {a['correct']}/"
                f"{a['pick_points']}, 95 % {a['accuracy_ci'][0]:.0%}-{a['accuracy_ci'][1]:.0%}"
            )
    print(f"details in {args.trials}/agreement.md (and .json); outcomes.csv feeds calibrate")
    return 0


def cmd_trials_fit(args) -> int:
    from mjx_pick.cli.inputs import object_of
    from mjx_pick.studies.calibration.trials import loop as trials

    obj = object_of(args)

    def log(entry):
        if entry["step"] % args.log_every == 0:
            values = ", ".join(f"{k} {v:.4g}" for k, v in entry["values"].items())
            print(f"step {entry['step']:4d}  best loss {entry['best_loss']:.4f}  {values}")

    res = trials.fit(
        args.trials,
        obj,
        args.params,
        bounds=name_ranges(args.bounds, "--bounds") or None,
        priors=name_ranges(args.prior, "--prior") or None,
        partial=args.partial,
        steps=args.steps,
        estimator=args.estimator,
        seed=args.seed,
        identify=not args.no_identify,
        temperature_mm=args.temperature_mm,
        next_n=args.next,
        paper=args.paper,
        backend=args.backend,
        overwrite=args.overwrite,
        resume=args.resume,
        log=log,
    )
    fit = res.result
    for name, value in fit.values.items():
        flag = "  NOT identified: kept at its start" if name in fit.not_identified else ""
        print(f"{name}: {fit.initial[name]:.4g} -> {value:.4g}{flag}")
    _print_agreement("before (the run's parameters)", res.before)
    _print_agreement("after (the fitted parameters)", res.after)
    if res.report["at_optimum"]:
        _print_agreement(
            "at the fit's optimum (not used: not identified)", res.report["at_optimum"]
        )
    _print_notes(res.notes)
    print(f"fit in {res.out_dir}/ (contact.toml, agreement.md, report.md)")
    if res.next_round is not None:
        r = res.next_round["round"]
        print(
            f"round {r} (predicted with the fitted parameters): "
            f"{len(res.next_round['picks'])} pick-points added to {args.trials}/trials.csv; "
            f"print {args.trials}/templates_round{r}.pdf"
        )
        _print_round(res.next_round)
    return 0
