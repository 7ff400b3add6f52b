"""Pick-point robustness under vision error, and each pick-point's minimum grip force.

Details: docs/studies.md (studies/robust.py).
"""

from __future__ import annotations

import dataclasses
import hashlib
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pyarrow as pa

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import ConfigError, check_range, to_dict, write_json, write_parquet
from mjx_pick.core.metrics import wilson_interval
from mjx_pick.core.objects import ObjectModel, check_same_object
from mjx_pick.core.settings import Settings
from mjx_pick.engine.simulator import Simulator, showing_progress
from mjx_pick.outputs.rundir import config_hash, portable_object
from mjx_pick.studies.options import RunOptions, split_fields
from mjx_pick.studies.recorded import settings_changes, settings_of


def perturb(picks: pp.GraspBatch, m: int, sigma_xy_mm: float, sigma_yaw_deg: float, seed: int):
    """M real poses around each reported pose: (K*M,) x, y, yaw and the pick index."""
    rng = np.random.default_rng(seed)
    k = len(picks)
    idx = np.repeat(np.arange(k), m)
    x = picks.x_mm[idx] + rng.normal(0.0, sigma_xy_mm, k * m)
    y = picks.y_mm[idx] + rng.normal(0.0, sigma_xy_mm, k * m)
    yaw = picks.yaw_deg[idx] + rng.normal(0.0, sigma_yaw_deg, k * m)
    return x, y, np.mod(yaw, 360.0), idx


class Placements(NamedTuple):
    """M real poses around each of K reported ones (K*M draws, pick-major).

    draws: the draws that are simulated (a GraspBatch of ok.sum() entries, the fingers
    at each reported pose's planned opening); ok (K*M,): simulated (the rest fail as
    they are: a finger lands on the object, or nothing lies between the fingers);
    index (K*M,): the reported pick-point of each draw; reason (K*M,): the feasibility
    check's reason code (``pickpoints.REASONS``).
    """

    draws: pp.GraspBatch
    ok: np.ndarray
    index: np.ndarray
    reason: np.ndarray


def placements(
    obj: ObjectModel,
    picks: pp.GraspBatch,
    base: Settings,
    m: int,
    sigma_xy_mm: float,
    sigma_yaw_deg: float,
    seed: int,
    pick_config: pp.PickConfig | None = None,
) -> Placements:
    """Real poses around each reported pick-point, checked with the fingers at the
    opening planned for the reported pose (see the module docstring). Grasps given as
    poses keep their tilt and height; their planar part is perturbed and the 6-DoF
    checks (``GraspChecker.at_opening``) say which draws land or miss."""
    x, y, yaw, idx = perturb(picks, m, sigma_xy_mm, sigma_yaw_deg, seed)
    if not picks.is_pick_points:
        return _grasp_placements(obj, picks, base, x, y, yaw, idx)
    checker = pp.FeasibilityChecker(obj, base.gripper, pick_config, base.grasp)
    planned = picks.opening_mm[idx]
    res = checker(x, y, yaw, opening_mm=planned)
    # coverage is a planning rule, not physics: a real pose with little object between
    # the fingers is simulated like any other; one with a finger on the object or
    # nothing between the fingers fails as it is
    ok = (res["reason"] == pp.fk.FEASIBLE) | (res["reason"] == pp.fk.COVERAGE)
    draws = pp.GraspBatch(
        pick_id=np.arange(len(x))[ok],
        x_mm=x[ok],
        y_mm=y[ok],
        yaw_deg=yaw[ok],
        opening_mm=planned[ok],
        coverage=res["coverage"][ok],
        gap_left_mm=res["gap_left_mm"][ok],
        gap_right_mm=res["gap_right_mm"][ok],
        rejected={},
        n_candidates=len(x),
        mode="robustness",
    )
    return Placements(draws, ok, idx, np.asarray(res["reason"]))


def _grasp_placements(obj, picks: pp.GraspBatch, base: Settings, x, y, yaw, idx) -> Placements:
    """placements of grasps given as poses: the draws' planar parts x, y, yaw (K*M,),
    each keeping its grasp's tilt and height; reasons in ``pickpoints.REASONS`` codes (a
    finger on the part or the table: CLEARANCE; nothing between the pads: OFF_OBJECT)."""
    from mjx_pick.core import grasp_checks as gc
    from mjx_pick.core.grasps import poses
    from mjx_pick.engine.inputs import scene_of

    planned = picks.opening_mm[idx]
    moved = dataclasses.replace(
        picks.take(idx), x_mm=x, y_mm=y, yaw_deg=yaw, pick_id=np.arange(len(x))
    )
    res = gc.GraspChecker(scene_of(obj, base)).at_opening(poses(moved, np.nan), planned)
    code = {gc.FEASIBLE: pp.fk.FEASIBLE, gc.OFF_OBJECT: pp.fk.OFF_OBJECT}
    reason = np.array([code.get(int(r), pp.fk.CLEARANCE) for r in res["reason"]])
    ok = reason == pp.fk.FEASIBLE
    draws = dataclasses.replace(
        moved.take(ok),
        gap_left_mm=res["gap_left_mm"][ok],
        gap_right_mm=res["gap_right_mm"][ok],
        coverage=res["coverage"][ok],
        rejected={},
        n_candidates=len(x),
        mode="robustness",
    )
    return Placements(draws, ok, idx, reason)


def check_draws(m: int, sigma_xy_mm: float, sigma_yaw_deg: float) -> None:
    """A ConfigError unless 1 <= m <= 100000 draws, sigma_xy_mm in [0, 100] mm and
    sigma_yaw_deg in [0, 180] deg."""
    check_range("robustness", "m", m, 1, 100_000)
    check_range("robustness", "sigma_xy_mm", sigma_xy_mm, 0, 100)
    check_range("robustness", "sigma_yaw_deg", sigma_yaw_deg, 0, 180)


@dataclasses.dataclass(frozen=True)
class Perturbations:
    """How the real poses are drawn around each reported one: m draws, each moved by
    N(0, sigma_xy_mm) in x and y (mm) and N(0, sigma_yaw_deg) in yaw (deg)."""

    m: int = 32
    sigma_xy_mm: float = 2.0
    sigma_yaw_deg: float = 3.0

    def check(self) -> None:
        check_draws(self.m, self.sigma_xy_mm, self.sigma_yaw_deg)


def robustness(
    obj: ObjectModel,
    picks: pp.GraspBatch,
    base: Settings | None = None,
    options: RunOptions | None = None,
    *,
    request: Perturbations | None = None,
    simulator: Simulator | None = None,
    **fields,
) -> pa.Table:
    """Robust success probability of each pick-point; rows ranked best first.

    request: the draws (:class:`Perturbations`: m, sigma_xy_mm, sigma_yaw_deg); options, or
    either's fields as keywords (``options.RunOptions``; n is not used): out is a new
    folder, or the evaluate folder the pick-points came from (its files stay; robustness.parquet and
    robustness.json join them); finished chunks are kept there as the draws are
    simulated (``engine.chunks.ChunkStore``; in an evaluate folder under
    ``chunks/robust/``) and removed once the outputs are written. resume: continue an
    interrupted run of this configuration in out from its chunks (on a complete one:
    read it back, simulate nothing). ray simulates the draws on a Ray cluster ("auto"
    or "HOST:PORT"; mjx_pick.engine.cluster), this process writing out; progress: a
    progress bar of the simulations on stderr. simulator: as sweep's.

    Returns a table with pick_id, x_mm, y_mm, yaw_deg, robust_p, robust_ci_low,
    robust_ci_high, trials, successes, landed (draws where a finger lands on the
    object), missed (nothing between the fingers), robust_score_mean and rank.
    """
    draws, opts = split_fields(Perturbations, request, options, fields)
    opts.only("robustness", *_ROBUST_FIELDS)
    draws.check()
    base = base or Settings()
    request = _request(obj, base, opts, draws, pick_points=_digest(picks))
    with opts.opening("robust", obj, request, simulator, joins=("evaluate",)) as study:
        if study.complete:
            return _read_robust(study.out_dir)
        sim, t0 = study.sim, time.perf_counter()
        desc = f"robustness: {len(picks)} pick-points x {draws.m} draws"
        desc += f" ({sim.runner.backend_name})"
        with showing_progress(sim.runner, desc, "sim", opts.progress):
            table = _robustness(obj, picks, base, sim, study.store, draws, opts)
        _write(obj, base, opts, draws, table, study, request, t0)
        return table


def _request(
    obj: ObjectModel, base: Settings, opts: RunOptions, draws: Perturbations, **more
) -> dict:
    """What decides a robust run's table: its configuration key's settings."""
    request = {"object": portable_object(obj.summary()), "base": to_dict(base)}
    request.update(dataclasses.asdict(draws), seed=opts.seed, picks=to_dict(opts.picks))
    return {**request, **more}


def _digest(picks: pp.GraspBatch) -> str:
    """The reported pick-points as part of a configuration key: ids, poses, openings."""
    h = hashlib.sha256()
    for a in (picks.pick_id, picks.x_mm, picks.y_mm, picks.yaw_deg, picks.opening_mm):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    for a in (picks.tilt_quat, picks.height_mm):  # grasps given as poses
        if a is not None:
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()[:16]


def _robustness(obj, picks, base, sim, store, draws: Perturbations, opts: RunOptions) -> pa.Table:
    """robustness's draws simulated through sim (chunks read from and saved to store,
    when given) and its table; nothing written."""
    m, sigma_xy_mm, sigma_yaw_deg = draws.m, draws.sigma_xy_mm, draws.sigma_yaw_deg
    placed = placements(obj, picks, base, m, sigma_xy_mm, sigma_yaw_deg, opts.seed, opts.picks)
    (out_d,) = sim.run([(base, placed.draws)], store)
    return _robust_table(picks, placed, out_d, m)


def _write(obj, base, opts: RunOptions, draws: Perturbations, table, study, request, t0) -> None:
    """robust's outputs in its folder (nothing without one): robustness.parquet and
    robustness.json, the run's record, then its chunks are dropped."""
    out_dir = study.out_dir
    if out_dir is None:
        return
    write_parquet(out_dir / "robustness.parquet", table)
    record = {"object": obj.summary(), "settings": to_dict(base), **dataclasses.asdict(draws)}
    record["seed"] = opts.seed
    write_json(out_dir / "robustness.json", {**record, "ranking": table.slice(0, 50).to_pylist()})
    config = {"object": obj.summary(), "settings": to_dict(base), "m": draws.m, "k": len(table)}
    config.update(sigma_xy_mm=draws.sigma_xy_mm, sigma_yaw_deg=draws.sigma_yaw_deg)
    config.update(seed=opts.seed, picks=to_dict(opts.picks))
    # in an evaluate folder: run-robust.json beside evaluate's own run.json, with this
    # run's key (rundir.is_complete reads it)
    meta = study.sim.runner.describe(time.perf_counter() - t0)
    study.close(config, {**meta, "key": config_hash(request)})


def _read_robust(out_dir: Path) -> pa.Table:
    """A complete robust run's table, read back (nothing simulated)."""
    import pyarrow.parquet as pq

    return pq.read_table(out_dir / "robustness.parquet")


def _robust_table(picks: pp.GraspBatch, placed: Placements, out_d: dict, m: int) -> pa.Table:
    """One row per pick-point from its m draws' results (out_d: of the feasible draws):
    success probability with its Wilson 95 % interval, draws that landed on the object
    or missed it, mean score, rank; best first (probability, interval's low end, score)."""
    idx, ok, k = placed.index, placed.ok, len(picks)
    success = np.zeros(len(idx), bool)
    score = np.zeros(len(idx))
    if len(placed.draws):
        success[ok] = out_d["success"]
        score[ok] = np.nan_to_num(out_d["score"], nan=0.0)
    successes = np.bincount(idx, weights=success, minlength=k).astype(int)
    landed = np.bincount(idx, weights=placed.reason == pp.fk.CLEARANCE, minlength=k).astype(int)
    off_object = placed.reason == pp.fk.OFF_OBJECT
    missed = np.bincount(idx, weights=off_object, minlength=k).astype(int)
    mean_score = np.bincount(idx, weights=score, minlength=k) / m
    ci = np.array([wilson_interval(int(s), m) for s in successes]).reshape(k, 2)
    p = successes / m
    order = np.lexsort((-mean_score, -ci[:, 0], -p))
    rank = np.empty(k, int)
    rank[order] = np.arange(1, k + 1)
    return pa.table(
        {
            "pick_id": picks.pick_id,
            "x_mm": picks.x_mm,
            "y_mm": picks.y_mm,
            "yaw_deg": picks.yaw_deg,
            "opening_mm": picks.opening_mm,
            "robust_p": p,
            "robust_ci_low": ci[:, 0],
            "robust_ci_high": ci[:, 1],
            "trials": np.full(k, m),
            "successes": successes,
            "landed": landed,
            "missed": missed,
            "robust_score_mean": mean_score,
            "rank": rank,
        }
    ).take(pa.array(order))


# the RunOptions fields robustness uses (it takes its pick-points: no n)
_ROBUST_FIELDS = (
    "grasps",
    "antipodal",
    "depth_mm",
    "seed",
    "pick_config",
    "backend",
    "batch_size",
    "out",
    "overwrite",
    "resume",
    "ray",
    "progress",
)


@dataclasses.dataclass(frozen=True)
class ForceSearch:
    """The bisection of :func:`min_grip_force`: the bracket lo_n..hi_n, N (default: the
    gripper's force range); it stops when every bracket is narrower than tolerance_n."""

    lo_n: float | None = None
    hi_n: float | None = None
    tolerance_n: float = 0.5


def min_grip_force(
    obj: ObjectModel,
    picks: pp.GraspBatch,
    base: Settings | None = None,
    options: RunOptions | None = None,
    *,
    request: ForceSearch | None = None,
    simulator: Simulator | None = None,
    **fields,
) -> np.ndarray:
    """Smallest successful F_d per pick-point, N (N,); see the module docstring.

    request: the bisection (:class:`ForceSearch`); options: backend and batch_size
    (``options.RunOptions``; a simulator given is used instead); or either's fields
    as keywords.
    """
    search, opts = split_fields(ForceSearch, request, options, fields)
    opts.only("min_force", "backend", "batch_size")
    base = base or Settings()
    g = base.gripper
    lo_n = g.force_min_n if search.lo_n is None else float(search.lo_n)
    hi_n = g.force_max_n if search.hi_n is None else float(search.hi_n)
    tolerance_n = search.tolerance_n
    check_range("min_force", "lo_n", lo_n, g.force_min_n, g.force_max_n)
    check_range("min_force", "hi_n", hi_n, lo_n, g.force_max_n, lo_open=True)
    check_range("min_force", "tolerance_n", tolerance_n, 0, lo_open=True)
    sim = simulator or Simulator(obj, opts.backend, opts.batch_size)
    n = len(picks)

    def succeeds(force: np.ndarray, which: np.ndarray) -> np.ndarray:
        jobs = [
            (
                dataclasses.replace(
                    base, grasp=dataclasses.replace(base.grasp, grip_force_n=float(force[i]))
                ),
                picks.take(np.array([i])),
            )
            for i in which
        ]
        return np.array([bool(r["success"][0]) for r in sim.run(jobs)], bool)

    everyone = np.arange(n)
    at_hi = succeeds(np.full(n, hi_n), everyone)
    at_lo = np.zeros(n, bool)
    if at_hi.any():
        at_lo[at_hi] = succeeds(np.full(n, lo_n), everyone[at_hi])
    lo = np.full(n, lo_n)
    hi = np.full(n, hi_n)
    live = at_hi & ~at_lo
    while live.any() and np.max(hi[live] - lo[live]) > tolerance_n:
        which = everyone[live]
        mid = 0.5 * (lo + hi)
        ok = succeeds(mid, which)
        hi[which[ok]] = mid[which[ok]]
        lo[which[~ok]] = mid[which[~ok]]
        live = at_hi & ~at_lo & (hi - lo > tolerance_n)
    result = np.where(at_lo, lo_n, hi)
    return np.where(at_hi, result, np.nan)


@dataclasses.dataclass(frozen=True)
class RobustBest(Perturbations):
    """What :func:`robust_best` tests: the top_k best successful pick-points of an
    evaluate folder's results (None: of n pick-points simulated first), each under
    the draws (:class:`Perturbations`)."""

    results: str | Path | None = None
    top_k: int = 10


def robust_best(
    obj: ObjectModel,
    base: Settings | None = None,
    options: RunOptions | None = None,
    *,
    request: RobustBest | None = None,
    simulator: Simulator | None = None,
    **fields,
) -> pa.Table:
    """The robustness of the ``top_k`` best successful pick-points (``mjx-pick robust``).

    request (:class:`RobustBest`): results, an evaluate folder (or its
    results.parquet) of this object to take them from; without it, ``n`` (default
    1000) pick-points drawn with ``seed`` are simulated first; top_k; the draws.
    base: the settings the draws are simulated with (gripper, physics, procedure);
    with results, None takes the run's own (its config.json), and settings that
    differ from the run's are refused, naming each: its pick-points were ranked under
    the run's. Without results, None is ``Settings()``.
    options, or either's fields as keywords (``options.RunOptions``): out, overwrite and
    resume as :func:`robustness` (the n pick-points' chunks are kept and resumed
    too); ray: every simulation on a Ray cluster ("auto" or "HOST:PORT";
    mjx_pick.engine.cluster). simulator: run through this one (e.g. a caller's on a
    cluster, kept open; backend, batch_size and ray are then its own). Every input is
    checked, and out claimed, before anything is simulated. progress: one progress bar
    on stderr over every simulation (the n pick-points, then the draws).
    """
    req, opts = split_fields(RobustBest, request, options, fields)
    opts.only("robust", "n", *_ROBUST_FIELDS)
    if req.results is not None and opts.n is not None:  # ignored otherwise, without a word
        raise ConfigError(
            f"--n {opts.n} with --results {req.results}: the pick-points ranked are that "
            "run's; leave out --n (or --results, to simulate n pick-points first)"
        )
    n, results, top_k = opts.n_or(1000), req.results, req.top_k
    req.check()
    check_range("robust", "top_k", top_k, 1, 100_000)
    if results is None:
        check_range("robust", "n", n, 1, 1e8)
    opts.check_resume()  # before results are read
    table = None
    if results is not None:
        table, base, opts = _read_results(Path(results), obj, base, opts)
    base = base or Settings()
    draws = Perturbations(req.m, req.sigma_xy_mm, req.sigma_yaw_deg)
    source = str(results) if results is not None else None
    request = _request(obj, base, opts, draws, top_k=top_k, results=source, n=n)
    with opts.opening("robust", obj, request, simulator, joins=("evaluate",)) as study:
        if study.complete:
            return _read_robust(study.out_dir)
        sim, store, t0 = study.sim, study.store, time.perf_counter()
        desc = f"robust ({sim.runner.backend_name})"
        with showing_progress(sim.runner, desc, "sim", opts.progress):
            picks = _best_picks(obj, base, sim, store, table, n, top_k, opts)
            ranked = _robustness(obj, picks, base, sim, store, draws, opts)
        _write(obj, base, opts, draws, ranked, study, request, t0)
        return ranked


def _best_picks(obj, base, sim, store, results, n, top_k, opts: RunOptions) -> pp.GraspBatch:
    """The top_k best successful pick-points: of results (an evaluate table), or of n
    pick-points simulated through sim (chunks read from and saved to store)."""
    from mjx_pick.core.grasp_checks import GraspChecker
    from mjx_pick.core.grasps import poses
    from mjx_pick.core.metrics import best_successes
    from mjx_pick.engine.inputs import scene_of
    from mjx_pick.studies.grasp_sources import draw_grasps

    given = None  # grasps given as poses: (N, 4, 4) frames
    if results is not None:
        table = results
        x, y, yaw, ids = (np.asarray(table[c]) for c in ("x_mm", "y_mm", "yaw_deg", "pick_id"))
        success, score = np.asarray(table["success"]), np.asarray(table["score"], float)
        if "grasp_pose" in table.column_names:
            given = np.asarray(table["grasp_pose"].to_pylist(), float).reshape(-1, 4, 4)
    else:
        picks = draw_grasps(
            obj, base, n, opts.seed, opts.picks, opts.grasps,
            antipodal=opts.antipodal, depth_mm=opts.depth_mm,
        )  # fmt: skip
        (out,) = sim.run([(base, picks)], store)
        x, y, yaw, ids = picks.x_mm, picks.y_mm, picks.yaw_deg, picks.pick_id
        success, score = out["success"], out["score"]
        if not picks.is_pick_points:
            given = poses(picks, np.nan)
    top = best_successes(success, score, top_k)
    if len(top) == 0:
        raise ConfigError("no successful pick-point to test: evaluate more pick-points first")
    if given is not None:
        checker = GraspChecker(scene_of(obj, base), opts.picks.safety_zone_mm)
        return checker.batch(ids[top], given[top], "robustness")
    checker = pp.FeasibilityChecker(obj, base.gripper, opts.picks, base.grasp)
    return checker.batch(ids[top], x[top], y[top], yaw[top], "robustness")


def _read_results(
    path: Path, obj: ObjectModel, base: Settings | None, opts: RunOptions
) -> tuple[pa.Table, Settings | None, RunOptions]:
    """An evaluate folder's results table, refused when it belongs to another object;
    with the settings its pick-points were ranked under (its config.json): base when
    None, and opts' pick configuration when none was given. Settings that differ from
    the run's are refused, naming each."""
    import json

    import pyarrow.parquet as pq

    table_path = path / "results.parquet" if path.is_dir() else path
    if not table_path.is_file():
        raise ConfigError(f"--results {path}: no results.parquet there")
    config_path = table_path.parent / "config.json"
    if config_path.is_file():
        config = json.loads(config_path.read_text())
        check_same_object(config.get("object") or {}, obj, f"--results {path}")
        if all(k in config for k in ("gripper", "contact", "solver", "grasp", "picks")):
            theirs = settings_of(config, f"--results {path}")
            given = (base or theirs[0], opts.pick_config or theirs[1])
            changes = settings_changes(theirs, given)
            if changes:
                shown = "; ".join(changes[:6]) + (" ..." if len(changes) > 6 else "")
                raise ConfigError(
                    f"--results {path}: its pick-points were simulated with other settings "
                    f"than these ({shown}): leave those settings out to use the run's, or "
                    "evaluate anew with these"
                )
            base, opts = given[0], dataclasses.replace(opts, pick_config=given[1])
    elif base is None:
        raise ConfigError(
            f"--results {path}: no config.json beside the table, so the settings its "
            "pick-points were simulated with are unknown: give them (gripper, physics)"
        )
    table = pq.read_table(table_path)
    for col in ("pick_id", "x_mm", "y_mm", "yaw_deg", "score", "success"):
        if col not in table.column_names:
            raise ConfigError(f"--results {path}: no column {col!r}")
    return table, base, opts
