"""The paper's validation loop as a study: which pick-points to try on the real cell,
the sheet a person fills at the robot, the agreement of simulation and reality, and
the fit of the recorded outcomes with the agreement before and after.

The paper (Bencak et al. 2023, sections 3.8, 4.2 and 4.3) printed 1:1 templates of the
10 best and 10 worst simulated pick-points, placed the real object on each under the
real gripper, tried each 5 times and counted how often the simulation was right (15 of
20). This package is that loop's logic; its ``loop`` module adds the printed templates and
``mjx-pick trials`` the commands.

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
