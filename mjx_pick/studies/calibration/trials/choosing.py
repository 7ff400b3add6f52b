"""Which pick-points teach the most: the information a trial carries (BALD) and the
choice of a round."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import (
    ConfigError,
)
from mjx_pick.studies.calibration.trials.runs import Simulations, information
from mjx_pick.studies.calibration.trials.sheet import MIN_BITS

# two pick-points closer than this are the same template (placing error is ~1 mm)
SAME_XY_MM, SAME_YAW_DEG = 2.0, 5.0


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


def new_round(
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
    sub, picks = _feasible_candidates(sims, table, exclude, pool, pick_config)
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
    success, score, failure = _prediction_under_test(sub, info, predictions_from_table)
    rows = _candidates(picks, info, success, score, failure, len(draws))
    chosen, why = choose(rows, n, info_share)
    grip_force_n = float(sims.settings.grasp.grip_force_n)
    picks_out = _sheet_rows(rows, chosen, why, number, repeats, grip_force_n)
    notes = _round_notes(rows, len(chosen), picks_out, n, names, number)
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


def _feasible_candidates(sims: Simulations, table: pa.Table, exclude, pool: int, pick_config):
    """table's candidate pool (``candidate_pool``, at most pool rows not in exclude)
    that the gripper can reach: (those rows (C,), their feasible picks). ConfigError
    when no usable pick-point is left to try."""
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
    return sub.filter(pa.array(keep)), picks


def _prediction_under_test(sub: pa.Table, info, from_table: bool) -> tuple:
    """(success, score, failure) (C,) of the prediction the trials test: the run's own
    answer in sub where from_table, else the nominal re-simulation's (info)."""
    run_success = np.asarray(sub["success"], bool)
    run_score = np.asarray(sub["score"], float)
    run_failure = np.asarray(sub["failure"].to_pylist(), dtype=object)
    if from_table:
        return run_success, run_score, run_failure
    return info.success, info.score, info.failure


def _candidates(picks, info, success, score, failure, n_draws: int) -> list[dict]:
    """One row per candidate pick-point: its pose, the prediction under test (success,
    score, failure), whether a re-run agrees, and its success probability at the
    nominal parameters and per draw with the information it carries (bits)."""
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
                "p_lo": float(info.p_draws[:, j].min()) if n_draws else float("nan"),
                "p_hi": float(info.p_draws[:, j].max()) if n_draws else float("nan"),
                "bits": float(info.bits[j]),
            }
        )
    return rows


def _sheet_rows(rows, chosen, why, number: int, repeats: int, grip_force_n: float) -> list:
    """The chosen candidates as the round's plan entries, one template page each, with
    why each was chosen."""
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
                "grip_force_n": grip_force_n,
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
    return picks_out


def _round_notes(rows, n_chosen: int, picks_out, n: int, names, number: int) -> list[str]:
    """What the round cannot do: fewer pick-points than asked, no candidate informative
    about the parameters, no predicted success (or failure) among those chosen."""
    notes = []
    if n_chosen < n:
        notes.append(
            f"only {n_chosen} distinct pick-points among the {len(rows)} candidates: "
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
    return notes
