"""Physical trials in the page (``mjx-pick validate``): a TRIALS.csv read and checked
before a run, and validation.json's figures as the page shows them (no web framework).

Details: docs/gui.md ("Physical trials").
"""

from __future__ import annotations

from pathlib import Path

from mjx_pick.core.config import ConfigError, read_toml
from mjx_pick.gui.formatting import fmt, outcome_words
from mjx_pick.gui.workfolder import confined, inside

# validation.json's figures, in the page's words (a success is the positive class)
FIGURES = (
    ("accuracy", "accuracy (labels that agree)"),
    ("precision", "precision (simulated successes that held)"),
    ("recall", "recall (real successes simulated so)"),
    ("f1", "F1"),
)


def check_trials(path: Path, workdir: Path, shown: str) -> dict:
    """A TRIALS.csv read as validate reads it (``studies.validation.read_trials``: every
    error names the line and the column), and every file it names inside the work
    folder -- its meshes, its gripper TOMLs and the model file ([mjcf] or [urdf]) each
    TOML names; the page has validate read nothing else. shown: the CSV as the page
    names it (the upload's name), in place of where it is stored.

    Returns {"trials", "grasps", "objects" (names), "grippers", "real_success_rate"};
    ConfigError otherwise (OutsideWorkFolder for a file a path or link leads out)."""
    from mjx_pick.core.gripper import preset_names
    from mjx_pick.studies.validation import read_trials

    path = confined(path, workdir)
    try:
        trials = read_trials(path)
    except ConfigError as err:
        text = str(err).replace(str(path), shown).replace(str(path.parent), "the CSV's folder")
        raise ConfigError(text) from None
    for mesh in sorted(set(trials.object)):
        _inside(mesh, workdir, f"{shown}: its mesh")
    grippers, presets = sorted(set(trials.gripper)), set(preset_names())
    for gripper in grippers:
        if gripper in presets:
            continue
        toml = _inside(gripper, workdir, f"{shown}: its gripper TOML")
        try:  # read as validate reads it (a byte-order mark too): its model files checked
            data = read_toml(toml, "gripper")
        except ConfigError:
            continue  # validate says what is wrong with it, by its name
        for kind in ("mjcf", "urdf"):
            model = data.get(kind)
            if isinstance(model, dict) and isinstance(model.get("file"), str):
                _inside(toml.parent / model["file"], workdir, f"{toml.name}: its [{kind}] file")
    return {
        "trials": len(trials),
        "grasps": len(set(trials.grasp_index().tolist())),
        "objects": sorted({Path(o).name for o in trials.object}),
        "grippers": [Path(g).name for g in grippers],
        "real_success_rate": float(trials.success.mean()),
    }


def _inside(path, workdir: Path, what: str) -> Path:
    """path inside the work folder, or ConfigError saying what it is and where it lies
    (a path out of it, or a link that leads out)."""
    found = inside(path, workdir)
    if found is None:
        raise ConfigError(
            f"{what} {Path(path).name} lies outside the work folder ({Path(path).resolve()}): "
            "the page reads only files inside it; put it beside the CSV"
        )
    return found


def trials_text(name: str, s: dict) -> str:
    """What the page says of checked trials (``check_trials``'s summary)."""
    return (
        f"{name}: {s['trials']:,} trials of {s['grasps']:,} grasps on "
        f"{', '.join(s['objects'])} with {', '.join(s['grippers'])}; real success rate "
        f"{100 * s['real_success_rate']:.1f} %"
    )


def _value(f: dict) -> str:
    v = f.get("value")
    return "-" if v is None else f"{v:.3f}"  # undefined: no simulated or real success


def _interval(f: dict) -> str:
    lo, hi = f.get("ci95") or (None, None)
    return "-" if lo is None or hi is None else f"{lo:.3f}-{hi:.3f}"


def figure_rows(report: dict) -> list[dict]:
    """validation.json's four figures: {"figure", "value", "interval"} (95 %, a bootstrap
    over grasps)."""
    return [
        {"figure": words, "value": _value(report[key]), "interval": _interval(report[key])}
        for key, words in FIGURES
    ]


def confusion_rows(report: dict) -> list[dict]:
    """The confusion matrix as two rows (real success, real failure) of trials."""
    c = report["confusion"]
    return [
        {"real": "real success", "sim_success": c["tp"], "sim_failure": c["fn"]},
        {"real": "real failure", "sim_success": c["fp"], "sim_failure": c["tn"]},
    ]


def object_rows(report: dict) -> list[dict]:
    """Each object's figures: trials, grasps, the four figures, its real success rate."""
    rows = []
    for name, f in report["per_object"].items():
        row = {"object": name, "trials": f["n"], "grasps": f["grasps"]}
        for key, _ in FIGURES:
            row[key] = f"{_value(f[key])} ({_interval(f[key])})"
        row["real_success_rate"] = fmt(float(f["real_success_rate"]))
        rows.append(row)
    return rows


def checks_text(report: dict) -> str:
    """The checks' rejections (each a predicted failure) and the simulated outcomes, in
    words."""
    from mjx_pick.core.grasp_checks import REASON_WORDS

    c = report["checks"]
    if c["rejected_trials"]:
        why = "; ".join(
            f"{v['trials']}: {REASON_WORDS.get(k, k)} ({v['held_on_the_robot']} held on the robot)"
            for k, v in c["by_reason"].items()
        )
        n = c["rejected_trials"]
        checks = (
            f"The checks rejected {n} trial{'s' if n != 1 else ''} before simulating "
            f"{'them' if n != 1 else 'it'} (a predicted failure), {c['rejected_that_held']} "
            f"of which held on the robot: {why}."
        )
    else:
        checks = "The checks rejected no trial: every grasp was simulated."
    outcomes = ", ".join(
        f"{outcome_words(k)} {v}" for k, v in (report.get("simulated_outcomes") or {}).items()
    )
    return checks + (f" Simulated outcomes: {outcomes}." if outcomes else "")
