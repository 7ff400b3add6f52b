"""Gripper comparison and gripper design search (the paper's applications 2 and 3).

Details: docs/studies.md (studies/comparison.py).
"""

from __future__ import annotations

import collections
import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pyarrow as pa

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import (
    ConfigError,
    check_field,
    check_range,
    to_dict,
    write_json,
    write_parquet,
)
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.metrics import mcnemar_p, rate_summary, results_table
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.settings import Settings
from mjx_pick.engine.chunks import ChunkStore
from mjx_pick.engine.simulator import Simulator, showing_progress
from mjx_pick.outputs.rundir import portable_object
from mjx_pick.studies.options import RunOptions, split_fields


@dataclasses.dataclass
class Comparison:
    """Outcome of compare(): one ranking row per gripper and the per-pick table."""

    ranking: list[dict]  # best first
    table: pa.Table  # one row per gripper x shared candidate
    names: list[str]  # gripper names in the order given (the rows below)
    success: np.ndarray  # (G, n) bool
    score: np.ndarray  # (G, n) float, 0 where infeasible
    feasible: np.ndarray  # (G, n) bool
    candidates: dict  # x_mm, y_mm, yaw_deg, pick_id (n,)
    out_dir: Path | None
    # resume found the comparison already complete: read back, nothing simulated
    already_complete: bool = False


def shared_candidates(
    obj: ObjectModel,
    grippers: list[GripperSpec],
    n: int,
    seed: int = 0,
    config: pp.PickConfig | None = None,
    grasp=None,
) -> tuple[dict, list[pp.GraspBatch], np.ndarray]:
    """The first n candidates of the seeded stream that some gripper can take.

    Returns:
      candidates (x_mm, y_mm, yaw_deg, pick_id: (n,) each), per gripper the GraspBatch of
      its feasible candidates (pick_id = candidate id), and reasons (G, n) int.
    """
    check_range("compare", "n", n, 1, 1e8)
    checkers = [pp.FeasibilityChecker(obj, g, config, grasp) for g in grippers]
    parts, found, drawn = [], 0, 0
    counts = np.zeros((len(grippers), len(pp.REASONS)), np.int64)  # per gripper, per reason
    for ids, x, y, yaw in pp.candidate_blocks(checkers[0], seed):
        if found >= n or drawn >= checkers[0].config.max_candidates:
            break
        drawn += len(ids)
        checks = [c(x, y, yaw) for c in checkers]
        r = np.stack([res["reason"] for res in checks])
        for g in range(len(grippers)):
            counts[g] += np.bincount(r[g], minlength=len(pp.REASONS))
        keep = np.flatnonzero((r == 0).any(axis=0))[: n - found]
        found += len(keep)
        parts.append(
            (
                ids[keep],
                x[keep],
                y[keep],
                yaw[keep],
                [{k: v[keep] for k, v in res.items()} for res in checks],
            )
        )
    rejected = [{r: int(row[i]) for i, r in enumerate(pp.REASONS) if i} for row in counts]
    for g, gripper in enumerate(grippers):  # a gripper that takes the part only rarely
        pp.warn_rare(obj, gripper, int(counts[g, 0]), drawn, rejected[g], checkers[g].config)
    if found == 0:
        why = "; ".join(
            f"{g.name}: {pp.why_none(rejected[i], g, checkers[i].config)}"
            for i, g in enumerate(grippers)
        )
        raise ConfigError(
            f"none of {', '.join(g.name for g in grippers)} can take {obj.name} at any of "
            f"{drawn:,} candidate poses: {why}"
        )
    ids, x, y, yaw = (np.concatenate([p[i] for p in parts]) for i in range(4))
    cand = {"x_mm": x, "y_mm": y, "yaw_deg": yaw, "pick_id": ids}
    batches = []
    for g in range(len(grippers)):
        res = {k: np.concatenate([p[4][g][k] for p in parts]) for k in parts[0][4][g]}
        batches.append(pp.feasible_batch(ids, x, y, yaw, res, "compare"))
    reasons = np.stack(
        [np.concatenate([p[4][g]["reason"] for p in parts]) for g in range(len(grippers))]
    )
    return cand, batches, reasons


def shared_grasps(
    obj: ObjectModel,
    grippers: list[GripperSpec],
    base: Settings,
    n: int,
    seed: int,
    opts: RunOptions,
    sim: Simulator | None = None,
) -> tuple[dict, list[pp.GraspBatch], np.ndarray]:
    """:func:`shared_candidates` for grasps given as poses (opts.grasps: "antipodal" or
    a grasp file): the same candidate poses checked on every gripper's scene by the
    6-DoF checks (``GraspChecker``). Antipodal: the first n of the seeded stream -- drawn
    for the widest gripper's stroke and pads -- that some gripper takes; a file: every
    grasp in it (its tool centre point moved by each gripper's tcp_offset_mm). reasons:
    ``grasp_checks.REASONS`` codes (0: feasible). sim: the study's simulator, whose
    scenes are checked (else each gripper's scene is built here)."""
    from mjx_pick.core import antipodal as ap
    from mjx_pick.core.grasp_checks import GraspChecker, feasible_batch
    from mjx_pick.core.grasps import decompose
    from mjx_pick.engine.inputs import scene_of
    from mjx_pick.studies.grasp_sources import file_centres

    zone = opts.picks.safety_zone_mm

    def scene(g: GripperSpec):  # the simulator's own scene where one runs the study
        settings = base.on_gripper(g)[0]
        return sim.exact_scene(settings) if sim is not None else scene_of(obj, settings)

    checkers = [GraspChecker(scene(g), zone) for g in grippers]
    if opts.grasps == "antipodal":
        config = opts.antipodal or ap.AntipodalConfig()
        wide = max(grippers, key=lambda g: g.stroke_mm)
        pad_mm = (float(wide.stroke_mm), float(wide.finger_width_mm), float(wide.pad_height_mm))
        rng = np.random.default_rng(seed)
        parts, found, drawn = [], 0, 0
        while found < n and drawn < config.max_candidates:
            poses = ap.antipodal_poses(obj.mesh, pad_mm, config, rng)
            if not len(poses):
                break
            res = [c(poses) for c in checkers]
            keep = np.flatnonzero(np.any([r["reason"] == 0 for r in res], axis=0))[: n - found]
            parts.append(
                (drawn + keep, poses[keep], [{k: v[keep] for k, v in r.items()} for r in res])
            )
            found, drawn = found + len(keep), drawn + len(poses)
        if found == 0:
            raise ConfigError(
                f"none of {', '.join(g.name for g in grippers)} can take any of {drawn:,} "
                f"antipodal grasps on {obj.name!r}"
            )
        ids = np.concatenate([p[0] for p in parts])
        each = [np.concatenate([p[1] for p in parts])] * len(grippers)
        results = [
            {k: np.concatenate([p[2][g][k] for p in parts]) for k in parts[0][2][g]}
            for g in range(len(grippers))
        ]
    else:
        read = [file_centres(obj, opts.grasps, opts.depth_mm, g.tcp_offset_mm) for g in grippers]
        labels, each = read[0][0], [centres for _, centres in read]
        ids = labels.pick_id if labels.pick_id is not None else np.arange(len(each[0]))
        results = [c(t) for c, t in zip(checkers, each, strict=True)]
    planar = decompose(each[0])
    cand = {"x_mm": planar["x_mm"], "y_mm": planar["y_mm"], "yaw_deg": planar["yaw_deg"]}
    cand["pick_id"] = np.asarray(ids, np.int64)
    batches = [feasible_batch(ids, t, r, "compare") for t, r in zip(each, results, strict=True)]
    return cand, batches, np.stack([r["reason"] for r in results])


def _candidates(obj, grippers, base, n, seed, pick_config, opts, sim=None):
    """compare's shared candidates from opts' grasp source (sim: the study's simulator,
    whose scenes the 6-DoF checks use)."""
    if opts is None or opts.grasps == "topdown":
        return shared_candidates(obj, grippers, n, seed, pick_config, base.grasp)
    return shared_grasps(obj, grippers, base, n, seed, opts, sim)


def unequal_forces(ranking: list[dict]) -> str:
    """A sentence for a ranking whose grippers squeezed different grip forces (one
    could not reach F_d and ran at its most), '' when they all squeezed the same: a
    ranking at unequal forces compares the forces too, and must say so."""
    forces = {row["gripper"]: row.get("grip_force_n") for row in ranking}
    if len({f for f in forces.values() if f is not None}) <= 1:
        return ""
    each = ", ".join(f"{g} at {f:g} N" for g, f in forces.items())
    return (
        f"the grippers squeezed different grip forces ({each}): a gripper that cannot "
        "reach the set force runs at its largest, so the ranking compares forces too"
    )


def compare(
    obj: ObjectModel,
    grippers: list[GripperSpec],
    base: Settings | None = None,
    options: RunOptions | None = None,
    *,
    rank_by: str = "success",
    simulator: Simulator | None = None,
    _store: ChunkStore | None = None,
    **run,
) -> Comparison:
    """Simulate one shared candidate set (n pick-points, default 200) on every gripper
    and rank them. options, or its fields as keywords (``options.RunOptions``): as
    sweep's (out, resume, ray, progress, ...); simulator: as sweep's. _store: the
    chunks of a study that runs this comparison as one of its steps (design), used
    without out."""
    opts = RunOptions.of(options, **run)
    if rank_by not in ("success", "score"):
        raise ConfigError(f"rank_by = {rank_by!r} is not allowed: choose 'success' or 'score'")
    if len(grippers) < 1:
        raise ConfigError("compare needs at least one gripper")
    count = collections.Counter(g.name for g in grippers)
    repeated = sorted(n for n, c in count.items() if c > 1)
    if repeated:
        shown = ", ".join(f"{n!r} ({count[n]} times)" for n in repeated[:5])
        more = f" and {len(repeated) - 5} more" if len(repeated) > 5 else ""
        raise ConfigError(f"gripper names must differ: {shown}{more}")
    base = base or Settings()
    n, seed, pick_config = opts.n_or(200), opts.seed, opts.picks
    if opts.grasps == "topdown":
        pp.check_raster(obj, pick_config)  # before the stroke checks
        fitted = [base.on_gripper(g)[0] for g in grippers]  # each at its own force and speed
        refused = [pp.stroke_refusal(obj, s.gripper, pick_config, s.grasp) for s in fitted]
        if all(refused):  # none can take it: said now, not after max_candidates draws
            raise ConfigError("no gripper can take the part: " + "; ".join(refused))
    request = {"object": portable_object(obj.summary()), "grippers": to_dict(grippers)}
    request.update(base=to_dict(base), n=n, seed=seed, rank_by=rank_by)
    request.update(picks=to_dict(pick_config))
    if opts.grasps != "topdown":  # a top-down comparison's key as before
        from mjx_pick.studies.grasp_sources import source_key

        request.update(grasps=source_key(opts))
    with opts.opening("compare", obj, request, simulator) as study:
        if study.complete:
            return _read_comparison(
                study.out_dir, obj, grippers, base, n, seed, pick_config, opts=opts
            )
        sim, store = study.sim, study.store if study.store is not None else _store
        t0 = time.perf_counter()
        result = _compare(obj, grippers, base, n, seed, pick_config, rank_by, sim, store, opts)
        if study.out_dir is not None:
            config = {"object": obj.summary(), "grippers": [to_dict(g) for g in grippers]}
            config.update(base=to_dict(base), n=n, seed=seed, rank_by=rank_by)
            _write_comparison(study.out_dir, obj, config, result)
            meta = sim.runner.describe(time.perf_counter() - t0)
            study.close({**config, "picks": to_dict(pick_config)}, meta)
        return result


def _write_comparison(out_dir: Path, obj, config: dict, result: Comparison) -> None:
    """A comparison's outputs: configuration, ranking, results and pictures."""
    write_json(out_dir / "config.json", config)
    write_json(out_dir / "ranking.json", result.ranking)
    write_parquet(out_dir / "results.parquet", result.table)
    plot_comparison(obj, result, out_dir)
    result.out_dir = out_dir


def _compare(
    obj, grippers, base, n, seed, pick_config, rank_by, sim, store=None, opts=None
) -> Comparison:
    """compare's simulations and ranking (nothing written): the shared candidates on
    every gripper through sim, chunks read from and saved to store (when given)."""
    names = [g.name for g in grippers]
    cand, batches, reasons = _candidates(obj, grippers, base, n, seed, pick_config, opts, sim)
    n_cand = len(cand["pick_id"])
    # each gripper's procedure fitted to its ranges: one that cannot squeeze F_d is
    # compared at its strongest
    jobs = [(base.on_gripper(g)[0], b) for g, b in zip(grippers, batches, strict=True)]
    desc = f"compare: {len(jobs)} grippers ({sim.runner.backend_name})"
    with showing_progress(sim.runner, desc, "sim", opts is not None and opts.progress):
        outs = sim.run(jobs, store)
    success = np.zeros((len(grippers), n_cand), bool)
    score = np.zeros((len(grippers), n_cand))
    tables = []
    for g, (b, out_g) in enumerate(zip(batches, outs, strict=True)):
        ok = reasons[g] == 0
        if len(b):
            success[g, ok] = out_g["success"]
            score[g, ok] = np.nan_to_num(out_g["score"], nan=0.0)  # diverged: no quality
            tables.append(
                results_table(b, out_g, jobs[g][0].gripper, {"gripper": np.full(len(b), names[g])})
            )
    ranking = _ranking(grippers, jobs, batches, outs, reasons, success, score, rank_by)
    table = pa.concat_tables(tables) if tables else pa.table({})
    return Comparison(ranking, table, names, success, score, reasons == 0, cand, None)


def _ranking(grippers, jobs, batches, outs, reasons, success, score, rank_by) -> list[dict]:
    """One row per gripper (rates over every candidate and over its feasible ones,
    grip force in N, diverged runs), best first by rank_by, each with its rank and
    McNemar's p against the best."""
    rows = []
    for g, gripper in enumerate(grippers):
        ok = reasons[g] == 0
        row = {"gripper": gripper.name, **rate_summary(success[g], score[g])}
        row["grip_force_n"] = jobs[g][0].grasp.grip_force_n
        feasible = rate_summary(success[g, ok], score[g, ok]) if ok.any() else None
        row["feasible"] = int(ok.sum())
        row["feasible_success_rate"] = feasible["success_rate"] if feasible else math.nan
        row["diverged"] = int(np.sum(outs[g]["diverged"])) if len(batches[g]) else 0
        rows.append(row)
    key = "success_rate" if rank_by == "success" else "score_mean"
    other = "score_mean" if rank_by == "success" else "success_rate"
    order = sorted(range(len(rows)), key=lambda g: (-rows[g][key], -rows[g][other]))
    lead = order[0]
    for rank, g in enumerate(order, start=1):
        rows[g]["rank"] = rank
        rows[g]["p_vs_best"] = 1.0 if g == lead else mcnemar_p(success[lead], success[g])
    return [rows[g] for g in order]


def _read_comparison(
    out_dir: Path, obj, grippers, base, n, seed, pick_config, ranking=None, opts=None
) -> Comparison:
    """A complete comparison's folder read back (resume has nothing to do): its ranking
    (ranking.json, unless given) and table, and the per-gripper arrays rebuilt from the
    table on the shared candidates (drawn again: geometry only, nothing simulated)."""
    import json

    import pyarrow.parquet as pq

    cand, _, reasons = _candidates(obj, grippers, base, n, seed, pick_config, opts)
    table = pq.read_table(out_dir / "results.parquet")
    if ranking is None:
        ranking = json.loads((out_dir / "ranking.json").read_text())
    names = [g.name for g in grippers]
    success = np.zeros((len(grippers), len(cand["pick_id"])), bool)
    score = np.zeros(success.shape)
    where = {int(pid): i for i, pid in enumerate(cand["pick_id"])}
    if table.num_rows:
        rows = table.select(["gripper", "pick_id", "success", "score"]).to_pydict()
        for g, pid, ok, s in zip(*rows.values(), strict=True):
            i = names.index(g), where[int(pid)]
            success[i], score[i] = bool(ok), 0.0 if s is None or np.isnan(s) else s
    feasible = reasons == 0
    return Comparison(
        ranking, table, names, success, score, feasible, cand, out_dir, already_complete=True
    )


def plot_comparison(obj: ObjectModel, result: Comparison, out_dir: Path) -> None:
    """ranking.png (rates and scores with intervals) and maps.png (per-gripper success
    on the silhouette: where the gripper centre lands, object frame)."""

    from mjx_pick.outputs.plots import add_polygon, gripper_in_object_frame, new_figure, save_png

    r = result.ranking
    names = [row["gripper"] for row in r]
    fig, axes = new_figure(1, 2, figsize=(10, 0.5 * len(r) + 2.5))
    for ax, key, ci, label in (
        (axes[0], "success_rate", "success_ci", "success rate (Wilson 95%)"),
        (axes[1], "score_mean", "score_ci", "mean score (95%), infeasible = 0"),
    ):
        y = np.arange(len(r))[::-1]
        v = np.array([row[key] for row in r])
        lo = np.clip(np.array([row[ci][0] for row in r]), 0.0, v)
        hi = np.clip(np.array([row[ci][1] for row in r]), v, 1.0)
        ax.barh(y, v, xerr=[v - lo, hi - v], color="#4a78b5", capsize=3)
        ax.set_yticks(y, names)
        ax.set_xlim(0, 1)
        ax.set_xlabel(label)
    fig.tight_layout()
    save_png(fig, out_dir / "ranking.png")

    cols = min(3, len(r))
    rows = math.ceil(len(r) / cols)
    fig, axes = new_figure(rows, cols, figsize=(4.5 * cols, 4 * rows), squeeze=False)
    c = result.candidates
    centre, _ = gripper_in_object_frame(c["x_mm"], c["y_mm"], c["yaw_deg"])
    for ax in axes.ravel():
        ax.set_axis_off()
    for k, row in enumerate(result.ranking):
        g = result.names.index(row["gripper"])
        ax = axes.ravel()[k]
        ax.set_axis_on()
        add_polygon(ax, obj.polygon, fc="#dddddd", ec="k", lw=1)
        feasible, ok = result.feasible[g], result.success[g]
        for mask, colour, label in (
            (~feasible & ~ok, "#bbbbbb", "infeasible"),
            (feasible & ~ok, "#d62728", "failed"),
            (ok, "#2ca02c", "success"),
        ):
            ax.scatter(centre[mask, 0], centre[mask, 1], s=6, color=colour, label=label, zorder=3)
        ax.set_aspect("equal")
        ax.set_title(f"{k + 1}. {row['gripper']}: {row['success_rate']:.0%}", fontsize=9)
        ax.legend(fontsize=6, loc="upper right")
    fig.tight_layout()
    save_png(fig, out_dir / "maps.png")


@dataclasses.dataclass
class DesignResult:
    """Outcome of design_search(): the winner against the base gripper on fresh picks."""

    best: GripperSpec
    base: GripperSpec
    final: Comparison  # best vs base on fresh pick-points
    rounds: list[list[dict]]  # each round's ranking
    out_dir: Path | None


def sample_variants(
    gripper: GripperSpec, bounds: dict[str, tuple[float, float]], k: int, seed: int = 0
) -> list[GripperSpec]:
    """k gripper variants, Latin-hypercube spread within bounds (invalid ones redrawn)."""
    from scipy.stats import qmc

    from mjx_pick.studies.sweeps import numeric_fields

    fields = numeric_fields(GripperSpec)
    for name, (lo, hi) in bounds.items():
        if name not in fields:
            raise ConfigError(
                f"design bound {name!r} is not a numeric gripper field: choose from "
                + ", ".join(fields)
            )
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ConfigError(f"design bound {name} = {lo:g}:{hi:g} must have lo < hi")
        for end in (lo, hi):  # a bound outside the field's range: refused as a flag is
            try:
                check_field(gripper, name, end, "gripper")
            except ConfigError as err:
                raise ConfigError(f"design bound {name}={lo:g}:{hi:g}: {err}") from None
    if not bounds:
        raise ConfigError("a design search needs at least one bound (e.g. finger_width_mm=10:40)")
    check_range("design", "variants", k, 1, 10_000)
    sampler = qmc.LatinHypercube(d=len(bounds), seed=seed)
    lo = np.array([b[0] for b in bounds.values()])
    hi = np.array([b[1] for b in bounds.values()])
    out, names, tries = [], set(), 0
    while len(out) < k and tries < 20 * k:
        u = sampler.random(k - len(out))
        tries += len(u)
        for row in lo + u * (hi - lo):
            values = {name: float(round(v, 1)) for name, v in zip(bounds, row, strict=True)}
            label = "-".join(f"{_short(n)}{v:g}" for n, v in values.items())
            if label in names:  # the same design, rounded: drawn again
                continue
            try:
                out.append(dataclasses.replace(gripper, name=f"{gripper.name}~{label}", **values))
            except ConfigError:
                continue  # e.g. fingers that cannot fit the stroke: draw again
            names.add(label)
    if len(out) < k:
        shown = ", ".join(f"{n}={a:g}:{b:g}" for n, (a, b) in bounds.items())
        raise ConfigError(
            f"design: could draw only {len(out)} distinct valid gripper variants within "
            f"{shown} (each value rounded to 0.1 of its unit) of the {k} asked for: ask for "
            "fewer (--variants) or widen the bounds"
        )
    return out


def _short(field: str) -> str:
    return {"finger_width_mm": "w", "finger_depth_mm": "d", "stroke_mm": "s"}.get(field, field)


@dataclasses.dataclass(frozen=True)
class DesignRequest:
    """What :func:`design_search` searches: variants drawn within the bounds, rounds of
    halving thirds, the final comparison's pick-points (None: 4 n) and the ranking
    ('success' or 'score')."""

    variants: int = 12
    rounds: int = 3
    final_n: int | None = None
    rank_by: str = "success"

    def check(self, n: int) -> None:
        check_range("design", "rounds", self.rounds, 1, 20)
        check_range("design", "n", n, 1, 1e8)
        if self.final_n is not None:
            check_range("design", "final_n", self.final_n, 1, 1e8)
        if self.rank_by not in ("success", "score"):
            raise ConfigError(
                f"rank_by = {self.rank_by!r} is not allowed: choose 'success' or 'score'"
            )


def design_search(
    obj: ObjectModel,
    bounds: dict[str, tuple[float, float]],
    base: Settings | None = None,
    options: RunOptions | None = None,
    *,
    request: DesignRequest | None = None,
    simulator: Simulator | None = None,
    **fields,
) -> DesignResult:
    """Search gripper geometry within bounds; see the module docstring.

    Round r simulates the surviving variants on n * 2**r shared pick-points (n: 64 by
    default) and keeps the best third (at least one); the survivor is then compared
    with the base gripper on final_n (default 4 n) fresh pick-points. With grasps given
    as poses (options.grasps, as compare's): antipodal grasps drawn likewise, or every
    grasp of a file in each round and the final (a file has no fresh grasps). The answer is
    always a variant within bounds (the base gripper is the reference): variants that
    no pick-point can fit (``pickpoints.stroke_refusal``) are left out before any
    draw, and a search none of whose variants fits is refused. options, or its
    fields as keywords (``options.RunOptions``): out is saved to as the rounds go (their
    finished chunks, ``engine.chunks.ChunkStore``), so that resume continues an
    interrupted search (on a complete one: reads it back); ray runs every
    round on a Ray cluster ("auto" or "HOST:PORT"; mjx_pick.engine.cluster), this process
    writing out; progress: a progress bar on stderr (its total grows as each round
    starts: a round's size depends on the last). simulator: run through this one (kept
    open; backend, batch_size and ray are then its own).
    """
    req, opts = split_fields(DesignRequest, request, options, fields)
    n, seed, pick_config = opts.n_or(64), opts.seed, opts.pick_config
    base = base or Settings()
    req.check(n)
    t0 = time.perf_counter()
    request = {"object": obj.summary(), "bounds": {k: list(v) for k, v in bounds.items()}}
    request.update(base=to_dict(base), variants=req.variants, n=n, rounds=req.rounds)
    request.update(seed=seed, final_n=req.final_n, rank_by=req.rank_by)
    request.update(picks=to_dict(pick_config))
    if opts.grasps == "topdown":
        pool, too_narrow = _fitting_variants(obj, base, bounds, req.variants, seed, pick_config)
    else:
        from mjx_pick.studies.grasp_sources import source_key

        # grasps given as poses (their source checked with the options): every variant is
        # checked on each grasp by the 6-DoF checks as the rounds go (compare's
        # shared_grasps); none fitting any is refused there, before its first simulation
        request.update(grasps=source_key(opts))
        pool, too_narrow = sample_variants(base.gripper, bounds, req.variants, seed), 0
    request.update(too_narrow=too_narrow)
    search = {"rounds": req.rounds, "n": n, "final_n": req.final_n, "seed": seed}
    search.update(rank_by=req.rank_by, pick_config=pick_config)
    # every comparison of the search draws its grasps from the same source
    search.update(grasps=opts.grasps, antipodal=opts.antipodal, depth_mm=opts.depth_mm)
    with opts.opening("design", obj, request, simulator) as study:
        if study.complete:
            return _read_design(study.out_dir, obj, base, pool, **search)
        return _design(obj, base, pool, study, bounds, request, t0, opts.progress, **search)


def _fitting_variants(obj, base: Settings, bounds, variants: int, seed: int, pick_config):
    """(the variants drawn within bounds that some pick-point fits, how many were left
    out): a variant none fits is no design; none left, a ConfigError (the base gripper
    is the reference, never the answer)."""
    drawn = sample_variants(base.gripper, bounds, variants, seed)
    fitting = [g for g in drawn if pp.stroke_refusal(obj, g, pick_config, base.grasp) is None]
    if not fitting:
        why = pp.stroke_refusal(obj, drawn[0], pick_config, base.grasp)
        raise ConfigError(
            f"design: none of the {len(drawn)} variants within "
            + ", ".join(f"{k}={lo:g}:{hi:g}" for k, (lo, hi) in bounds.items())
            + f" can take the part; e.g. {why}"
        )
    return fitting, len(drawn) - len(fitting)


def _design(
    obj, base, pool, study, bounds, request, t0, progress, *,
    rounds, n, final_n, seed, rank_by, pick_config, grasps, antipodal, depth_mm,
) -> DesignResult:  # fmt: skip
    """design_search once its inputs are checked, its simulator made and out claimed
    (study: the opened study, ``options.OpenStudy``)."""
    sim = study.sim
    # every comparison of the search: the same sampling, ranking, simulator and chunks
    rank = {"rank_by": rank_by, "pick_config": pick_config, "simulator": sim}
    rank.update(_store=study.store, grasps=grasps, antipodal=antipodal, depth_mm=depth_mm)
    desc = f"design: {rounds} rounds + final ({sim.runner.backend_name})"
    with showing_progress(sim.runner, desc, "sim", progress) as bar:
        best, history = _rounds(obj, base, pool, rounds, n, seed, bar, rank)
        contenders = [best] if best == base.gripper else [best, base.gripper]
        if bar is not None:
            fresh = {"topdown": "fresh pick-points", "antipodal": "fresh antipodal grasps"}
            on = fresh.get(grasps, "the file's grasps")
            bar.note(f"final: the best against the base gripper on {on}")
        final_seed = seed + 1_000_003
        final = compare(obj, contenders, base, n=final_n or 4 * n, seed=final_seed, **rank)
    result = DesignResult(best, base.gripper, final, history, None)
    if study.out_dir is not None:
        _write_design(study.out_dir, obj, base, bounds, result, seed, sim.rollouts)
        study.close(request, sim.runner.describe(time.perf_counter() - t0))
    return result


def _rounds(obj, base, pool, rounds: int, n: int, seed: int, bar, rank: dict):
    """The search's rounds: round r compares the pool on n * 2**r pick-points and keeps
    the best third (the last round: the best). Returns (the best, each round's
    ranking); a best that picks nothing is a ConfigError."""
    history = []
    for r in range(rounds):
        if bar is not None:
            bar.note(f"round {r + 1}/{rounds}: {len(pool)} grippers")
        res = compare(obj, pool, base, n=n * 2**r, seed=seed, **rank)
        history.append(res.ranking)
        keep = max(1, math.ceil(len(pool) / 3)) if r < rounds - 1 else 1
        by_name = {g.name: g for g in pool}
        pool = [by_name[row["gripper"]] for row in res.ranking[:keep]]
    best = pool[0]
    last = next(row for row in history[-1] if row["gripper"] == best.name)
    if last["feasible"] == 0 or last["success_rate"] == 0:
        raise ConfigError(
            f"design: no variant within the bounds picks the part: the best, {best.name}, "
            f"succeeded on none of its {last['feasible']} feasible pick-points; widen the "
            "bounds"
        )
    return best, history


def _write_design(out_dir: Path, obj, base, bounds, result: DesignResult, seed, rollouts) -> None:
    """A design search's outputs: its record, the best gripper's TOML, the final
    comparison's results and pictures."""
    from mjx_pick.core.config import to_toml, write_atomic

    record = {"object": obj.summary(), "bounds": {k: list(v) for k, v in bounds.items()}}
    record.update(best=to_dict(result.best), base=to_dict(base.gripper))
    record.update(final=result.final.ranking, rounds=result.rounds, seed=seed, rollouts=rollouts)
    write_json(out_dir / "design.json", record)
    write_atomic(out_dir / "best_gripper.toml", to_toml(result.best))
    write_parquet(out_dir / "results.parquet", result.final.table)
    plot_comparison(obj, result.final, out_dir)
    result.out_dir = out_dir


def _read_design(
    out_dir: Path, obj, base, pool, *, rounds, n, final_n, seed, rank_by, pick_config,
    grasps, antipodal, depth_mm,
) -> DesignResult:  # fmt: skip
    """A complete design search's folder read back (resume has nothing to do): the
    winner is the pool's variant of that name (the pool is drawn again from the seed),
    the final comparison rebuilt as compare's (:func:`_read_comparison`)."""
    import json

    saved = json.loads((out_dir / "design.json").read_text())
    best = {g.name: g for g in pool}[saved["best"]["name"]]
    contenders = [best] if best == base.gripper else [best, base.gripper]
    picks = pick_config or pp.PickConfig()
    final_seed = seed + 1_000_003
    source = RunOptions(grasps=grasps, antipodal=antipodal, depth_mm=depth_mm)
    final = _read_comparison(
        out_dir, obj, contenders, base, final_n or 4 * n, final_seed, picks, saved["final"],
        source,
    )  # fmt: skip
    return DesignResult(best, base.gripper, final, saved["rounds"], out_dir)
