"""The paper's validation loop as a study: which pick-points to try on the real cell,
the sheet a person fills at the robot, the agreement of simulation and reality, and
the fit of the recorded outcomes with the agreement before and after.

Details: docs/calibration.md (studies/calibration/trials/__init__.py).
"""

from mjx_pick.studies.calibration.trials.agreement import (
    agree,
    agreement,
    agreement_md,
    agreement_notes,
)
from mjx_pick.studies.calibration.trials.choosing import candidate_pool, choose
from mjx_pick.studies.calibration.trials.plan import plan_trials
from mjx_pick.studies.calibration.trials.refit import TrialFit, fit_md, fit_trials
from mjx_pick.studies.calibration.trials.runs import (
    Information,
    RunSource,
    Simulations,
    entropy_bits,
    information,
    parameter_draws,
    plan_settings,
    read_run,
    settings_of,
)
from mjx_pick.studies.calibration.trials.sheet import (
    ALLOWED,
    CANDIDATES,
    COMMAND,
    MIN_BITS,
    PLAN,
    POSE_TOL,
    SHEET,
    SHEET_COLUMNS,
    SIM_COLUMNS,
    TemplateWriter,
    Tried,
    check_rows,
    load_plan,
    read_sheet,
    record,
    sheet_row,
    tried_rows,
    write_sheet,
)
from mjx_pick.studies.calibration.trials.simulated import synthetic_trials

__all__ = [
    "ALLOWED",
    "CANDIDATES",
    "COMMAND",
    "Information",
    "MIN_BITS",
    "PLAN",
    "POSE_TOL",
    "RunSource",
    "SHEET",
    "SHEET_COLUMNS",
    "SIM_COLUMNS",
    "Simulations",
    "TemplateWriter",
    "TrialFit",
    "Tried",
    "agree",
    "agreement",
    "agreement_md",
    "agreement_notes",
    "candidate_pool",
    "check_rows",
    "choose",
    "entropy_bits",
    "fit_md",
    "fit_trials",
    "information",
    "load_plan",
    "parameter_draws",
    "plan_settings",
    "plan_trials",
    "read_run",
    "read_sheet",
    "record",
    "settings_of",
    "sheet_row",
    "synthetic_trials",
    "tried_rows",
    "write_sheet",
]
