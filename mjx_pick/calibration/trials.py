"""The paper's validation loop as a study: which pick-points to try on the real cell,
the sheet a person fills at the robot, the agreement of simulation and reality, and
the fit of the recorded outcomes with the agreement before and after.

The paper (Bencak et al. 2023, sections 3.8, 4.2 and 4.3) printed 1:1 templates of the
10 best and 10 worst simulated pick-points, placed the real object on each under the
real gripper, tried each 5 times and counted how often the simulation was right (15 of
20). This module is that loop's logic; ``mjx_pick.trials`` adds the printed templates
(the outputs layer) and ``mjx-pick trials`` the commands.

A trials folder (owned by the ``trials`` command, ``rundir``) holds:

* ``trials.json`` -- the plan: the evaluate run it came from, the object, the settings,
  and per round the chosen pick-points with their predictions;
* ``trials.csv`` -- the sheet a person fills: a superset of the measured-outcomes format
  (``data.py``): page and round (of the template), pick_id, the calibration columns
  (x_mm, y_mm, yaw_deg, grip_force_n, trials, successes, lift_time_s, trace) and the
  simulation's prediction (sim_success, sim_p, sim_failure, info_bits, why; left out
  when the plan is blind). ``successes`` stays blank until the pick-point was tried;
* ``candidates.parquet`` -- the run's pick-points, from which every round chooses;
* after ``agree``: ``agreement.json`` / ``agreement.md`` and ``outcomes.csv`` (the tried
  rows in the calibrate format); after ``fit``: ``fit-round<r>/`` (calibrate's folder
  plus ``agreement.json`` / ``.md`` before and after) and the next round's rows.

Which pick-points teach the most (:func:`information`): every candidate is simulated
under S draws of the uncertain contact parameters (from their prior; after a fit, from
its intervals), each at R real placements around the template pose (the placing error,
as in ``robust``). With p_s the fraction of placements that succeed under draw s, the
expected information one trial gives about the parameters (BALD, Houlsby et al. 2011) is

    I = H(mean_s p_s) - mean_s H(p_s)     bits, H the binary entropy,

large where the draws disagree on the outcome and each is sure of it, zero where every
draw predicts the same -- however uncertain the placement makes it. A round takes about
``info_share`` of its pick-points by I; the rest as the paper did, the best-scoring
predicted successes and the worst predicted failures, which test the model's confident
claims and give the agreement both kinds of prediction.

Agreement (:func:`agreement`): a tried pick-point is a real success when at least half
its trials succeeded (as ``Problem.accuracy``); the prediction is the simulation's
success at the template pose. Confusion matrix, accuracy with its Wilson 95 % interval,
the accuracy of always predicting the more common real outcome (a model that does not
beat it has shown nothing), and notes wherever the data cannot say more.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from mjx_pick import pickpoints as pp
from mjx_pick.calibration.data import OPTIONAL, REQUIRED, Outcomes, outcomes_from_rows
from mjx_pick.calibration.identify import Z95
from mjx_pick.calibration.parameters import (
    ParamSpace,
    canonical_params,
    param_space,
    row_inputs,
    start_values,
)
from mjx_pick.config import (
    ConfigError,
    check_range,
    from_mapping,
    to_dict,
    write_atomic,
    write_json,
    write_parquet,
)
from mjx_pick.engine import Engine
from mjx_pick.grasp import GraspConfig
from mjx_pick.gripper import GripperSpec
from mjx_pick.kernels import grasp as gk
from mjx_pick.metrics import mcnemar_p, wilson_interval
from mjx_pick.objects import ObjectModel
from mjx_pick.physics import ContactParams, SolverParams
from mjx_pick.rundir import claim, config_hash, finish, read_manifest
from mjx_pick.scene import build_scene
from mjx_pick.simulate import Settings, make_inputs

COMMAND = "trials"
PLAN = "trials.json"
SHEET = "trials.csv"
CANDIDATES = "candidates.parquet"
# the simulation's columns of the sheet (left out of a blind plan's sheet)
SIM_COLUMNS = ("sim_success", "sim_p", "sim_failure", "info_bits", "why")
SHEET_COLUMNS = ("page", "round", "pick_id", *REQUIRED, "lift_time_s", "trace", *SIM_COLUMNS)
ALLOWED = ("page", "round", "pick_id", *REQUIRED, *OPTIONAL, *SIM_COLUMNS)
MIN_BITS = 0.05  # below this a pick-point's outcome says next to nothing about the parameters
# two pick-points closer than this are the same template (placing error is ~1 mm)
SAME_XY_MM, SAME_YAW_DEG = 2.0, 5.0
POSE_TOL = 5e-3  # mm, deg, N: the sheet's values are written with 4 decimals

TemplateWriter = Callable[[Path, dict, dict], None]


# --------------------------------------------------------------------------- inputs


def check_object(theirs: dict, obj: ObjectModel, where: str) -> None:
    """Refuse an object that is not the one `theirs` (an ``ObjectModel.summary``) was
    made for: name, mass, height and silhouette must match."""
    mine = obj.summary()
    differ = []
    for k in ("name", "mass_g", "height_mm", "outline_wkt"):
        a, b = theirs.get(k), mine.get(k)
        if a is None:
            continue
        same = math.isclose(a, b, rel_tol=1e-6) if isinstance(a, int | float) else a == b
        if not same:
            differ.append(k)
    if differ:
        raise ConfigError(
            f"{where} is of object {theirs.get('name')!r} ({theirs.get('mass_g', 0):g} g), "
            f"not this {mine['name']!r} ({mine['mass_g']:g} g): they differ in "
            f"{', '.join(differ)}; give the object (and --mass-g ...) it was made with"
        )


def settings_of(config: dict, where: str) -> tuple[Settings, pp.PickConfig]:
    """The Settings and PickConfig an evaluate run's config.json (or a plan) records."""
    try:
        s = Settings(
            from_mapping(GripperSpec, config["gripper"], where=f"{where}: gripper"),
            from_mapping(ContactParams, config["contact"], where=f"{where}: contact"),
            from_mapping(SolverParams, config["solver"], where=f"{where}: solver"),
            from_mapping(GraspConfig, config["grasp"], where=f"{where}: grasp"),
        )
        picks = from_mapping(pp.PickConfig, config["picks"], where=f"{where}: picks")
    except KeyError as err:
        raise ConfigError(f"{where} does not record the {err.args[0]} settings") from None
    return s, picks


class RunSource(NamedTuple):
    """A finished evaluate folder: its results table, configuration and settings."""

    path: Path
    table: pa.Table
    config: dict
    settings: Settings
    pick_config: pp.PickConfig


def read_run(run_dir, obj: ObjectModel) -> RunSource:
    """An evaluate output folder, checked: finished, of this object, with its table."""
    path = Path(run_dir)
    if not path.is_dir():
        raise ConfigError(f"run {str(path)!r} is not a folder (give an evaluate --out folder)")
    manifest = read_manifest(path) or {}
    if manifest.get("command") not in (None, "evaluate"):
        raise ConfigError(
            f"run {path} holds the results of `mjx-pick {manifest['command']}`, not of "
            "`mjx-pick evaluate`: plan trials from an evaluate folder"
        )
    if manifest.get("status") not in (None, "complete"):
        raise ConfigError(
            f"run {path} did not finish (status {manifest['status']}): finish it with "
            "`mjx-pick evaluate ... --resume` first"
        )
    missing = [n for n in ("results.parquet", "config.json") if not (path / n).is_file()]
    if missing:
        raise ConfigError(f"run {path} is not an evaluate output folder: no {', '.join(missing)}")
    config = json.loads((path / "config.json").read_text())
    check_object(config.get("object") or {}, obj, f"run {path}")
    table = pq.read_table(path / "results.parquet")
    need = ("pick_id", "x_mm", "y_mm", "yaw_deg", "opening_mm", "success", "score", "failure")
    absent = [c for c in need if c not in table.column_names]
    if absent:
        raise ConfigError(f"run {path}: results.parquet has no column(s) {', '.join(absent)}")
    settings, picks = settings_of(config, f"run {path}/config.json")
    return RunSource(path, table, config, settings, picks)


# ----------------------------------------------------------------------- simulation


class Simulations:
    """One compiled scene of base settings; each parameter vector is per-row data,
    mapped as a fit maps it (``parameters.row_inputs``: contact through
    ``physics.mujoco_contact``, F_d + force offset), so draws and fits simulate alike."""

    def __init__(
        self, obj: ObjectModel, settings: Settings, backend: str = "auto", batch_size=None
    ):
        s = settings
        self.object, self.settings = obj, s
        self.scene = build_scene(obj, s.gripper, s.contact, s.solver, s.grasp)
        self.engine = Engine(backend, batch_size)
        self._runner = None

    def run(self, picks: pp.PickBatch, values: list[dict]) -> dict[str, np.ndarray]:
        """Simulate every pick-point (N) under each parameter vector (V dicts, name ->
        natural value; {} is the base settings) in ONE engine run.

        Returns (V, N) arrays: success (bool), score, failure (code, ``gk.FAILURES``),
        diverged (bool), lift_height_mm."""
        if self._runner is None:
            self._runner = self.engine.make(self.scene, self.settings.grasp)
        n = len(picks)
        s = self.settings
        base = make_inputs(self.scene, s.grasp, picks, s.overrides(self.scene, n))
        force = np.full(n, s.grasp.grip_force_n)
        parts = [row_inputs(base, self.scene, s, force, v) for v in values]
        inputs = jax.tree.map(lambda *a: np.concatenate(a), *parts)
        out = self.engine.run(self._runner, inputs).results
        keys = ("success", "score", "failure", "diverged", "lift_height_mm")
        return {k: np.asarray(out[k]).reshape(len(values), n) for k in keys}

    @property
    def simulations(self) -> int:
        return self.engine.rollouts


def entropy_bits(p) -> np.ndarray:
    """Binary entropy of success probabilities p (any shape), bits; 0 at 0 and 1."""
    p = np.clip(np.asarray(p, float), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -(p * np.log2(p) + (1 - p) * np.log2(1 - p))
    return np.nan_to_num(h, nan=0.0)


def parameter_draws(
    space: ParamSpace, count: int, seed: int, centre_z=None, sd_z=None
) -> np.ndarray:
    """(count, P) natural parameter values: a Latin hypercube through a Gaussian in each
    parameter's z (value, or log value), truncated to its bounds. Default centre and
    spread: the prior's; after a fit, the fitted value and its interval's."""
    from scipy.stats import qmc, truncnorm

    centre = space.prior_mean if centre_z is None else np.asarray(centre_z, float)
    sd = space.prior_sd if sd_z is None else np.asarray(sd_z, float)
    sd = np.maximum(sd, 1e-9)
    u = qmc.LatinHypercube(d=len(space.names), seed=seed).random(count)
    a, b = (space.z_lo - centre) / sd, (space.z_hi - centre) / sd
    z = centre + sd * truncnorm.ppf(u, a, b)
    return np.asarray(space.natural(np.clip(z, space.z_lo, space.z_hi)), float)


class Information(NamedTuple):
    """What the simulation says about K candidate pick-points.

    success, score, failure (K,): at the template pose under the nominal parameters
    (the prediction); p_nominal (K,): the fraction of R placements that succeed under
    them; p_draws (S, K): the same under each parameter draw; bits (K,): the expected
    information of one trial about the parameters (module docstring)."""

    success: np.ndarray
    score: np.ndarray
    failure: np.ndarray
    p_nominal: np.ndarray
    p_draws: np.ndarray
    bits: np.ndarray


def information(
    sims: Simulations,
    picks: pp.PickBatch,
    nominal: dict,
    draws: list[dict],
    *,
    placements: int,
    jitter_mm: float,
    jitter_deg: float,
    seed: int,
    pick_config: pp.PickConfig | None = None,
) -> Information:
    """Simulate K candidates at `placements` placements each -- the template pose and
    placements - 1 Gaussian draws around it (jitter_mm on x and y, jitter_deg on yaw;
    the fingers open as planned for the template pose) -- under the nominal parameters
    and each draw: one engine run of at most (1 + S) x K x placements simulations (a
    placement where a finger lands on the object or nothing lies between the fingers
    fails unsimulated)."""
    from mjx_pick.robust import placements as place

    k = len(picks)
    ok = np.ones((k, placements), bool)
    batch = picks
    if placements > 1:
        placed = place(
            sims.object,
            picks,
            sims.settings,
            placements - 1,
            jitter_mm,
            jitter_deg,
            seed,
            pick_config,
        )
        ok[:, 1:] = placed.ok.reshape(k, placements - 1)
        if len(placed.draws):
            batch = pp.concat([picks, placed.draws])
    out = sims.run(batch, [nominal, *draws])
    at = np.zeros((1 + len(draws), k, placements), bool)
    at[:, :, 0] = out["success"][:, :k]
    jittered = np.zeros((1 + len(draws), k, placements - 1), bool)
    jittered[:, ok[:, 1:]] = out["success"][:, k:]
    at[:, :, 1:] = jittered
    p = at.mean(axis=-1)
    p_draws = p[1:]
    bits = entropy_bits(p_draws.mean(axis=0)) - entropy_bits(p_draws).mean(axis=0)
    failure = np.asarray(gk.FAILURES, dtype=object)[out["failure"][0, :k]]
    return Information(
        out["success"][0, :k].astype(bool),
        np.asarray(out["score"][0, :k], float),
        failure,
        p[0],
        p_draws,
        np.maximum(bits, 0.0),
    )


# -------------------------------------------------------------------------- choosing


def candidate_pool(table: pa.Table, exclude, size: int) -> np.ndarray:
    """Rows of a results table to consider: not diverged, not tried already, at most
    `size`, half predicted successes and half failures where both exist, each half
    spread evenly over its score ranking (its best and worst included)."""
    ids = np.asarray(table["pick_id"])
    ok = ~np.asarray(table["diverged"], bool) if "diverged" in table.column_names else True
    ok = ok & ~np.isin(ids, np.asarray(list(exclude), np.int64))
    success = np.asarray(table["success"], bool)
    score = np.nan_to_num(np.asarray(table["score"], float), nan=-1.0)
    groups = [np.flatnonzero(ok & success), np.flatnonzero(ok & ~success)]
    groups = [g[np.argsort(-score[g], kind="stable")] for g in groups]
    quota = [min(len(groups[0]), (size + 1) // 2), 0]
    quota[1] = min(len(groups[1]), size - quota[0])
    quota[0] = min(len(groups[0]), size - quota[1])
    chosen = []
    for g, q in zip(groups, quota, strict=True):
        if q:
            at = np.unique(np.round(np.linspace(0, len(g) - 1, q)).astype(int))
            chosen.append(g[at])
    return np.sort(np.concatenate(chosen)) if chosen else np.zeros(0, int)


def _same_template(a: dict, b: dict) -> bool:
    dyaw = abs((a["yaw_deg"] - b["yaw_deg"] + 180.0) % 360.0 - 180.0)
    dxy = math.hypot(a["x_mm"] - b["x_mm"], a["y_mm"] - b["y_mm"])
    return dxy < SAME_XY_MM and dyaw < SAME_YAW_DEG


def choose(rows: list[dict], n: int, info_share: float) -> tuple[list[int], list[str]]:
    """Indices into rows (dicts with x_mm, y_mm, yaw_deg, success, score, failure,
    p_nominal, bits, p_lo, p_hi) of n pick-points to try, and why each.

    About info_share x n by information (at least MIN_BITS); then, alternately, the
    best-scoring predicted success and the worst-scoring predicted failure (the paper's
    check), one class continuing when the other runs out. No two are the same template
    (fewer than n when the rows hold fewer distinct ones)."""
    picked: list[int] = []
    why: list[str] = []

    def take(i: int, reason: str) -> bool:
        if i in picked or any(_same_template(rows[i], rows[j]) for j in picked):
            return False
        picked.append(i)
        why.append(reason)
        return True

    n_info = int(round(n * info_share))
    for i in sorted(range(len(rows)), key=lambda i: -rows[i]["bits"]):
        if len(picked) >= n_info or rows[i]["bits"] < MIN_BITS:
            break
        r = rows[i]
        take(
            i,
            f"informative: {r['bits']:.2f} bits; the parameter draws give it "
            f"{r['p_lo']:.0%}-{r['p_hi']:.0%} success",
        )
    good = sorted((i for i, r in enumerate(rows) if r["success"]), key=lambda i: -rows[i]["score"])
    bad = sorted(
        (i for i, r in enumerate(rows) if not r["success"]), key=lambda i: rows[i]["score"]
    )
    queues = [iter(good), iter(bad)]
    live = [True, True]
    turn = 0
    while len(picked) < n and any(live):
        if live[turn]:
            i = next(queues[turn], None)
            if i is None:
                live[turn] = False
            else:
                r = rows[i]
                reason = (
                    f"check: predicted success, score {r['score']:.2f} (a best pick-point, "
                    "as the paper tried)"
                    if turn == 0
                    else f"check: predicted failure ({r['failure']}), score {r['score']:.2f} "
                    "(a worst pick-point, as the paper tried)"
                )
                if not take(i, reason):
                    continue
        turn = 1 - turn
    return picked, why


def _new_round(
    sims: Simulations,
    table: pa.Table,
    exclude,
    *,
    number: int,
    n: int,
    repeats: int,
    names,
    nominal: dict,
    draws: np.ndarray,
    planned_with: str,
    placements: int,
    jitter_mm: float,
    jitter_deg: float,
    pool: int,
    info_share: float,
    seed: int,
    pick_config,
    predictions_from_table: bool,
) -> dict:
    """Choose a round of pick-points from `table`'s rows (not in exclude); its plan
    entry (``trials.json``'s rounds)."""
    rows_at = candidate_pool(table, exclude, pool)
    if len(rows_at) == 0:
        raise ConfigError(
            "no pick-point left to try: every usable pick-point of the run is in the sheet "
            "(evaluate more pick-points and plan again)"
        )
    sub = table.take(pa.array(rows_at))
    checker = pp.FeasibilityChecker(
        sims.object, sims.settings.gripper, pick_config, sims.settings.grasp
    )
    cols = {c: np.asarray(sub[c]) for c in ("pick_id", "x_mm", "y_mm", "yaw_deg")}
    picks = checker.batch(cols["pick_id"], cols["x_mm"], cols["y_mm"], cols["yaw_deg"], "trials")
    keep = np.isin(cols["pick_id"], picks.pick_id)
    sub = sub.filter(pa.array(keep))
    draw_dicts = [dict(zip(names, map(float, d), strict=True)) for d in draws]
    spent = sims.simulations
    info = information(
        sims,
        picks,
        nominal,
        draw_dicts,
        placements=placements,
        jitter_mm=jitter_mm,
        jitter_deg=jitter_deg,
        seed=seed,
        pick_config=pick_config,
    )
    run_success = np.asarray(sub["success"], bool)
    run_score = np.asarray(sub["score"], float)
    run_failure = np.asarray(sub["failure"].to_pylist(), dtype=object)
    if predictions_from_table:  # the run's own answer is the prediction under test
        success, score, failure = run_success, run_score, run_failure
    else:
        success, score, failure = info.success, info.score, info.failure
    rows = []
    for j in range(len(picks)):
        rows.append(
            {
                "pick_id": int(picks.pick_id[j]),
                "x_mm": float(picks.x_mm[j]),
                "y_mm": float(picks.y_mm[j]),
                "yaw_deg": float(picks.yaw_deg[j]),
                "opening_mm": float(picks.opening_mm[j]),
                "success": bool(success[j]),
                "score": float(np.nan_to_num(score[j], nan=0.0)),
                "failure": str(failure[j]),
                # the same simulation run again (batch and rounding of this run)
                "rerun_agrees": bool(info.success[j] == success[j]),
                "p_nominal": float(info.p_nominal[j]),
                "p_draws": [round(float(v), 4) for v in info.p_draws[:, j]],
                "p_lo": float(info.p_draws[:, j].min()) if len(draws) else float("nan"),
                "p_hi": float(info.p_draws[:, j].max()) if len(draws) else float("nan"),
                "bits": float(info.bits[j]),
            }
        )
    chosen, why = choose(rows, n, info_share)
    picks_out = []
    for page, (i, reason) in enumerate(zip(chosen, why, strict=True), start=1):
        r = rows[i]
        if not r["rerun_agrees"]:
            reason += "; borderline: a re-run of the simulation predicts the opposite"
        picks_out.append(
            {
                "page": page,
                "round": number,
                "pick_id": r["pick_id"],
                "x_mm": round(r["x_mm"], 4),
                "y_mm": round(r["y_mm"], 4),
                "yaw_deg": round(r["yaw_deg"], 4),
                "opening_mm": r["opening_mm"],
                "grip_force_n": float(sims.settings.grasp.grip_force_n),
                "trials": int(repeats),
                "sim_success": r["success"],
                "sim_score": round(r["score"], 4),
                "sim_failure": r["failure"],
                "sim_rerun_agrees": r["rerun_agrees"],
                "sim_p": round(r["p_nominal"], 4),
                "p_draws": r["p_draws"],
                "info_bits": round(r["bits"], 4),
                "why": reason,
            }
        )
    notes = []
    if len(chosen) < n:
        notes.append(
            f"only {len(chosen)} distinct pick-points among the {len(rows)} candidates: "
            f"asked for {n} (evaluate more pick-points, or raise --pool)"
        )
    if not any(r["bits"] >= MIN_BITS for r in rows):
        notes.append(
            f"no candidate's outcome depends on {', '.join(names)} within their "
            f"{'prior' if number == 1 else 'fitted spread'}: these trials test the model, "
            "they cannot narrow its parameters"
        )
    for label, want in (("success", True), ("failure", False)):
        if not any(p["sim_success"] == want for p in picks_out):
            notes.append(
                f"no chosen pick-point is predicted to be a {label}: the agreement will not "
                f"test predicted {label}s"
            )
    return {
        "round": number,
        "planned_with": {"source": planned_with, "values": dict(nominal)},
        "parameters": list(names),
        "draws": [[float(v) for v in d] for d in draws],
        "candidates": len(rows),
        "simulations": int(sims.simulations - spent),
        "notes": notes,
        "picks": picks_out,
        # every candidate simulated, chosen or not: what the choice was made from
        "candidates_info": [
            {k: r[k] for k in ("pick_id", "success", "p_nominal", "bits")} for r in rows
        ],
    }


# ------------------------------------------------------------------------------ plan


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
    backend: str = "auto",
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
        is marked complete (``mjx_pick.trials`` passes the 1:1 PDF writer).

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
    out_dir = claim(out, COMMAND, config_hash(request), overwrite=overwrite)
    sims = Simulations(obj, src.settings, backend, batch_size)
    space = _space(obj, src.settings, sims, names, options["bounds"], options["priors"])
    z_draws = parameter_draws(space, draws, seed)
    rnd = _new_round(
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
    s = src.settings
    plan = {
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
    write_parquet(out_dir / CANDIDATES, src.table)
    write_json(out_dir / PLAN, plan)
    header = [c for c in SHEET_COLUMNS if not (blind and c in SIM_COLUMNS)]
    write_sheet(out_dir / SHEET, header, [sheet_row(p) for p in rnd["picks"]])
    if write_templates is not None:
        write_templates(out_dir, plan, rnd)
    meta = sims.engine.describe()
    finish(out_dir, command=COMMAND, config=request, seed=seed, **meta)
    return plan


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


def load_plan(folder) -> dict:
    """A trials folder's plan, refused when the folder is not one."""
    path = Path(folder)
    if not (path / PLAN).is_file():
        raise ConfigError(
            f"{path} is not a trials folder (no {PLAN}): make one with `mjx-pick trials plan`"
        )
    manifest = read_manifest(path) or {}
    if manifest.get("command") != COMMAND:
        raise ConfigError(
            f"{path} was written by `mjx-pick {manifest.get('command')}`, not by "
            "`mjx-pick trials plan`"
        )
    try:
        plan = json.loads((path / PLAN).read_text())
    except ValueError as err:
        raise ConfigError(f"{path / PLAN} is not valid JSON ({err})") from None
    if plan.get("format") != 1 or not plan.get("rounds"):
        raise ConfigError(f"{path / PLAN} is not a plan this version reads")
    return plan


def plan_settings(plan: dict, folder) -> tuple[Settings, pp.PickConfig]:
    return settings_of(plan["settings"], f"{Path(folder) / PLAN}")


# ----------------------------------------------------------------------------- sheet


def sheet_row(p: dict) -> dict:
    """A plan entry as a sheet row (cell text), successes blank."""
    return {
        "page": str(p["page"]),
        "round": str(p["round"]),
        "pick_id": str(p["pick_id"]),
        "x_mm": f"{p['x_mm']:.4f}",
        "y_mm": f"{p['y_mm']:.4f}",
        "yaw_deg": f"{p['yaw_deg']:.4f}",
        "grip_force_n": f"{p['grip_force_n']:g}",
        "trials": str(p["trials"]),
        "successes": "",
        "lift_time_s": "",
        "trace": "",
        "sim_success": "1" if p["sim_success"] else "0",
        "sim_p": f"{p['sim_p']:.2f}",
        "sim_failure": p["sim_failure"],
        "info_bits": f"{p['info_bits']:.3f}",
        "why": p["why"],
    }


def write_sheet(path: Path, header: list[str], rows: list[dict]) -> None:
    """Write the sheet atomically (cells as given; columns not in header dropped)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=header, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, "") for k in header})
    write_atomic(path, buf.getvalue())


def read_sheet(folder) -> tuple[list[str], list[dict]]:
    """The sheet's header and rows (cell text), its columns checked."""
    path = Path(folder) / SHEET
    if not path.is_file():
        raise ConfigError(f"{path} does not exist (the trials folder lost its sheet)")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        header = [h.strip() for h in (reader.fieldnames or [])]
        rows = [{(k or "").strip(): (v or "").strip() for k, v in r.items()} for r in reader]
    missing = [c for c in ("pick_id", *REQUIRED) if c not in header]
    if missing:
        raise ConfigError(
            f"{path}: missing column(s) {', '.join(missing)}; the sheet needs pick_id and "
            f"{', '.join(REQUIRED)}"
        )
    unknown = [c for c in header if c not in ALLOWED]
    if unknown:
        raise ConfigError(
            f"{path}: unknown column(s) {', '.join(unknown)}; allowed: {', '.join(ALLOWED)}"
        )
    return header, rows


class Tried(NamedTuple):
    """The sheet's tried rows: outcomes (R,), their plan entries, their file lines, and
    the lines of the rows not tried yet."""

    outcomes: Outcomes
    entries: list[dict]
    lines: list[int]
    untried: list[int]


def _planned(plan: dict) -> dict[int, dict]:
    return {p["pick_id"]: p for rnd in plan["rounds"] for p in rnd["picks"]}


def check_rows(folder, plan: dict, rows: list[dict]) -> list[dict]:
    """Each sheet row's plan entry; a row that is not as planned is an error naming it."""
    path = Path(folder) / SHEET
    planned = _planned(plan)
    entries, seen = [], {}
    for line, r in enumerate(rows, start=2):
        where = f"{path}, row {line}"
        try:
            pid = int(r["pick_id"])
        except ValueError:
            raise ConfigError(
                f"{where}, column pick_id: {r['pick_id']!r} is not a whole number"
            ) from None
        if pid in seen:
            raise ConfigError(f"{where}: pick_id {pid} is also in row {seen[pid]}")
        seen[pid] = line
        p = planned.get(pid)
        if p is None:
            raise ConfigError(
                f"{where}: pick_id {pid} is not planned in this folder's {PLAN}: a sheet from "
                "another plan? Use the trials.csv that `mjx-pick trials plan` wrote here"
            )
        for col in ("x_mm", "y_mm", "yaw_deg", "grip_force_n"):
            try:
                v = float(r[col])
            except ValueError:
                raise ConfigError(f"{where}, column {col}: {r[col]!r} is not a number") from None
            if abs(v - p[col]) > POSE_TOL:
                raise ConfigError(
                    f"{where} (pick_id {pid}), column {col}: {v:g} is not the planned "
                    f"{p[col]:g}: its template and prediction are for the planned value "
                    "(a sheet from another plan, or an edited row)"
                )
        if r.get("round") and r["round"] != str(p["round"]):
            raise ConfigError(f"{where}: round {r['round']} is not the planned {p['round']}")
        entries.append(p)
    return entries


def tried_rows(folder, plan: dict | None = None, partial: bool = False) -> Tried:
    """The tried rows of the sheet, every row checked against the plan.

    Rows with a blank ``successes`` are not tried yet: an error naming them unless
    partial (then they are left out); a sheet with no tried row is an error."""
    path = Path(folder) / SHEET
    plan = plan or load_plan(folder)
    _, rows = read_sheet(folder)
    if not rows:
        raise ConfigError(f"{path} has no rows")
    entries = check_rows(folder, plan, rows)
    filled = [i for i, r in enumerate(rows) if r["successes"] != ""]
    untried = [i + 2 for i, r in enumerate(rows) if r["successes"] == ""]
    if not filled:
        raise ConfigError(
            f"{path}: no trial recorded yet: fill the successes column (how many of each "
            f"row's trials lifted and held the object), or run `mjx-pick trials record "
            f"{Path(folder)}`"
        )
    if untried and not partial:
        shown = ", ".join(str(x) for x in untried[:10]) + (" ..." if len(untried) > 10 else "")
        raise ConfigError(
            f"{path}: row(s) {shown} have no successes yet: fill them, or pass --partial to "
            f"use the {len(filled)} tried row(s)"
        )
    outcomes = outcomes_from_rows(
        [rows[i] for i in filled], path, [i + 2 for i in filled], label="trials sheet"
    )
    return Tried(outcomes, [entries[i] for i in filled], [i + 2 for i in filled], untried)


def record(folder, ask: Callable[[str], str], say: Callable[[str], None] = print) -> dict:
    """Ask for each untried row's successes and write the sheet after every answer.

    ask(prompt) returns the person's answer: a whole number of successes out of the
    row's trials, "K/N" for K successes of N trials (tried another number of times), an
    empty answer to skip the row, "q" to stop (EOFError stops too). The prompt shows the
    template page and pose, never the prediction. Returns {filled, skipped, left}."""
    plan = load_plan(folder)
    header, rows = read_sheet(folder)
    check_rows(folder, plan, rows)
    todo = [i for i, r in enumerate(rows) if r["successes"] == ""]
    filled = skipped = 0
    for k, i in enumerate(todo):
        r = rows[i]
        prompt = (
            f"[{k + 1}/{len(todo)}] round {r.get('round') or '?'}, page {r.get('page') or '?'}: "
            f"pick {r['pick_id']} (x {float(r['x_mm']):.1f} mm, y {float(r['y_mm']):.1f} mm, "
            f"yaw {float(r['yaw_deg']):.1f} deg, F_d {r['grip_force_n']} N): successes of "
            f"{r['trials']} trials (K, K/N, Enter skips, q stops): "
        )
        while True:
            try:
                answer = ask(prompt).strip().lower()
            except EOFError:
                answer = "q"
            if answer in ("", "q"):
                break
            got = _parse_answer(answer, r["trials"])
            if isinstance(got, str):
                say(got)
                continue
            r["successes"], r["trials"] = str(got[0]), str(got[1])
            write_sheet(Path(folder) / SHEET, header, rows)
            filled += 1
            break
        if answer == "q":
            break
        if answer == "":
            skipped += 1
    left = sum(1 for r in rows if r["successes"] == "")
    return {"filled": filled, "skipped": skipped, "left": left}


def _parse_answer(answer: str, trials_text: str) -> tuple[int, int] | str:
    """(successes, trials) of an answer, or the message saying why it is not one."""
    k_text, slash, n_text = answer.partition("/")
    if not slash and not trials_text:
        return f"{answer!r}: this row has no trials count: answer K/N (K successes of N trials)"
    try:
        k = int(k_text)
        n = int(n_text) if slash else int(float(trials_text))
    except ValueError:
        return f"{answer!r}: give a whole number of successes (or K/N, Enter, q)"
    if n < 1 or not 0 <= k <= n:
        return f"{answer!r}: successes must lie in 0..{n} (and trials >= 1)"
    return k, n


# ------------------------------------------------------------------------- agreement


def agreement(predicted, trials, successes, rows: list[dict] | None = None) -> dict:
    """Agreement of predicted successes with tried outcomes ((R,) arrays).

    A row is a real success when successes >= trials / 2. rows: per row, what to
    show beside it in the per pick-point table (pick_id, round, pose, sim_p, ...).
    Returns counts, the confusion matrix, accuracy with its Wilson 95 % interval,
    sensitivity and specificity (with intervals, None without a denominator), the
    majority baseline, trial-level counts, per-row detail and notes."""
    pred = np.asarray(predicted, bool)
    t = np.asarray(trials, float)
    s = np.asarray(successes, float)
    real = s >= 0.5 * t
    n = len(pred)
    correct = pred == real
    k = int(correct.sum())
    tp, fp = int(np.sum(pred & real)), int(np.sum(pred & ~real))
    fn, tn = int(np.sum(~pred & real)), int(np.sum(~pred & ~real))
    lo, hi = wilson_interval(k, n)
    majority = bool(real.sum() * 2 >= n)
    base_k = int(np.sum(real == majority))

    def rate(num, den):
        return None if den == 0 else {"value": num / den, "ci": list(wilson_interval(num, den))}

    out = {
        "pick_points": n,
        "trials": int(t.sum()),
        "correct": k,
        "accuracy": k / n if n else None,
        "accuracy_ci": [lo, hi],
        "confusion": {
            "sim_success_real_success": tp,
            "sim_success_real_failure": fp,
            "sim_failure_real_success": fn,
            "sim_failure_real_failure": tn,
        },
        "sensitivity": rate(tp, tp + fn),  # real successes predicted as such
        "specificity": rate(tn, tn + fp),  # real failures predicted as such
        "baseline": {
            "predict": "success" if majority else "failure",
            "correct": base_k,
            "accuracy": base_k / n if n else None,
        },
        # each trial against its pick-point's prediction (trials of one pick-point are
        # not independent: no interval)
        "trials_agreeing": int(np.sum(np.where(pred, s, t - s))),
        "split": int(np.sum(s * 2 == t)),
    }
    per = []
    for i in range(n):
        row = dict(rows[i]) if rows else {}
        ci = wilson_interval(int(s[i]), int(t[i]))
        row.update(
            predicted=bool(pred[i]),
            successes=int(s[i]),
            trials=int(t[i]),
            real_success=bool(real[i]),
            real_ci=[round(ci[0], 4), round(ci[1], 4)],
            agrees=bool(correct[i]),
        )
        per.append(row)
    out["rows"] = per
    out["notes"] = agreement_notes(out, pred, real)
    return out


def agreement_notes(a: dict, pred, real) -> list[str]:
    """What the agreement does not show, in words."""
    n = a["pick_points"]
    lo, hi = a["accuracy_ci"]
    notes = [
        f"{a['correct']} of {n} pick-points agree; the 95 % interval of the accuracy is "
        f"{lo:.0%}-{hi:.0%}" + (" -- wide: more pick-points narrow it" if hi - lo > 0.3 else "")
    ]
    if a["baseline"]["correct"] >= a["correct"]:
        notes.append(
            f"the simulation does no better than predicting '{a['baseline']['predict']}' "
            f"for every pick-point ({a['baseline']['correct']} of {n})"
        )
    if real.all() or not real.any():
        what = "succeeded" if real.all() else "failed"
        notes.append(
            f"every tried pick-point {what} on the real cell: the agreement cannot show "
            f"whether the simulation tells the other kind apart"
        )
    if pred.all() or not pred.any():
        what = "success" if pred.all() else "failure"
        notes.append(f"the simulation predicted {what} for every tried pick-point")
    if a["split"]:
        notes.append(
            f"{a['split']} pick-point(s) succeeded in exactly half their trials: counted as "
            "real successes (as calibrate counts them)"
        )
    return notes


def _row_detail(entry: dict) -> dict:
    keys = ("pick_id", "round", "page", "x_mm", "y_mm", "yaw_deg", "grip_force_n")
    d = {k: entry[k] for k in keys}
    d.update(sim_p=entry["sim_p"], sim_failure=entry["sim_failure"])
    return d


def agree(folder, partial: bool = False) -> dict:
    """The agreement of the tried rows with the predictions they were planned with,
    overall and per round; writes agreement.json, agreement.md and outcomes.csv (the
    tried rows in the calibrate format) into the folder."""
    from mjx_pick.calibration.data import write_outcomes

    folder = Path(folder)
    plan = load_plan(folder)
    tried = tried_rows(folder, plan, partial)
    o = tried.outcomes
    pred = [e["sim_success"] for e in tried.entries]
    rows = [_row_detail(e) for e in tried.entries]
    overall = agreement(pred, o.trials, o.successes, rows)
    rounds = np.array([e["round"] for e in tried.entries])
    by_round = {}
    for rnd in plan["rounds"]:
        at = np.flatnonzero(rounds == rnd["round"])
        if len(at):
            a = agreement(
                np.asarray(pred)[at], o.trials[at], o.successes[at], [rows[i] for i in at]
            )
            a.pop("rows")
            a["planned_with"] = rnd["planned_with"]["source"]
            by_round[str(rnd["round"])] = a
    result = {
        "folder": str(folder),
        "object": plan["object"]["name"],
        "gripper": plan["settings"]["gripper"]["name"],
        "untried_rows": tried.untried,
        "overall": overall,
        "by_round": by_round,
    }
    write_json(folder / "agreement.json", result)
    write_atomic(folder / "agreement.md", agreement_md(result))
    write_outcomes(folder / "outcomes.csv", o)
    finish(folder, command="trials-agree", config={"partial": partial})
    return result


def _confusion_md(a: dict) -> list[str]:
    c = a["confusion"]
    return [
        "| | real success | real failure |",
        "|---|---|---|",
        f"| **simulated success** | {c['sim_success_real_success']} | "
        f"{c['sim_success_real_failure']} |",
        f"| **simulated failure** | {c['sim_failure_real_success']} | "
        f"{c['sim_failure_real_failure']} |",
    ]


def _summary_md(a: dict) -> list[str]:
    lo, hi = a["accuracy_ci"]
    lines = [
        f"Accuracy **{a['correct']}/{a['pick_points']}** ({a['accuracy']:.0%}; 95 % Wilson "
        f"interval {lo:.0%}-{hi:.0%}) over {a['trials']} trials. Always predicting "
        f"'{a['baseline']['predict']}' would get {a['baseline']['correct']}/{a['pick_points']}.",
        "",
    ]
    for key, text in (("sensitivity", "real successes"), ("specificity", "real failures")):
        r = a[key]
        if r is not None:
            lines.append(
                f"* {key}: {r['value']:.0%} of the {text} predicted as such "
                f"(95 % {r['ci'][0]:.0%}-{r['ci'][1]:.0%})"
            )
    lines += [f"* {note}" for note in a["notes"]]
    return lines


def _rows_md(rows: list[dict]) -> list[str]:
    lines = [
        "| round | page | pick | x mm | y mm | yaw deg | F_d N | simulated | placements ok"
        " | real | real 95 % | agrees |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        sim = "success" if r["predicted"] else f"failure ({r.get('sim_failure', '-')})"
        lines.append(
            f"| {r.get('round', '-')} | {r.get('page', '-')} | {r.get('pick_id', '-')} | "
            f"{r.get('x_mm', float('nan')):.1f} | {r.get('y_mm', float('nan')):.1f} | "
            f"{r.get('yaw_deg', float('nan')):.1f} | {r.get('grip_force_n', float('nan')):g} | "
            f"{sim} | {_percent(r.get('sim_p'))} | {r['successes']}/{r['trials']} | "
            f"{r['real_ci'][0]:.0%}-{r['real_ci'][1]:.0%} | {'yes' if r['agrees'] else '**no**'} |"
        )
    return lines


def _percent(v) -> str:
    return "-" if v is None else f"{v:.0%}"


def agreement_md(result: dict) -> str:
    """agreement.md of :func:`agree`'s result."""
    a = result["overall"]
    lines = [
        f"# Simulation and reality: {result['object']} / {result['gripper']}",
        "",
        "Each tried pick-point against the prediction it was planned with (round 1: the "
        "evaluate run; a later round: the fit before it -- a prediction made before its "
        "trials). A pick-point is a real success when at least half its trials succeeded.",
        "",
        *_confusion_md(a),
        "",
        *_summary_md(a),
    ]
    if len(result["by_round"]) > 1:
        lines += ["", "| round | predicted by | agree | accuracy | 95 % |", "|---|---|---|---|---|"]
        for r, b in result["by_round"].items():
            lines.append(
                f"| {r} | {b['planned_with']} | {b['correct']}/{b['pick_points']} | "
                f"{b['accuracy']:.0%} | {b['accuracy_ci'][0]:.0%}-{b['accuracy_ci'][1]:.0%} |"
            )
    if result["untried_rows"]:
        lines += ["", f"Not tried yet: sheet rows {result['untried_rows']}."]
    lines += ["", "## Per pick-point", "", *_rows_md(a["rows"])]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------- fit


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


def fit_trials(
    folder,
    obj: ObjectModel,
    params=None,
    *,
    partial: bool = False,
    steps: int = 40,
    estimator: str = "cma",
    seed: int = 0,
    identify: bool = True,
    bounds: dict | None = None,
    priors: dict | None = None,
    temperature_mm: float | None = None,
    next_n: int = 6,
    backend: str = "auto",
    overwrite: bool = False,
    resume: bool = False,
    log=None,
    write_templates: TemplateWriter | None = None,
    **calibrate_options,
) -> TrialFit:
    """Fit the tried rows, re-simulate them with the fitted parameters, compare the
    agreement before and after, and propose the next round.

    Args:
      folder: a trials folder; obj: its object (checked against the plan).
      params: the parameters to fit (default: the plan's).
      partial: fit the tried rows while others are still blank.
      steps, estimator, seed, identify, bounds, priors, temperature_mm, and
        calibrate_options: as ``calibrate`` / ``Problem`` (bounds and priors: default
        the plan's, for the parameters it names).
      next_n: pick-points of the next round (0: none), chosen as the plan chose, with
        the fitted parameters as the nominal ones and draws from the fit's intervals
        (the prior's spread for a parameter the data did not identify).
      overwrite / resume: replace / continue an earlier fit of the same round.
      write_templates: as :func:`plan_trials`, for the next round.

    Writes ``fit-round<r>/`` (r: the last round with a tried row): calibrate's files
    plus agreement.json and agreement.md; appends the next round to the sheet and the
    plan (replacing a proposed round none of whose rows was tried yet).
    """
    from mjx_pick.calibration.fit import calibrate
    from mjx_pick.calibration.problem import Problem

    folder = Path(folder)
    plan = load_plan(folder)
    check_object(plan["object"], obj, f"trials folder {folder}")
    names = canonical_params(params or plan["params"])
    check_range("trials", "next", next_n, 0, 1000)
    tried = tried_rows(folder, plan, partial)
    settings, pick_config = plan_settings(plan, folder)
    bounds = {**_named(plan.get("bounds"), names), **(bounds or {})}
    priors = {**_named(plan.get("priors"), names), **(priors or {})}
    last = max(e["round"] for e in tried.entries)
    out_dir = folder / f"fit-round{last}"
    if out_dir.exists() and not resume:
        if not overwrite:
            raise ConfigError(
                f"{out_dir} holds an earlier fit of round {last}: pass --overwrite to replace "
                "it (or --resume to continue it)"
            )
        if (read_manifest(out_dir) or {}).get("command") != "calibrate":
            raise ConfigError(f"{out_dir} was not written by a fit: move it away first")
        shutil.rmtree(out_dir)
    problem = Problem(
        obj,
        tried.outcomes,
        names,
        settings,
        temperature_mm=temperature_mm,
        bounds=bounds,
        priors=priors,
        pick_config=pick_config,
        backend=backend,
    )
    res = calibrate(
        problem,
        steps=steps,
        estimator=estimator,
        seed=seed,
        identify=identify,
        out=out_dir,
        resume=resume,
        log=log,
        **calibrate_options,
    )
    space = problem.space
    fitted = space.theta([res.values[n] for n in names])
    vectors = [problem.start_theta(), fitted]
    if res.not_identified:  # the optimum too, to show what the data could not pin
        vectors.append(space.theta([res.optimum[n] for n in names]))
    sim = problem.simulate(np.stack(vectors))
    o = tried.outcomes
    names_of = np.asarray(gk.FAILURES, dtype=object)
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
    right_before = np.array([r["agrees"] for r in before["rows"]])
    right_after = np.array([r["agrees"] for r in after["rows"]])
    p_change = mcnemar_p(right_after, right_before)
    planned = np.array([e["sim_success"] for e in tried.entries])
    rerun_differs = int(np.sum(planned != sim["success"][0]))
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
    report = {
        "parameters": list(names),
        "initial": res.initial,
        "fitted": res.values,
        "optimum": res.optimum,
        "intervals": {k: (res.identifiability or {}).get(k, {}).get("interval") for k in names},
        "not_identified": list(res.not_identified),
        "rows": len(o),
        "before": before,
        "after": after,
        "at_optimum": optimum[0] if optimum else None,
        "mcnemar_p": p_change,
        "rerun_differs": rerun_differs,
        "notes": notes,
    }
    write_json(out_dir / "agreement.json", report)
    write_atomic(out_dir / "agreement.md", fit_md(report, plan))
    next_round = None
    if next_n:
        next_round, note = _propose(
            folder, obj, plan, problem, res, settings, pick_config, last + 1, next_n, backend
        )
        if note:
            notes.append(note)
        if next_round is not None:
            _add_round(folder, plan, next_round)
            if write_templates is not None:
                write_templates(folder, plan, next_round)
    return TrialFit(res, before, after, p_change, rerun_differs, out_dir, next_round, notes, report)


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
    rnd = _new_round(
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


# ---------------------------------------------------------------- synthetic trials


def synthetic_trials(
    folder,
    obj: ObjectModel,
    hidden: dict,
    *,
    jitter_mm: float | None = None,
    jitter_deg: float | None = None,
    seed: int = 1,
    backend: str = "auto",
) -> int:
    """SYNTHETIC outcomes for validation: fill every untried row of the sheet as a real
    cell whose contact parameters are `hidden` ({name: value}, ``parameters.PARAMS``)
    would: each of a row's trials is the simulation at a placement jittered by
    jitter_mm / jitter_deg (default: the plan's placing error; both 0: every trial at
    the template pose). Returns the rows filled."""
    folder = Path(folder)
    plan = load_plan(folder)
    check_object(plan["object"], obj, f"trials folder {folder}")
    hidden = {canonical_params([k])[0]: float(v) for k, v in hidden.items()}
    settings, pick_config = plan_settings(plan, folder)
    header, rows = read_sheet(folder)
    entries = check_rows(folder, plan, rows)
    todo = [i for i, r in enumerate(rows) if r["successes"] == ""]
    if not todo:
        return 0
    from mjx_pick.robust import placements as place

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
