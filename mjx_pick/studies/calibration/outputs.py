"""What a fit writes: contact.toml (for evaluate --contact, with what it was fitted for),
calibration.json, loss.png, report.md; and the check of a contact.toml against a run.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from mjx_pick.core.config import to_dict, to_toml, toml_value, write_atomic, write_json

# procedure settings that do not change what the contact parameters mean
_PROCEDURE_FREE = ("grip_force_n",)


def fitted_for(problem) -> dict:
    """What a fit's contact parameters belong to: the object, the gripper and the
    procedure (grasp settings but F_d, which each measured row sets; the time step)."""
    s = problem.settings
    obj = problem.object
    grasp = {k: v for k, v in to_dict(s.grasp).items() if k not in _PROCEDURE_FREE}
    return {
        "object": obj.name,
        "object_mass_g": round(obj.mass_kg * 1e3, 4),
        "gripper": s.gripper.name,
        "timestep_s": s.solver.timestep_s,
        "rows": len(problem.outcomes),
        "procedure": grasp,
    }


def mismatch(meta: dict, obj, gripper, grasp, solver) -> list[str]:
    """How a run differs from what a contact.toml was fitted for (empty: it matches).

    meta: the contact file's ``fitted_for`` table (``physics.load_contact``)."""
    out = []
    if meta.get("object") not in (None, obj.name):
        out.append(f"object {meta['object']!r} (this run: {obj.name!r})")
    mass = meta.get("object_mass_g")
    if mass is not None and abs(mass - obj.mass_kg * 1e3) > 1e-3 * max(mass, 1e-9):
        out.append(f"object mass {mass:g} g (this run: {obj.mass_kg * 1e3:g} g)")
    if meta.get("gripper") not in (None, gripper.name):
        out.append(f"gripper {meta['gripper']!r} (this run: {gripper.name!r})")
    ts = meta.get("timestep_s")
    if ts is not None and abs(ts - solver.timestep_s) > 1e-12:
        out.append(f"solver.timestep_s {ts:g} (this run: {solver.timestep_s:g})")
    now = {k: v for k, v in to_dict(grasp).items() if k not in _PROCEDURE_FREE}
    for k, v in (meta.get("procedure") or {}).items():
        if k in now and _differs(v, now[k]):
            out.append(f"grasp.{k} {v!r} (this run: {now[k]!r})")
    return out


def contact_file_notes(path, obj, gripper, grasp, solver) -> list[str]:
    """What a user should hear before a run with ``--contact path``: the set-up the file
    was fitted for when it differs from this run's, and a fitted force offset that the
    run does not apply. Empty when there is nothing to say. The run still goes ahead (a
    user may mean it); the caller prints these lines."""
    from mjx_pick.core.physics import load_contact

    _, meta = load_contact(path)
    notes = []
    diff = mismatch(meta.get("fitted_for") or {}, obj, gripper, grasp, solver)
    if diff:
        notes.append(
            f"warning: --contact {path} was fitted for another set-up: "
            + "; ".join(diff)
            + ". Its parameters may not hold here."
        )
    offset = (
        (meta.get("calibrated") or {}).get("force_offset_n") if meta.get("fitted_for") else None
    )
    if offset:
        notes.append(
            f"note: the fit behind --contact {path} found the gripper squeezes "
            f"F_d {offset:+.3g} N; --grip-force-n sets what is simulated"
        )
    return notes


def _differs(a, b) -> bool:
    if isinstance(a, int | float) and isinstance(b, int | float):
        return abs(float(a) - float(b)) > 1e-9 * max(1.0, abs(float(a)))
    return a != b


def contact_toml(result, problem) -> str:
    """ContactParams as TOML, then [fitted_for] and [calibrated] (read back by
    ``physics.load_contact``; a plain ``load_toml`` rejects them by design)."""
    text = to_toml(result.contact)
    meta = fitted_for(problem)
    proc = meta.pop("procedure")
    lines = ["", "[fitted_for]"]
    lines += [f"{k} = {toml_value(v)}" for k, v in meta.items()]
    lines += ["", "[fitted_for.procedure]"]
    lines += [f"{k} = {toml_value(v)}" for k, v in proc.items() if v is not None]
    lines += ["", "[calibrated]"]
    lines.append(f"parameters = {toml_value(list(problem.names))}")
    lines.append(f"not_identified = {toml_value(list(result.not_identified))}")
    # without the check (--no-identify) an empty list above says nothing: said so here
    ident = result.identifiability or {}
    checked = all((ident.get(n) or {}).get("interval") is not None for n in problem.names)
    lines.append(f"identifiability_checked = {toml_value(checked)}")
    if "force_offset_n" in result.values:
        # not a contact parameter: the gripper squeezes F_d + this when set to F_d
        lines.append(f"force_offset_n = {result.values['force_offset_n']!r}")
    return text + "\n".join(lines) + "\n"


def write_result(result, problem, out_dir: Path) -> None:
    """contact.toml, calibration.json, loss.png, report.md (each written atomically)."""
    space = problem.space
    write_atomic(out_dir / "contact.toml", contact_toml(result, problem))
    write_json(
        out_dir / "calibration.json",
        {
            "parameters": list(problem.names),
            "estimator": result.estimator,
            "initial": result.initial,
            "fitted": result.values,
            "optimum": result.optimum,
            "not_identified": list(result.not_identified),
            "identifiability": result.identifiability,
            "notes": list(getattr(problem, "notes", [])),
            "bounds": {
                n: [float(a), float(b)]
                for n, a, b in zip(space.names, space.lo, space.hi, strict=True)
            },
            "priors_z": {
                n: {"mean": float(m), "sd": float(s), "log": bool(lg)}
                for n, m, s, lg in zip(
                    space.names, space.prior_mean, space.prior_sd, space.log, strict=True
                )
            },
            "noise": dataclasses.asdict(problem.noise),
            "trace_kinds": list(problem.outcomes.trace_kinds()),
            "fitted_for": fitted_for(problem),
            "contact": to_dict(result.contact),
            "accuracy_before": result.accuracy_before,
            "accuracy_after": result.accuracy_after,
            "rows": len(problem.outcomes),
            "rollouts": result.rollouts,
            "history": result.history,
        },
    )
    _loss_plot(result, out_dir / "loss.png")
    write_atomic(out_dir / "report.md", report_md(result, problem))


def _loss_plot(result, path: Path) -> None:
    """loss.png: the loss against the simulations spent, each step's and the best so
    far. The loss is 0.5 |r|^2 per measured trial (``calibration.loss``): a pure
    number, 0 a perfect fit; a log axis where every value is above 0."""
    from matplotlib.ticker import FuncFormatter

    from mjx_pick.outputs.plots import new_figure, save_png

    fig, ax = new_figure(figsize=(7, 4))
    h = result.history
    x = np.array([e["rollouts"] for e in h], float)
    loss = np.array([e["loss"] for e in h], float)
    best = np.array([e["best_loss"] for e in h], float)
    ax.plot(x, loss, "o-", ms=3, lw=1, color="#9ab8d8", label="loss at each step")
    ax.plot(x, best, "-", lw=2, color="#1f4e8c", label="best so far")
    finite = np.concatenate([loss, best])
    finite = finite[np.isfinite(finite)]
    if len(finite) and finite.min() > 0:
        ax.set_yscale("log")
    elif len(finite):  # a zero loss (a perfect fit) has no place on a log axis
        ax.set_yscale("symlog", linthresh=max(1e-6, 1e-3 * float(finite.max())))
    # 0.3, not 3 x 10^-1; between the decades only 2, 3 and 5 (the rest would overlap)
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(
        FuncFormatter(lambda v, _: f"{v:g}" if f"{v:.0e}"[0] in "235" else "")
    )
    if len(h):
        ax.annotate(
            f"best {best[-1]:.4g}",
            (x[-1], best[-1]),
            textcoords="offset points",
            xytext=(-6, 8),
            ha="right",
            fontsize=9,
            color="#1f4e8c",
        )
    ax.set_xlabel("pick-point simulations spent (count)")
    ax.set_ylabel("loss per measured trial\n(0.5 |r|^2 / trials, dimensionless)")
    ax.set_title(
        f"calibration ({result.estimator}): {len(h)} steps, fitting " + ", ".join(result.initial),
        fontsize=10,
    )
    ax.legend(fontsize=9)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    save_png(fig, path)


def bound_words(info: dict) -> str:
    """What a parameter's identifiability entry says of its bounds, in words computed
    from where its value and its interval lie ("" where neither touches one): the
    optimum ON a bound, or only its 95 % interval reaching one -- never the first for
    the second (a start of 0.86 is not "at its lower bound" 0.05 because its
    interval is wide)."""
    lo, hi = info.get("bounds") or (None, None)
    value_of = {"lower": lo, "upper": hi}
    side = info.get("on_bound")
    if side is not None:
        return f"fit at its {side} bound {value_of[side]:.4g}"
    reaches = info.get("interval_reaches") or []
    if reaches:
        ends = " and ".join(f"{s} bound {value_of[s]:.4g}" for s in reaches)
        return f"its 95 % interval reaches its {ends}"
    return ""


def what_was_written(result, name: str) -> str:
    """One sentence: the value written for a parameter the data did not identify, and
    why that one (its start, or its interval's end; at a bound without intervals)."""
    info = (result.identifiability or {}).get(name, {})
    start, written = result.initial[name], result.values[name]
    words = bound_words(info)
    bound = f"{words}; " if words else ""
    if abs(written - start) <= 1e-12 * max(1.0, abs(start)):
        return f"{name}: {bound}kept at its starting value {start:.4g}"
    return (
        f"{name}: {bound}its starting value {start:.4g} lies outside the data's 95 % "
        f"interval, whose nearest end {written:.4g} is written"
    )


def report_md(result, problem) -> str:
    ident = result.identifiability or {}
    lines = [
        "# Calibration",
        "",
        f"{len(problem.outcomes)} measured pick-points, {result.rollouts} simulations, "
        f"estimator `{result.estimator}`.",
        "",
        "| parameter | initial | optimum | 95 % interval | not excluded along its "
        "bounds (global) | identified | used |",
        "|---|---|---|---|---|---|---|",
    ]
    for n in problem.names:
        info = ident.get(n, {})
        iv = info.get("interval")
        iv_text = f"{iv[0]:.4g} - {iv[1]:.4g}" if iv else "-"
        gv = (info.get("global") or {}).get("interval")
        gv_text = f"{gv[0]:.4g} - {gv[1]:.4g}" if gv else "-"
        ok = {True: "yes", False: "**no**"}.get(info.get("identified"), "-")
        opt = (result.optimum or result.values)[n]
        lines.append(
            f"| {n} | {result.initial[n]:.4g} | {opt:.4g} | {iv_text} | {gv_text} | {ok} | "
            f"{result.values[n]:.4g} |"
        )
    if result.not_identified:
        lines += ["", "Not identified by these data (what contact.toml holds for each):"]
        lines += [f"- {what_was_written(result, n)}" for n in result.not_identified]
        lines += [
            "",
            "The data alone do not narrow them to half their prior's range; or, along "
            "the parameter's bounds, other values fit the data as well as the optimum; "
            "or, with the other parameters re-fitted -- the profile likelihood -- values "
            "beyond its interval do: a valley across parameters, as pad friction against "
            "grip force; or the optimum lies on a bound, which stopped the search there. "
            "Measure what moves them (traces, other grip forces) to fit them.",
        ]
    if any((ident.get(n) or {}).get("interval") is None for n in problem.names):
        lines += ["", "Identifiability was not checked (--no-identify): no interval."]
    if not result.history:
        lines += ["", "No estimator step was taken (0 steps): the values are the start's."]
    if getattr(problem, "notes", None):
        lines += ["", "Notes:"] + [f"- {note}" for note in problem.notes]
    if result.history:
        lines += [
            "",
            f"Loss {result.history[0]['loss']:.4f} -> best {result.history[-1]['best_loss']:.4f}"
            f" in {len(result.history)} steps.",
        ]
    for label, acc in (("before", result.accuracy_before), ("after", result.accuracy_after)):
        if acc:
            lines.append(f"Held-out accuracy {label}: {acc['correct']}/{acc['total']}.")
    if "force_offset_n" in result.values:
        lines.append(
            f"The gripper squeezes F_d {result.values['force_offset_n']:+.3g} N: simulate "
            "with --grip-force-n corrected by it to predict the real cell."
        )
    lines += [
        "",
        "Use: `mjx-pick evaluate OBJECT --contact contact.toml` (same object, "
        "gripper and procedure: evaluate warns otherwise).",
    ]
    return "\n".join(lines) + "\n"
