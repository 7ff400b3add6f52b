"""Evaluate pick-points end to end: object + gripper -> pick-points -> simulation -> results.

Details: docs/studies.md (studies/evaluation.py).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa

from mjx_pick.core import numbers
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import (
    ConfigError,
    check_range,
    to_dict,
    write_atomic,
    write_json,
    write_parquet,
)
from mjx_pick.core.gripper import GripperSpec, load_gripper
from mjx_pick.core.metrics import summarize
from mjx_pick.core.objects import ObjectModel, load_object
from mjx_pick.core.physics import ContactParams, SolverParams
from mjx_pick.core.procedure import GraspConfig, check_clearance, min_grasp_force_n
from mjx_pick.core.scene import Scene
from mjx_pick.core.settings import Settings
from mjx_pick.engine import interrupts
from mjx_pick.engine.chunks import ChunkStore
from mjx_pick.engine.devices import checks_device
from mjx_pick.engine.inputs import scene_of
from mjx_pick.engine.registry import AUTO
from mjx_pick.engine.runner import (
    Cancelled,
    Runner,
    auto_chunk,
    chunk_name,
    read_chunk,
    run_chunks,
)
from mjx_pick.engine.simulator import Simulator, showing_progress
from mjx_pick.kernels import types as kt
from mjx_pick.outputs.progress import ProgressBar
from mjx_pick.outputs.rundir import (
    claim,
    config_hash,
    fail,
    finish,
    read_manifest,
    release,
    versions,
)
from mjx_pick.studies.grasp_sources import ANTIPODAL, TOPDOWN, draw_grasps, source_key
from mjx_pick.studies.options import RunOptions, split_fields
from mjx_pick.studies.pickfiles import read_picks_csv
from mjx_pick.studies.robust import min_grip_force


@dataclasses.dataclass
class Evaluation:
    """What an evaluation produced (also written to out_dir when one was given)."""

    table: pa.Table
    summary: dict
    config: dict
    traces: pa.Table | None
    out_dir: Path | None
    # resume found the run already complete: read back, nothing simulated
    already_complete: bool = False


def user_picks(
    obj: ObjectModel,
    gripper: GripperSpec,
    x,
    y,
    yaw,
    config=None,
    grasp=None,
    skip_infeasible: bool = False,
    pick_id=None,
    line=None,
) -> pp.GraspBatch:
    """Check user pick-points. Infeasible ones are an error naming them and the reasons,
    or, with skip_infeasible, left out with a warning that names them. pick_id: each
    point's id (default: its index), kept through to the results so that they map back
    to the user's rows; line: each one's line in the user's file (for messages)."""
    checker = pp.FeasibilityChecker(obj, gripper, config, grasp)
    ids = np.arange(len(x)) if pick_id is None else np.asarray(pick_id, np.int64)
    res = checker(x, y, yaw)
    bad = np.flatnonzero(res["reason"] != 0)
    if len(bad):
        shown = ", ".join(
            f"pick_id {ids[i]}"
            + ("" if line is None else f" (line {line[i]})")
            + f": {pp.REASONS[res['reason'][i]]}"
            for i in bad[:8]
        )
        message = (
            f"{len(bad)} of {len(x)} pick-points are infeasible for {gripper.name}: {shown}"
            + (" ..." if len(bad) > 8 else "")
        )
        if not skip_infeasible or len(bad) == len(x):
            hint = "" if skip_infeasible else " (--skip-infeasible leaves them out)"
            raise ConfigError(message + hint)
        warnings.warn(message + "; left out", stacklevel=2)
    return checker.batch(ids, x, y, yaw, mode="user")


def _resolve(obj, gripper) -> tuple[ObjectModel, GripperSpec]:
    if not isinstance(obj, ObjectModel):
        obj = load_object(obj)
    if not isinstance(gripper, GripperSpec):
        gripper = load_gripper(gripper)
    return obj, gripper


@dataclasses.dataclass(frozen=True)
class EvaluateRequest:
    """What :func:`evaluate` computes (how it runs: ``options.RunOptions``).

    Attributes:
      picks: a GraspBatch or a CSV path (x_mm, y_mm, yaw_deg) instead of generating n.
      contact, solver, grasp: settings (None: the paper's; a grasp left None is fitted
        to the gripper's ranges, ``GraspConfig.fitted_to``).
      n_traces: traces kept for the n best and n worst pick-points.
      until, min_score, max_n: Optimization mode: simulate batches until `until`
        pick-points reach min_score or max_n are spent (resumable: batch j is chunk j).
      min_force: add each pick-point's smallest successful F_d within the gripper's
        force range (a batched bisection, ``robust.min_grip_force``).
      stability_um: > 0: simulate every pick-point again with the object moved this far
        along x (at most 100 um) and add success_shifted, score_shifted, label_stable
        (docs/physics.md, "Labels decided by a hair").
      step_check: simulate every pick-point again at half the time step and add
        success_half_step, label_converged.
      skip_infeasible: leave infeasible rows of a picks CSV out (with a warning naming
        them) instead of refusing the file.

    Where the grasps come from when picks is None is the run options' (``RunOptions``:
    grasps, antipodal, depth_mm).
    """

    picks: pp.GraspBatch | str | Path | None = None
    contact: ContactParams | None = None
    solver: SolverParams | None = None
    grasp: GraspConfig | None = None
    n_traces: int = 3
    until: int | None = None
    min_score: float = 0.9
    max_n: int | None = None
    min_force: bool = False
    stability_um: float = 0.0
    step_check: bool = False
    skip_infeasible: bool = False


def evaluate(
    obj: ObjectModel | str,
    gripper: GripperSpec | str = "robotiq-2f85",
    options: RunOptions | None = None,
    *,
    request: EvaluateRequest | None = None,
    simulator: Simulator | None = None,
    **fields,
) -> Evaluation:
    """Simulate pick-points of an object with a gripper; see the module docstring.

    Args:
      obj: an ObjectModel, a shipped asset name, or an image/mesh path (see load_object).
      gripper: a GripperSpec, a preset name or a gripper TOML path.
      options: how it runs (``options.RunOptions``: n, default 1000; seed, backend,
        out, resume, chunk_size, cancel, ...).
      request: what it computes (:class:`EvaluateRequest`: picks, settings, traces,
        Optimization mode, extra checks).
      simulator: run on this simulator of obj (its object, runner and backend), left
        open: the scenes and backends it keeps serve later calls (a warm process,
        ``studies.session.Session``). None: a runner of this call's own, closed when it
        ends.
      fields: fields of either, by name (a keyword overrides the same field given in
        options or request).
    """
    req, opts = split_fields(EvaluateRequest, request, options, fields)
    _refuse_unused(req, opts)  # before n takes its default
    opts = dataclasses.replace(opts, n=opts.n_or(1000), pick_config=opts.picks)
    t_object, given = time.perf_counter(), isinstance(obj, ObjectModel)
    obj, gripper = _resolve(obj, gripper)
    fixed_costs = dict(opts.fixed_costs or {})
    if not given and "object_s" not in fixed_costs:  # prepared here: a cost of this run
        fixed_costs["object_s"] = time.perf_counter() - t_object
    req = _numbers(req)
    settings = _settings(gripper, req)
    _check(obj, settings, req, opts)
    if simulator is not None:
        _check_simulator(simulator, obj, opts)
    user_batch = _user_batch(obj, settings, req, opts)
    t_scene = time.perf_counter()
    if simulator is None:
        scene, runner = scene_of(obj, settings), _runner(opts)
    else:
        scene, runner = simulator.exact_scene(settings), simulator.runner
    kept = runner.cancel, runner.since
    if simulator is not None:  # this call's cancel event and timing, on the caller's runner
        runner.cancel, runner.since = opts.cancel, runner.timing
    compiled = runner.timing.compile_s
    try:
        if simulator is None:
            made = runner.make(scene, settings.grasp)
            chunks = runner.chunks(made, settings.grasp)
        else:  # the backend of settings' program, built by an earlier call or now
            made, chunks = simulator.backend(settings), simulator.chunks(settings)
        # the run's fixed costs, seconds: filled in as they are paid (summary "time_s");
        # scene: the MjModel and the backend that holds it, less what the backend counted
        # as compile time while it was made (a Warp backend's buffer sizing, its kernels)
        costs = {k: float(v) for k, v in fixed_costs.items()}
        made_compile = runner.timing.compile_s - compiled
        costs["scene_s"] = time.perf_counter() - t_scene - made_compile
        ctx = _Context(chunks, runner, made, scene, costs, user_batch, simulator)
        return _evaluate(ctx, _Request(obj, settings, req, opts))
    finally:
        runner.cancel, runner.since = kept
        if simulator is None:
            runner.close()


def _check_simulator(simulator: Simulator, obj: ObjectModel, opts: RunOptions) -> None:
    """A run on a caller's simulator: of this object, on its backend and batch size, in
    this process (ConfigError naming what differs)."""
    if simulator.object is not obj:
        raise ConfigError(
            f"the simulator simulates {simulator.object.name!r}, not {obj.name!r}: give its "
            "object (simulator.object) or a simulator of this one"
        )
    wanted = {"backend": (opts.backend, AUTO), "batch_size": (opts.batch_size, None)}
    for name, (value, default) in wanted.items():
        own = getattr(simulator.runner, "backend_name" if name == "backend" else name)
        if value != default and value != own:
            raise ConfigError(
                f"{name} = {value!r}: this run's simulator runs {name} {own!r}; leave "
                f"{name} out, or run on a simulator (a Session) made with {name} {value!r}"
            )
    if opts.ray is not None:
        raise ConfigError(
            "ray: a run on a simulator of this process (a Session) does not run on a Ray "
            "cluster; leave out ray, or evaluate without a simulator"
        )


def _refuse_unused(req: EvaluateRequest, opts: RunOptions) -> None:
    """Refuse a combination whose one part the run would ignore: n with given
    pick-points (their rows are the run) or in Optimization mode (until and max_n
    decide its size), given pick-points in Optimization mode (it draws its own until
    `until` reach min_score), max_n without until, skip_infeasible without a picks
    file (each named as the CLI's flag)."""
    given = req.picks is not None
    what = "the pick-points given (--picks)"
    problems = []
    if given and opts.n is not None:
        problems.append(f"--n {opts.n} with {what}: the run is their rows; leave out --n")
    elif req.until is not None and opts.n is not None:
        problems.append(
            f"--n {opts.n} with --until {req.until}: Optimization mode simulates until "
            f"{req.until} pick-points reach --min-score, at most --max; leave out --n"
        )
    if given and req.until is not None:
        problems.append(
            f"--until {req.until} (Optimization mode) draws its own pick-points until "
            f"{req.until} reach --min-score: it cannot take {what}; leave out one of them"
        )
    if req.max_n is not None and req.until is None:
        problems.append(f"--max {req.max_n} bounds Optimization mode only: give --until K too")
    if req.skip_infeasible and not isinstance(req.picks, str | Path):
        problems.append("--skip-infeasible applies to a picks file (--picks FILE) only")
    if len(problems) == 1:
        raise ConfigError(problems[0])
    if problems:
        raise ConfigError(f"{len(problems)} problems: " + "; ".join(problems))


def _numbers(req: EvaluateRequest) -> EvaluateRequest:
    """The request's numbers checked (``core.numbers``: a ConfigError naming the input,
    the value and what is allowed), whole ones as ints (RunOptions checks its own)."""
    check, optional = numbers.check, numbers.check_optional
    return dataclasses.replace(
        req,
        n_traces=check("n_traces", req.n_traces),
        min_score=check("min_score", req.min_score),
        stability_um=check("stability_um", req.stability_um),
        until=optional("until", req.until),
        max_n=optional("max_n", req.max_n),
    )


def _settings(gripper: GripperSpec, req: EvaluateRequest) -> Settings:
    """The run's settings: the request's on gripper, a procedure left unset fitted to
    the gripper's ranges (with a warning saying what moved)."""
    keep = () if req.grasp is None else [f.name for f in dataclasses.fields(GraspConfig)]
    return settings_on(gripper, req.contact, req.solver, req.grasp, keep)


def settings_on(gripper: GripperSpec, contact, solver, grasp, keep) -> Settings:
    """Settings of contact, solver and grasp (None: the defaults) on gripper, the
    procedure's fields but keep fitted to the gripper's ranges (``Settings.on_gripper``),
    with a warning saying what moved."""
    settings, note = Settings(
        contact=contact or ContactParams(),
        solver=solver or SolverParams(),
        grasp=grasp or GraspConfig(),
    ).on_gripper(gripper, keep)
    if note:
        warnings.warn(note, stacklevel=4)
    return settings


def _check(obj: ObjectModel, settings: Settings, req: EvaluateRequest, opts: RunOptions) -> None:
    """Every check of the inputs that can fail before a scene, a runner or a folder."""
    settings.grasp.check_gripper(settings.gripper)
    check_clearance(obj, settings.grasp)
    source = opts.grasps  # checked with the options (RunOptions)
    if source != TOPDOWN:
        if req.picks is not None:
            raise ConfigError(
                f"give pick-points (--picks) or grasps = {source!r} (--grasps), not both"
            )
        if req.until is not None:
            raise ConfigError(
                "Optimization mode (--until) draws top-down pick-points: leave out --until, "
                f"or --grasps {source!r}"
            )
    else:
        pp.check_raster(obj, opts.pick_config)
    if source == TOPDOWN and not isinstance(req.picks, pp.GraspBatch):
        # a batch given was checked when drawn
        # a part wider than the stroke everywhere: refused now, not after a raster, a
        # scene and max_candidates draws that find no pick-point
        pp.check_stroke(obj, settings.gripper, opts.pick_config, settings.grasp)
    on_cluster = {"--min-force": req.min_force, "--stability-um": req.stability_um}
    on_cluster["--step-check"] = req.step_check
    for flag, wanted in on_cluster.items():
        if opts.ray is not None and wanted:
            raise ConfigError(
                f"{flag} does not run on a Ray cluster yet: leave out --ray or {flag}"
            )
    if req.step_check:
        half_step(settings.solver)  # a step that cannot be halved: refused now
    opts.check_resume()


def _user_batch(obj, settings: Settings, req: EvaluateRequest, opts: RunOptions):
    """The user's pick-points file, read and checked before a simulator or a folder is
    made (None: pick-points are drawn, or given as a GraspBatch)."""
    if req.picks is None or isinstance(req.picks, pp.GraspBatch) or req.until is not None:
        return None
    rows = read_picks_csv(req.picks)
    return user_picks(
        obj,
        settings.gripper,
        rows.x_mm,
        rows.y_mm,
        rows.yaw_deg,
        config=opts.pick_config,
        grasp=settings.grasp,
        skip_infeasible=req.skip_infeasible,
        pick_id=rows.pick_id,
        line=rows.line,
    )


def _runner(opts: RunOptions) -> Runner:
    """The run's runner: in this process, or on a Ray cluster's actors."""
    if opts.ray is None:
        chunk = opts.chunk_size or None
        return Runner(opts.backend, opts.batch_size, chunk_size=chunk, cancel=opts.cancel)
    from mjx_pick.engine.cluster import ray_runner

    return ray_runner(
        opts.ray, opts.backend, opts.batch_size, cancel=opts.cancel, on_event=opts.on_cluster_event
    )


@dataclasses.dataclass(frozen=True)
class _Request:
    """One evaluate() call once resolved and checked: the object, the settings, what it
    computes and how it runs (n and pick_config resolved): the one value its steps
    read."""

    obj: ObjectModel
    settings: Settings
    what: EvaluateRequest
    run: RunOptions


@dataclasses.dataclass
class _Context:
    """What one evaluate() call simulates with: its chunks (``Runner.chunks``: this
    process, or a Ray cluster's actors), the runner and its backend for the scene, the
    scene, the fixed costs paid so far (seconds, filled in as they are paid) and the
    user's checked pick-points (None unless read from a file)."""

    chunks: object
    runner: Runner
    backend: object
    scene: Scene
    costs: dict
    user_batch: pp.GraspBatch | None = None
    simulator: Simulator | None = None  # a caller's, kept open (a Session's)


def _evaluate(ctx: _Context, req: _Request) -> Evaluation:
    """evaluate() once its runner (this process, or a Ray cluster) is ready."""
    out_dir = Path(req.run.out) if req.run.out is not None else None
    settings = experiment_settings(ctx.scene, _key_settings(ctx, req))
    key = config_hash(settings)
    done = _complete_run(out_dir, key) if out_dir is not None and not req.run.overwrite else None
    if done is not None and req.run.resume:
        return done
    if done is not None:  # its chunks are gone: the chunk store would no longer see it
        raise ConfigError(
            f"{out_dir} holds this run, complete: pass --resume to read it back, choose "
            "another --out, or pass --overwrite to run it again"
        )
    # every input is checked before the folder is claimed: a bad one leaves it as it was
    t_picks = time.perf_counter()
    req, picks_batch = _picks(ctx, req)
    ctx.costs["picks_s"] = time.perf_counter() - t_picks  # sampling and the feasibility checks
    if out_dir is not None:  # before any simulation: a folder it may not use is refused now
        run = req.run
        claim(
            out_dir, "evaluate", key, resume=run.resume, overwrite=run.overwrite, settings=settings
        )
    try:
        return _evaluate_claimed(ctx, req, picks_batch, out_dir, key)
    except (KeyboardInterrupt, Cancelled):
        raise  # the folder is marked by _stopped
    except BaseException as err:
        if out_dir is not None:  # never left "running": the next run replaces it
            fail(out_dir, err, command="evaluate")
        raise


def _key_settings(ctx: _Context, req: _Request) -> dict:
    """What decides the run's results (``experiment_key`` hashes it with the scene)."""
    s, what, run = req.settings, req.what, req.run
    return {
        "gripper": s.gripper,
        "contact": s.contact,
        "solver": s.solver,
        "grasp": s.grasp,
        "picks": run.pick_config,
        "source": _picks_source(what.picks),
        **_grasps_source(run),
        "n": run.n
        if what.picks is None and what.until is None and run.grasps in (TOPDOWN, ANTIPODAL)
        else None,
        "seed": run.seed,
        "until": what.until,
        "min_score": what.min_score if what.until is not None else None,
        "max_n": what.max_n,
        "min_force": what.min_force,
        "stability_um": what.stability_um,
        "step_check": what.step_check,
        "backend": ctx.chunks.name,
        # a batched program's float32 rounding depends on its batch shape, on the C
        # engine too (its per-tick kernel: engine module docstring)
        "batch_size": ctx.chunks.batch_size,
    }


def _picks(ctx: _Context, req: _Request):
    """(req, the pick-points of the main run): drawn, given, or the user's checked
    file; None in Optimization mode, whose max_n is then settled in req."""
    what, run, s = req.what, req.run, req.settings
    if what.until is not None:
        what = dataclasses.replace(what, max_n=what.max_n or 10 * what.until)
        check_range("evaluate", "max_n", what.max_n, what.until, 10**9)
        return dataclasses.replace(req, what=what), None
    if what.picks is None:
        batch = draw_grasps(
            req.obj,
            s,
            run.n,
            run.seed,
            run.pick_config,
            run.grasps,
            antipodal=run.antipodal,
            depth_mm=run.depth_mm,
            scene=ctx.scene,
            device=checks_device(ctx.backend),
        )
        return req, batch
    if isinstance(what.picks, pp.GraspBatch):
        return req, what.picks
    return req, ctx.user_batch  # read and checked before the scene was built


def _evaluate_claimed(
    ctx: _Context, req: _Request, picks_batch: pp.GraspBatch | None, out_dir: Path | None, key: str
) -> Evaluation:
    """evaluate() once its inputs are checked and its folder (if any) claimed."""
    store = ChunkStore(out_dir, key, req.run.resume) if out_dir is not None else None
    chunk = _chunk_size(ctx, req, picks_batch, store)
    config = _run_config(ctx, req, picks_batch, chunk, key)
    if out_dir is not None:
        write_json(out_dir / "config.json", config)
        write_atomic(out_dir / "scene.xml", ctx.scene.xml)

    t0 = time.perf_counter()
    try:
        if req.what.until is not None:
            picks_batch, table = _optimize(ctx, chunk, store, req)
            config["n"], config["mode"] = int(len(picks_batch)), picks_batch.mode
            if out_dir is not None:
                write_json(out_dir / "config.json", config)
        else:
            table = _simulate(
                ctx.chunks, picks_batch, chunk, store, req.run.progress, req.run.on_progress
            )
        summary = _run_summary(ctx, req, picks_batch, table, time.perf_counter() - t0)
        table = _extra_passes(ctx, req, picks_batch, table, summary)
        traces = (
            _traces(ctx.chunks, picks_batch, table, req.what.n_traces)
            if req.what.n_traces
            else None
        )
        interrupts.raise_if_requested()  # a Ctrl-C swallowed in the last chunk: not complete
    except (KeyboardInterrupt, Cancelled) as stop:
        _stopped(out_dir, stop, ctx.chunks, req.run.seed, config, time.perf_counter() - t0)
        raise
    t_write = time.perf_counter()
    if out_dir is not None:
        write_parquet(out_dir / "results.parquet", table)
        if traces is not None:
            write_parquet(out_dir / "traces.parquet", traces)
    ctx.costs["write_s"] = time.perf_counter() - t_write
    summary["time_s"] = _breakdown(ctx.costs, ctx.chunks.describe()["timing"])
    if out_dir is not None:
        write_json(out_dir / "summary.json", summary)
        meta = ctx.chunks.describe(time.perf_counter() - t0)
        meta["timing"]["breakdown_s"] = summary["time_s"]
        finish(
            out_dir,
            command="evaluate",
            config=config,
            seed=req.run.seed,
            release_lock=False,
            **meta,
        )
        if not req.run.keep_chunks:  # every row is in results.parquet now
            store.remove()
        release(out_dir)
    return Evaluation(table, summary, config, traces, out_dir)


def _chunk_size(
    ctx: _Context, req: _Request, picks_batch: pp.GraspBatch | None, store: ChunkStore | None
) -> int:
    """Pick-points per chunk: the store's when resuming (chunk k on disk keeps its
    meaning), else the user's, else Optimization mode's batch, free device memory's
    (this process) or one actor batch (a cluster) -- saved in the store before the
    first chunk is simulated."""
    if req.what.until is not None:
        batch = int(req.run.chunk_size or until_batch(req.what.until, ctx.chunks.batch_size))
        proposed = min(batch, req.what.max_n)
    elif req.run.chunk_size:
        proposed = int(req.run.chunk_size)
    elif ctx.runner.cluster is None:
        proposed = auto_chunk(ctx.backend)
    else:
        proposed = ctx.chunks.batch_size
    return store.chunk_size("evaluate", proposed) if store is not None else int(proposed)


def _run_config(
    ctx: _Context, req: _Request, picks_batch: pp.GraspBatch | None, chunk: int, key: str
) -> dict:
    """The run's configuration as config.json holds it: settings, MuJoCo's contact
    parameters, pick-points, backend, device, batch and chunk size, versions."""
    return {
        "object": req.obj.summary(),
        "gripper": to_dict(req.settings.gripper),
        "contact": to_dict(req.settings.contact),
        "contact_in_mujoco": to_dict(ctx.scene.contact),
        "scene": {
            # where the pads grip (GraspConfig.grasp_height) and their contact patch
            "fingertip_height_mm": round(ctx.scene.index.pad_bottom_z0_m * 1e3, 6),
            "pad_patch_mm": [round(v, 6) for v in ctx.scene.pad_patch_mm],
        },
        "solver": to_dict(req.settings.solver),
        "grasp": to_dict(req.settings.grasp),
        "picks": to_dict(req.run.pick_config),
        "n": int(len(picks_batch)) if picks_batch is not None else None,
        "seed": int(req.run.seed),
        "mode": picks_batch.mode if picks_batch is not None else "optimization",
        "backend": ctx.chunks.name,
        "device": ctx.chunks.device,
        "batch_size": int(ctx.chunks.batch_size),
        "chunk_size": int(chunk),
        "ray": getattr(ctx.chunks, "address", None),
        "config_key": key,
        "versions": versions(),
    }


def _run_summary(
    ctx: _Context, req: _Request, picks_batch: pp.GraspBatch, table: pa.Table, wall_s: float
) -> dict:
    """summary.json of the main run: counts and rates (``metrics.summarize``), eq. (1)'s
    F_Gmin (N), candidates, compile apart from run time (s), pick-points per second."""
    summary = summarize(table)
    mu = req.settings.contact.pad_friction
    timing = ctx.chunks.describe()["timing"]
    summary.update(
        {
            "object": req.obj.name,
            # a mesh's repair figures (ObjectModel.repair; None for a prism)
            "object_repair": req.obj.repair,
            "gripper": req.settings.gripper.name,
            "backend": ctx.chunks.name,
            "device": ctx.chunks.device,
            "f_gmin_n": min_grasp_force_n(req.obj, mu, req.settings.grasp.safety_factor),
            "grip_force_n": req.settings.grasp.grip_force_n,
            "candidates_checked": int(picks_batch.n_candidates),
            "rejected": dict(picks_batch.rejected),
            "compile_s": timing["compile_s"],
            "run_s": timing["run_s"],
            "wall_s": round(wall_s, 3),
            # per backend (per actor on a cluster): simulations over simulating time
            "picks_per_s": round(timing["simulations"] / timing["run_s"], 2)
            if timing["run_s"] > 0
            else None,
            "simulated_s_per_pick": round(req.settings.grasp.duration_s, 3),
            "physics_steps_per_pick": req.settings.grasp.n_ticks()
            * req.settings.grasp.substeps(req.settings.solver),
        }
    )
    if hasattr(ctx.chunks, "cluster_summary"):
        summary["cluster"] = ctx.chunks.cluster_summary()
    return summary


def _extra_passes(
    ctx: _Context, req: _Request, picks_batch: pp.GraspBatch, table: pa.Table, summary: dict
) -> pa.Table:
    """table with the columns of the extra passes asked for (minimum grip force, label
    stability, label convergence), their figures added to summary. They run through the
    run's own runner and backend (no new compile; the half time step's scene compiles
    its own program)."""
    if not (req.what.min_force or req.what.stability_um or req.what.step_check):
        return table
    settings = Settings(
        req.settings.gripper, req.settings.contact, req.settings.solver, req.settings.grasp
    )
    sim = ctx.simulator  # a caller's: its backend of settings' program is ctx.backend
    if sim is None:
        sim = Simulator(req.obj, runner=ctx.runner)
        sim.adopt(settings, ctx.backend)
    if req.what.min_force:
        t1 = time.perf_counter()
        with showing_progress(
            ctx.runner, "minimum grip force (bisection)", "sim", req.run.progress
        ):
            forces = min_grip_force(req.obj, picks_batch, settings, simulator=sim)
        table = table.append_column("min_force_n", pa.array(forces))
        # holding at the gripper's smallest force says only that the true minimum is at
        # or below it: flagged, never presented as the minimum itself
        at_floor = np.isfinite(forces) & (forces <= req.settings.gripper.force_min_n + 1e-9)
        table = table.append_column("min_force_at_floor", pa.array(at_floor))
        summary["min_force_at_floor"] = int(at_floor.sum())
        summary["min_force_s"] = round(time.perf_counter() - t1, 3)
        summary["min_force_n_median"] = (
            float(np.nanmedian(forces)) if np.isfinite(forces).any() else None
        )
    if req.what.stability_um:
        t1 = time.perf_counter()
        table = _stability(
            table, picks_batch, sim, settings, req.what.stability_um, req.run.progress
        )
        stable = table["label_stable"].to_numpy(zero_copy_only=False)
        summary["stability_um"] = req.what.stability_um
        summary["labels_unstable"] = int((~stable).sum())
        summary["stability_s"] = round(time.perf_counter() - t1, 3)
    if req.what.step_check:
        t1 = time.perf_counter()
        table = _step_check(table, picks_batch, sim, settings, req.run.progress)
        converged = table["label_converged"].to_numpy(zero_copy_only=False)
        summary["labels_unconverged"] = int((~converged).sum())
        summary["step_check_s"] = round(time.perf_counter() - t1, 3)
    return table


def _breakdown(costs: dict, timing: dict) -> dict:
    """The run's time by part, seconds, in the order a user waits for them: import (the
    caller's, when given), object (preparation: the caller's, or this call's), scene
    (model and backend, less the compile time counted while it was made), picks (sampling,
    feasibility), compile (device programs; C-engine batches), simulate (every
    simulation of the run: main, traces, extra passes) and write (results, traces)."""
    parts = {
        "import": costs.get("import_s"),
        "object": costs.get("object_s"),
        "scene": costs.get("scene_s"),
        "picks": costs.get("picks_s"),
        "compile": timing["compile_s"],
        "simulate": timing["run_s"],
        "write": costs.get("write_s"),
    }
    return {k: round(float(v), 3) for k, v in parts.items() if v is not None}


def until_batch(until: int, batch_size: int) -> int:
    """Optimization mode's pick-points per batch (chunk) by default: twice those asked
    for, rounded up to a power of two (a C-engine call of a size already compiled), at
    least 32 and at most the backend's batch -- a run that finds its `until` early
    stops early instead of simulating a whole device batch."""
    want = max(32, 1 << max(int(2 * until) - 1, 1).bit_length())
    return int(min(want, batch_size))


def half_step(solver: SolverParams) -> SolverParams:
    """solver at half its time step (the step check's), or a ConfigError naming the
    step that cannot be halved."""
    try:
        return dataclasses.replace(solver, timestep_s=solver.timestep_s / 2)
    except ConfigError as e:
        raise ConfigError(
            f"--step-check halves solver.timestep_s = {solver.timestep_s:g} s: {e}"
        ) from None


def _labels_again(sim: Simulator, settings, picks_batch, table) -> tuple[np.ndarray, np.ndarray]:
    """(success (n,) bool, score (n,)) of the table's pick-points simulated again as
    picks_batch (the same pick-points, perhaps moved) with settings, one batch through
    sim (the run's own runner)."""
    # the table's rows are the batch's pick-points in order (infeasible ones, if kept,
    # included)
    ids = table["pick_id"].to_numpy()
    if len(ids) != len(picks_batch) or not np.array_equal(ids, picks_batch.pick_id):
        raise RuntimeError("evaluate: the results table does not follow its pick-points")
    (res,) = sim.run([(settings, picks_batch)])
    return np.asarray(res["success"], bool), np.asarray(res["score"], float)


def _stability(table, picks_batch, sim: Simulator, settings, shift_um, progress):
    """table with success_shifted, score_shifted and label_stable: every simulated
    pick-point again with the object moved shift_um micrometres along x (one batch
    through sim, which runs on the run's own runner and backend)."""
    shifted = dataclasses.replace(picks_batch, x_mm=picks_batch.x_mm + shift_um * 1e-3)
    with showing_progress(sim.runner, "stability (pick-points moved)", "sim", progress):
        success, score = _labels_again(sim, settings, shifted, table)
    table = table.append_column("success_shifted", pa.array(success))
    table = table.append_column("score_shifted", pa.array(score))
    return table.append_column("label_stable", pa.array(_same_labels(table, success)))


def _step_check(table, picks_batch, sim: Simulator, settings, progress):
    """table with success_half_step and label_converged: every simulated pick-point
    again at half the time step (its own scene and program, through sim)."""
    half = dataclasses.replace(settings, solver=half_step(settings.solver))
    with showing_progress(sim.runner, "step check (half the time step)", "sim", progress):
        success, _ = _labels_again(sim, half, picks_batch, table)
    table = table.append_column("success_half_step", pa.array(success))
    return table.append_column("label_converged", pa.array(_same_labels(table, success)))


def _same_labels(table, success: np.ndarray) -> np.ndarray:
    """(n,) bool: the table's labels equal success, the same pick-points' labels again."""
    return success == table["success"].to_numpy(zero_copy_only=False).astype(bool)


def _complete_run(out_dir: Path, key: str) -> Evaluation | None:
    """The run in out_dir read back when it is a complete evaluate run of this
    experiment (resume then has nothing to do), else None."""
    import pyarrow.parquet as pq

    manifest = read_manifest(out_dir)
    need = [out_dir / n for n in ("results.parquet", "summary.json", "config.json")]
    if (
        manifest is None
        or manifest.get("command") != "evaluate"
        or manifest.get("config_key") != key
        or manifest.get("status") != "complete"
        or not all(p.is_file() for p in need)
    ):
        return None
    traces = out_dir / "traces.parquet"
    return Evaluation(
        pq.read_table(need[0]),
        json.loads(need[1].read_text()),
        json.loads(need[2].read_text()),
        pq.read_table(traces) if traces.is_file() else None,
        out_dir,
        already_complete=True,
    )


def _stopped(out_dir, stop: BaseException, chunks, seed, config, wall_s=None) -> None:
    """Mark a folder whose run stopped early; its finished chunks stay for --resume."""
    if out_dir is not None:
        status, message = interrupts.stop_status(stop)
        meta = chunks.describe(wall_s)
        finish(
            out_dir, status, command="evaluate", config=config, seed=seed, message=message, **meta
        )


def _picks_source(picks) -> str:
    """What the pick-points come from, for the output folder's configuration hash."""
    if picks is None:
        return "generated"
    if isinstance(picks, pp.GraspBatch):
        data = np.stack([picks.x_mm, picks.y_mm, picks.yaw_deg]).astype(np.float64)
        if not picks.is_pick_points:  # a grasp's pose and where it starts decide it too
            data = np.concatenate(
                [data, *(np.atleast_2d(np.asarray(a, float).T) for a in _pose_arrays(picks))]
            )
        return "batch:" + config_hash(data.tobytes().hex())
    path = Path(picks)
    return "csv:" + (config_hash(path.read_text()) if path.is_file() else str(path))


def _grasps_source(run: RunOptions) -> dict:
    """The grasp source's entries of the folder's configuration hash (none for top-down
    pick-points: their runs' keys as before; ``grasp_sources.source_key``)."""
    key = source_key(run)
    return {} if key is None else {"grasps": key}


def _pose_arrays(grasps: pp.GraspBatch) -> list[np.ndarray]:
    """The arrays that make grasps given as poses what they are beyond their planar part."""
    tilt = grasps.tilt_quat if grasps.tilt_quat is not None else np.zeros((len(grasps), 0))
    height = grasps.height_mm if grasps.height_mm is not None else np.zeros(0)
    return [tilt, height, grasps.opening_mm, grasps.gap_left_mm, grasps.gap_right_mm]


def _file_digest(path: str | Path) -> str:
    """sha256 of a file's bytes (a file the scene names: what it holds, not where)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def experiment_key(scene: Scene, settings: dict) -> str:
    """The resume key of an evaluate run: a hash of what decides its results.

    * the object's content: the simulated model (``scene.xml``: the object's meshes,
      mass and inertia, the gripper, contact and solver), with every file it names
      replaced by a digest of the file's bytes, and the silhouette the pick-points are
      checked against (``ObjectModel.summary`` less its ``source`` path);
    * settings: gripper (an MJCF gripper's file by its digest), physics, procedure,
      pick-point source and configuration, seed, mode, backend and batch size (the
      rounding of a batched program depends on its shape) -- JSON-able values or
      dataclasses.

    Never where anything is installed (the same asset read from a checkout and from
    site-packages gives the same key) nor the chunk size (derived from free device
    memory; a resumed run keeps the one on disk, ``engine.chunks.ChunkStore``).
    """
    return config_hash(experiment_settings(scene, settings))


def experiment_settings(scene: Scene, settings: dict) -> dict:
    """What :func:`experiment_key` hashes, as JSON-able values (the output folder's
    manifest records them, so that a refusal names each setting that changed)."""
    xml = scene.portable_xml()
    obj = {k: v for k, v in scene.object.summary().items() if k != "source"}
    values = {k: to_dict(v) for k, v in settings.items()}
    mjcf = (values.get("gripper") or {}).get("mjcf")
    # a model file by its content, wherever it is installed (a URDF: also its table's)
    for table in (mjcf, (mjcf or {}).get("urdf")):
        if table and table.get("file"):
            file = Path(table["file"])
            table["file"] = f"sha256:{_file_digest(file)}" if file.is_file() else file.name
    return {"model": xml, "object": obj, **values}


def _simulate(chunks, picks, chunk: int, store, bar: bool, on_progress):
    """The main run, chunk by chunk (``runner.run_chunks``), with a progress bar if asked
    (``progress.ProgressBar``, on stderr): pick-points, chunks done and, on a cluster,
    pick-points/s per node and in all."""
    if not bar:
        return run_chunks(chunks, picks, chunk, store, on_progress)
    chunks_done = [0]
    n_chunks = max(1, -(-len(picks) // chunk))
    note = getattr(chunks, "progress_note", None)
    desc = f"simulating ({chunks.name})"
    with ProgressBar(desc, "pick", total=len(picks)) as pbar:

        def chunk_done(result) -> None:
            chunks_done[0] += 1
            text = f"chunks {chunks_done[0]}/{n_chunks} this run"
            if note is not None:
                text += f"; {note()}"
            pbar.note(text)

        def report(done: int, total: int) -> None:
            pbar(done, total)
            if on_progress is not None:
                on_progress(done, total)

        return run_chunks(chunks, picks, chunk, store, report, on_chunk=chunk_done)


def _optimize(ctx: _Context, chunk: int, store: ChunkStore | None, req: _Request):
    """Optimization mode: batches of chunk pick-points until req.what.until reach
    req.what.min_score or req.what.max_n are spent; (GraspBatch, results table of every simulated
    pick). The candidates are checked where ``checks_device`` says for ctx's backend.

    Batch j is chunk j of the run (the batches depend only on the seed and the batch
    size, never on results): a resumed run reads the chunks in its store and simulates
    from the first one missing, so it stops exactly where an uninterrupted run stops.
    """
    tables: list = []

    def score_fn(b: pp.GraspBatch) -> np.ndarray:
        j = len(tables)
        table = read_chunk(store, j, b)
        if table is None:
            for result in ctx.chunks.run({j: b}):
                table = result.table
            if store is not None:
                store.write(chunk_name(j), table)
        tables.append(table)
        score = np.asarray(table["score"], float)
        return np.where(np.asarray(table["success"]), np.nan_to_num(score, nan=-1.0), -1.0)

    res = pp.optimize(
        req.obj,
        req.settings.gripper,
        score_fn,
        k=req.what.until,
        min_score=req.what.min_score,
        max_n=req.what.max_n,
        batch_size=chunk,
        seed=req.run.seed,
        config=req.run.pick_config,
        grasp=req.settings.grasp,
        device=checks_device(ctx.backend),
    )
    return res.picks, pa.concat_tables(tables)


def _traces(chunks, picks: pp.GraspBatch, table: pa.Table, n: int):
    """Re-simulate the n best and n worst pick-points with recording on."""
    score = np.asarray(table["score"], float)
    order = np.argsort(np.where(np.isnan(score), -np.inf, score))
    chosen = np.unique(np.concatenate([order[::-1][:n], order[:n]]))
    if len(chosen) == 0:
        return None
    sub = picks.take(chosen)
    rows = chunks.record(sub)
    n_pick, n_tick, _ = rows.shape
    cols = {"pick_id": np.repeat(sub.pick_id, n_tick)}
    for j, name in enumerate(kt.TRACE_FIELDS):
        cols[name] = rows[:, :, j].reshape(-1)
    cols["phase"] = np.asarray(kt.PHASES, dtype=object)[cols["phase"].astype(int)]
    cols["rank"] = np.repeat(np.where(np.isin(chosen, order[::-1][:n]), "best", "worst"), n_tick)
    return pa.table(cols)
