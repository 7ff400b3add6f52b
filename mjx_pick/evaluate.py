"""Evaluate pick-points end to end: object + gripper -> pick-points -> simulation -> results.

``evaluate`` is the Python form of ``mjx-pick evaluate``. With ``out`` it writes:

* ``config.json``  the merged configuration, versions, backend, device and seed;
* ``scene.xml``    the MuJoCo model that was simulated;
* ``results.parquet`` one row per pick-point (``mjx_pick.metrics.COLUMNS``);
* ``summary.json`` counts, success rate, score quantiles, failure reasons, eq. (1)'s
  F_Gmin, pick-points per second, compile time apart from run time;
* ``traces.parquet`` long-format traces of the n best and n worst pick-points (they
  are re-simulated with recording on: keeping traces of every pick-point of a large
  batch would not fit in device memory).

Every simulation runs through one ``mjx_pick.engine.Engine``: large runs go in chunks
(``engine.run_chunks``); each finished chunk is written atomically under ``chunks/`` so
that ``resume=True`` redoes nothing that finished. ``on_progress(done, total)`` reports
pick-points done after each chunk; setting the ``cancel`` event stops the run before
the next chunk (``engine.Cancelled``; the folder is marked "cancelled" and its finished
chunks stay for ``resume``).
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa

from mjx_pick import pickpoints as pp
from mjx_pick.config import ConfigError, to_dict, write_atomic, write_json, write_parquet
from mjx_pick.engine import Cancelled, Engine, ProgressFn, Simulator, auto_chunk, run_chunks
from mjx_pick.grasp import GraspConfig, min_grasp_force_n
from mjx_pick.gripper import GripperSpec, load_gripper
from mjx_pick.kernels import grasp as gk
from mjx_pick.metrics import results_table, summarize
from mjx_pick.objects import ObjectModel, load_object
from mjx_pick.physics import ContactParams, SolverParams
from mjx_pick.robustness import min_grip_force
from mjx_pick.rundir import claim, config_hash, finish, versions
from mjx_pick.scene import build_scene
from mjx_pick.simulate import Settings, default_batch_size, make_inputs


@dataclasses.dataclass
class Evaluation:
    """What an evaluation produced (also written to out_dir when one was given)."""

    table: pa.Table
    summary: dict
    config: dict
    traces: pa.Table | None
    out_dir: Path | None


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


def user_picks(
    obj: ObjectModel,
    gripper: GripperSpec,
    x,
    y,
    yaw,
    config=None,
    grasp=None,
    skip_infeasible: bool = False,
) -> pp.PickBatch:
    """Check user pick-points. Infeasible ones are an error naming rows and reasons, or,
    with skip_infeasible, left out with a warning that names them (pick_id keeps each
    kept row's index in the file, so results map back to it)."""
    checker = pp.FeasibilityChecker(obj, gripper, config, grasp)
    ids = np.arange(len(x))
    res = checker(x, y, yaw)
    bad = np.flatnonzero(res["reason"] != 0)
    if len(bad):
        shown = ", ".join(f"row {i + 2} ({pp.REASONS[res['reason'][i]]})" for i in bad[:8])
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


def evaluate(
    obj: ObjectModel | str,
    gripper: GripperSpec | str = "robotiq-2f85",
    *,
    n: int = 1000,
    seed: int = 0,
    picks: pp.PickBatch | str | Path | None = None,
    contact: ContactParams | None = None,
    solver: SolverParams | None = None,
    grasp: GraspConfig | None = None,
    pick_config: pp.PickConfig | None = None,
    backend: str = "auto",
    batch_size: int | None = None,
    out: str | Path | None = None,
    n_traces: int = 3,
    progress: bool = False,
    resume: bool = False,
    until: int | None = None,
    min_score: float = 0.9,
    max_n: int | None = None,
    chunk_size: int | None = None,
    min_force: bool = False,
    overwrite: bool = False,
    skip_infeasible: bool = False,
    on_progress: ProgressFn | None = None,
    cancel: threading.Event | None = None,
) -> Evaluation:
    """Simulate pick-points of an object with a gripper; see the module docstring.

    Args:
      obj: an ObjectModel, a shipped asset name, or an image/mesh path (see load_object).
      gripper: a GripperSpec, a preset name or a gripper TOML path.
      n: pick-points to generate (Normal mode) when picks is None.
      seed: generator seed (same seed, same pick-points).
      picks: a PickBatch or a CSV path (x_mm, y_mm, yaw_deg) instead of generating.
      contact, solver, grasp, pick_config: settings (defaults: the paper's).
      backend: "auto", "mjx" or "mujoco".
      batch_size: simulations per backend call (default: per backend).
      out: output folder (nothing is written without one).
      n_traces: traces kept for the n best and n worst pick-points.
      progress: show a progress bar (tqdm, on stderr).
      on_progress: called as on_progress(done, total) with the pick-points simulated
        (or read back on resume) of the main run, before the first chunk and after each
        (Optimization mode, whose total is not known ahead, reports nothing).
      cancel: a threading.Event; once set, the run stops before its next chunk with
        mjx_pick.engine.Cancelled (the output folder keeps its finished chunks).
      resume: skip chunks an interrupted run with the same configuration finished.
      overwrite: replace what another command (or another configuration) wrote in out.
      skip_infeasible: leave infeasible rows of a picks CSV out (with a warning naming
        them) instead of refusing the file.
      until, min_score, max_n: Optimization mode -- simulate batches until `until`
        pick-points reach min_score or max_n are spent.
      chunk_size: pick-points per chunk written to disk (default: from device memory).
      min_force: add a min_force_n column: each pick-point's smallest successful F_d
        within the gripper's force range (a batched bisection, about 10 more
        simulations per pick-point; see mjx_pick.robustness.min_grip_force).
    """
    obj, gripper = _resolve(obj, gripper)
    contact = contact or ContactParams()
    solver = solver or SolverParams()
    grasp = grasp or GraspConfig()
    pick_config = pick_config or pp.PickConfig()
    grasp.check_gripper(gripper)
    scene = build_scene(obj, gripper, contact, solver, grasp)
    engine = Engine(backend, batch_size, chunk_size=chunk_size or None, cancel=cancel)
    runner = engine.make(scene, grasp)
    out_dir = Path(out) if out is not None else None
    if out_dir is not None:  # before any simulation: a folder it may not use is refused now
        request = {
            "object": obj.summary(),
            "gripper": to_dict(gripper),
            "contact": to_dict(contact),
            "solver": to_dict(solver),
            "grasp": to_dict(grasp),
            "picks": to_dict(pick_config),
            "source": _picks_source(picks),
            "n": n,
            "seed": seed,
            "until": until,
            "min_score": min_score,
            "max_n": max_n,
            "min_force": min_force,
            "backend": backend,
        }
        claim(out_dir, "evaluate", config_hash(request), resume=resume, overwrite=overwrite)

    if until is not None:
        try:
            picks_batch, results = _optimize(
                engine,
                runner,
                grasp,
                obj,
                gripper,
                until,
                min_score,
                max_n or 10 * until,
                seed,
                pick_config,
            )
        except (KeyboardInterrupt, Cancelled) as stop:
            _stopped(out_dir, stop, engine, seed, None)
            raise
    else:
        if picks is None:
            picks_batch = pp.generate_normal(
                obj, gripper, n, seed=seed, config=pick_config, grasp=grasp
            )
        elif isinstance(picks, pp.PickBatch):
            picks_batch = picks
        else:
            picks_batch = user_picks(
                obj,
                gripper,
                *read_picks_csv(picks),
                config=pick_config,
                grasp=grasp,
                skip_infeasible=skip_infeasible,
            )
        results = None

    chunk = int(chunk_size or auto_chunk(runner))
    config = {
        "object": obj.summary(),
        "gripper": to_dict(gripper),
        "contact": to_dict(contact),
        "contact_in_mujoco": to_dict(scene.contact),
        "scene": {
            # where the pads grip (GraspConfig.grasp_height) and their contact patch
            "fingertip_height_mm": round(scene.index.pad_bottom_z0_m * 1e3, 6),
            "pad_patch_mm": [round(v, 6) for v in scene.pad_patch_mm],
        },
        "solver": to_dict(solver),
        "grasp": to_dict(grasp),
        "picks": to_dict(pick_config),
        "n": int(len(picks_batch)),
        "seed": int(seed),
        "mode": picks_batch.mode,
        "backend": runner.name,
        "device": runner.device,
        "batch_size": int(runner.batch_size),
        "chunk_size": int(chunk),
    }
    key = _config_key(config)
    config["config_key"] = key
    config["versions"] = versions()
    if out_dir is not None:
        _check_resume(out_dir, key, resume)
        write_json(out_dir / "config.json", config)
        write_atomic(out_dir / "scene.xml", scene.xml)

    t0 = time.perf_counter()
    try:
        if results is None:
            table = _simulate(
                engine, runner, grasp, picks_batch, chunk, out_dir, progress, on_progress
            )
        else:
            table = results_table(picks_batch, results)
        wall = time.perf_counter() - t0
        summary = summarize(table)
        mu = contact.pad_friction
        summary.update(
            {
                "object": obj.name,
                "gripper": gripper.name,
                "backend": runner.name,
                "device": runner.device,
                "f_gmin_n": min_grasp_force_n(obj, mu, grasp.safety_factor),
                "grip_force_n": grasp.grip_force_n,
                "candidates_checked": int(picks_batch.n_candidates),
                "rejected": dict(picks_batch.rejected),
                "compile_s": round(runner.stats.compile_s, 3),
                "run_s": round(runner.stats.run_s, 3),
                "wall_s": round(wall, 3),
                "picks_per_s": round(runner.stats.n / runner.stats.run_s, 2)
                if runner.stats.run_s > 0
                else None,
                "simulated_s_per_pick": round(grasp.duration_s, 3),
                "physics_steps_per_pick": grasp.n_ticks() * grasp.substeps(solver),
            }
        )
        if min_force:
            settings = Settings(gripper, contact, solver, grasp)
            sim = Simulator(obj, engine=engine)  # its bisection runs through this engine
            sim.adopt(settings, runner)
            t1 = time.perf_counter()
            forces = min_grip_force(obj, picks_batch, settings, simulator=sim)
            table = table.append_column("min_force_n", pa.array(forces))
            # holding at the gripper's smallest force says only that the true minimum is at
            # or below it: flagged, never presented as the minimum itself
            at_floor = np.isfinite(forces) & (forces <= gripper.force_min_n + 1e-9)
            table = table.append_column("min_force_at_floor", pa.array(at_floor))
            summary["min_force_at_floor"] = int(at_floor.sum())
            summary["min_force_s"] = round(time.perf_counter() - t1, 3)
            summary["min_force_n_median"] = (
                float(np.nanmedian(forces)) if np.isfinite(forces).any() else None
            )
        traces = _traces(engine, runner, grasp, picks_batch, table, n_traces) if n_traces else None
    except (KeyboardInterrupt, Cancelled) as stop:
        _stopped(out_dir, stop, engine, seed, config, time.perf_counter() - t0)
        raise
    if out_dir is not None:
        write_parquet(out_dir / "results.parquet", table)
        write_json(out_dir / "summary.json", summary)
        if traces is not None:
            write_parquet(out_dir / "traces.parquet", traces)
        meta = engine.describe(time.perf_counter() - t0)
        finish(out_dir, command="evaluate", config=config, seed=seed, **meta)
    return Evaluation(table, summary, config, traces, out_dir)


def _stopped(out_dir, stop: BaseException, engine: Engine, seed, config, wall_s=None) -> None:
    """Mark a folder whose run stopped early; its finished chunks stay for --resume."""
    if out_dir is not None:
        status = "cancelled" if isinstance(stop, Cancelled) else "interrupted"
        meta = engine.describe(wall_s)
        finish(out_dir, status, command="evaluate", config=config, seed=seed, **meta)


def _picks_source(picks) -> str:
    """What the pick-points come from, for the output folder's configuration hash."""
    if picks is None:
        return "generated"
    if isinstance(picks, pp.PickBatch):
        data = np.stack([picks.x_mm, picks.y_mm, picks.yaw_deg]).astype(np.float64)
        return "batch:" + config_hash(data.tobytes().hex())
    path = Path(picks)
    return "csv:" + (config_hash(path.read_text()) if path.is_file() else str(path))


def _config_key(config: dict) -> str:
    text = json.dumps(
        {k: v for k, v in config.items() if k not in ("device",)}, sort_keys=True, default=str
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _check_resume(out_dir: Path, key: str, resume: bool) -> None:
    old = out_dir / "config.json"
    chunks = sorted((out_dir / "chunks").glob("part-*.parquet"))
    if not chunks:
        return
    if not resume:
        raise ConfigError(
            f"{out_dir} holds results of an earlier run: pass --resume to continue it, "
            "or choose another --out"
        )
    if old.is_file() and json.loads(old.read_text()).get("config_key") != key:
        raise ConfigError(
            f"{out_dir} holds a run with a different configuration; it cannot be resumed "
            "with these settings (choose another --out)"
        )


def _simulate(engine, runner, grasp, picks, chunk, out_dir, bar: bool, on_progress):
    """The main run through the engine's chunked runner, with a tqdm bar if asked."""
    if not bar:
        return run_chunks(engine, runner, grasp, picks, chunk, out_dir, on_progress)
    from tqdm import tqdm

    with tqdm(total=len(picks), unit="pick", desc=f"simulating ({runner.name})") as pbar:

        def report(done: int, total: int) -> None:
            pbar.update(done - pbar.n)
            if on_progress is not None:
                on_progress(done, total)

        return run_chunks(engine, runner, grasp, picks, chunk, out_dir, report)


def _optimize(engine, runner, grasp, obj, gripper, k, min_score, max_n, seed, config):
    """Optimization mode: batches of pick-points through the engine until k reach
    min_score or max_n are spent; (PickBatch, results of every simulated pick)."""
    collected = {}
    batch = engine.batch_size or default_batch_size(engine.backend_name)

    def score_fn(b: pp.PickBatch) -> np.ndarray:
        out = engine.run(runner, make_inputs(runner.scene, grasp, b)).results
        for name, v in out.items():
            collected.setdefault(name, []).append(np.asarray(v))
        return np.where(out["success"], np.nan_to_num(out["score"], nan=-1.0), -1.0)

    res = pp.optimize(
        obj,
        gripper,
        score_fn,
        k=k,
        min_score=min_score,
        max_n=max_n,
        batch_size=min(batch, max_n),
        seed=seed,
        config=config,
        grasp=grasp,
    )
    merged = {name: np.concatenate(v) for name, v in collected.items()}
    return res.picks, merged


def _traces(engine, runner, grasp, picks: pp.PickBatch, table: pa.Table, n: int):
    """Re-simulate the n best and n worst pick-points with recording on."""
    score = np.asarray(table["score"], float)
    order = np.argsort(np.where(np.isnan(score), -np.inf, score))
    chosen = np.unique(np.concatenate([order[::-1][:n], order[:n]]))
    if len(chosen) == 0:
        return None
    sub = picks.take(chosen)
    rows = engine.run(runner, make_inputs(runner.scene, grasp, sub), record=True).traces
    n_pick, n_tick, _ = rows.shape
    cols = {"pick_id": np.repeat(sub.pick_id, n_tick)}
    for j, name in enumerate(gk.TRACE_FIELDS):
        cols[name] = rows[:, :, j].reshape(-1)
    cols["phase"] = np.asarray(gk.PHASES, dtype=object)[cols["phase"].astype(int)]
    cols["rank"] = np.repeat(np.where(np.isin(chosen, order[::-1][:n]), "best", "worst"), n_tick)
    return pa.table(cols)
