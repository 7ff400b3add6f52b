"""The trials folder's files: the plan (trials.json) and the sheet a person fills
(trials.csv), read back with every value checked."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from mjx_pick.core.config import (
    ConfigError,
    open_csv,
    write_atomic,
)
from mjx_pick.outputs.rundir import read_manifest
from mjx_pick.studies.calibration.data import OPTIONAL, REQUIRED, Outcomes, outcomes_from_rows

COMMAND = "trials"


PLAN = "trials.json"


SHEET = "trials.csv"


CANDIDATES = "candidates.parquet"


SIM_COLUMNS = ("sim_success", "sim_p", "sim_failure", "info_bits", "why")


SHEET_COLUMNS = ("page", "round", "pick_id", *REQUIRED, "lift_time_s", "trace", *SIM_COLUMNS)


ALLOWED = ("page", "round", "pick_id", *REQUIRED, *OPTIONAL, *SIM_COLUMNS)


MIN_BITS = 0.05  # below this a pick-point's outcome says next to nothing about the parameters


POSE_TOL = 5e-3  # mm, deg, N: the sheet's values are written with 4 decimals


TemplateWriter = Callable[[Path, dict, dict], None]


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
    with open_csv(path, "trials sheet") as fh:
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
