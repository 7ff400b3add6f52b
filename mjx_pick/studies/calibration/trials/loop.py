"""The paper's template-and-trial loop as a product (``mjx-pick trials``).

Details: docs/calibration.md (studies/calibration/trials/loop.py).
"""

from __future__ import annotations

from pathlib import Path

from mjx_pick.core.config import ConfigError, from_mapping
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.objects import ObjectModel
from mjx_pick.outputs.reporting.template import PAPERS_MM, positioning_template
from mjx_pick.studies.calibration.trials import (
    agree,
    fit_trials,
    load_plan,
    plan_trials,
    record,
    synthetic_trials,
    tried_rows,
)

__all__ = [
    "agree",
    "fit",
    "load_plan",
    "plan",
    "record",
    "synthetic_trials",
    "template_path",
    "tried_rows",
]


def template_path(folder, round_number: int) -> Path:
    """Where a round's templates are printed from."""
    return Path(folder) / f"templates_round{round_number}.pdf"


def _template_writer(paper: str):
    """write_templates(folder, plan, round) for the study functions: the round's PDF."""
    if paper not in PAPERS_MM:
        raise ConfigError(f"--paper {paper!r} is not allowed: choose {', '.join(PAPERS_MM)}")

    def write(folder: Path, plan: dict, rnd: dict) -> None:
        import shapely

        outline = shapely.from_wkt(plan["object"]["outline_wkt"])
        gripper = from_mapping(GripperSpec, plan["settings"]["gripper"])
        r = rnd["round"]
        picks = [
            {
                "x_mm": p["x_mm"],
                "y_mm": p["y_mm"],
                "yaw_deg": p["yaw_deg"],
                "opening_mm": p["opening_mm"],
                "label": f"round {r}, pick {p['pick_id']}: try it {p['trials']} times at F_d "
                f"{p['grip_force_n']:g} N; write the successes in trials.csv",
            }
            for p in rnd["picks"]
        ]
        title = f"{plan['object']['name']} / {gripper.name}: trials, round {r}"
        positioning_template(outline, gripper, picks, template_path(folder, r), paper, title)

    return write


def plan(run_dir, obj: ObjectModel, out, *, paper: str = "a4", **options) -> dict:
    """Plan round 1 (``calibration.trials.plan_trials``: options are its keywords) and
    print its templates (templates_round1.pdf, on `paper`: a4 or letter)."""
    return plan_trials(run_dir, obj, out=out, write_templates=_template_writer(paper), **options)


def fit(folder, obj: ObjectModel, params=None, *, paper: str = "a4", **options):
    """Fit the tried rows and plan the next round (``calibration.trials.fit_trials``:
    options are its keywords), printing the next round's templates."""
    writer = _template_writer(paper)
    return fit_trials(folder, obj, params=params, write_templates=writer, **options)
