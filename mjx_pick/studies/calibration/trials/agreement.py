"""The agreement of simulation and reality on the tried pick-points."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_pick.core.config import (
    write_atomic,
    write_json,
)
from mjx_pick.core.metrics import wilson_interval
from mjx_pick.outputs.rundir import finish
from mjx_pick.studies.calibration.trials.sheet import load_plan, tried_rows


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
        "sensitivity": _rate(tp, tp + fn),  # real successes predicted as such
        "specificity": _rate(tn, tn + fp),  # real failures predicted as such
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
    out["rows"] = _per_row(pred, t, s, real, correct, rows)
    out["notes"] = agreement_notes(out, pred, real)
    return out


def _rate(num: int, den: int) -> dict | None:
    """num / den with its Wilson 95 % interval, {value, ci}; None without a denominator."""
    return None if den == 0 else {"value": num / den, "ci": list(wilson_interval(num, den))}


def _per_row(pred, t, s, real, correct, rows: list[dict] | None) -> list[dict]:
    """The per pick-point table: rows' entry (or {}) with the prediction, the tried
    successes and trials, the real verdict with its Wilson 95 % interval and whether
    they agree; pred, t, s, real, correct: (R,) arrays."""
    per = []
    for i in range(len(pred)):
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
    return per


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
    from mjx_pick.studies.calibration.data import write_outcomes

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
