"""Sim-to-real calibration: fit contact parameters (and the gripper's force offset) to
measured pick outcomes and traces.

One module per responsibility, in the order of the flow:

* ``data`` -- the measured-outcomes CSV and its trace files (read, check, write);
* ``parameters`` -- the parameter space: names, bounds, priors, and the mapping of a
  parameter vector to simulation inputs through ``physics`` / ``Settings``;
* ``loss`` -- residuals per measurement kind (outcome, lift time, force / lift /
  rotation traces, prior) and the loss;
* ``problem`` -- the simulations of a fit, through the one engine;
* ``estimators`` -- smoothed-gradient Adam, random search, CMA-ES, forward mode, as
  ask/tell pairs;
* ``fit`` -- the fit loop (orbax checkpoints, resume) and the least-squares fit with
  ``mujoco.sysid``;
* ``identify`` -- intervals and identifiability from the loss's curvature;
* ``outputs`` -- contact.toml (with what it was fitted for), calibration.json, plots,
  report; the contact-file check used by evaluate;
* ``synthetic`` -- outcomes and traces simulated with hidden parameters;
* ``trials`` -- the paper's template-and-trial loop (``mjx-pick trials``): which
  pick-points to try, the sheet, the agreement of simulation and reality, the fit and
  the next round (imported on its own: ``from mjx_pick.studies.calibration import trials``).
"""

from mjx_pick.studies.calibration.data import (
    OPTIONAL,
    REQUIRED,
    TRACE_KINDS,
    Outcomes,
    example_outcomes,
    make_outcomes,
    read_outcomes,
    write_outcomes,
)
from mjx_pick.studies.calibration.estimators import ESTIMATORS
from mjx_pick.studies.calibration.fit import CalibrationResult, calibrate, least_squares
from mjx_pick.studies.calibration.identify import identifiability
from mjx_pick.studies.calibration.loss import Noise
from mjx_pick.studies.calibration.outputs import fitted_for, mismatch, write_result
from mjx_pick.studies.calibration.parameters import (
    ALIASES,
    FITTABLE,
    PARAMS,
    ParamSpace,
    canonical_params,
    fitted_contact,
    param_space,
)
from mjx_pick.studies.calibration.problem import Evaluation, Problem
from mjx_pick.studies.calibration.synthetic_outcomes import synthetic_outcomes

__all__ = [
    "ALIASES",
    "ESTIMATORS",
    "FITTABLE",
    "OPTIONAL",
    "PARAMS",
    "REQUIRED",
    "TRACE_KINDS",
    "CalibrationResult",
    "Evaluation",
    "Noise",
    "Outcomes",
    "ParamSpace",
    "Problem",
    "calibrate",
    "canonical_params",
    "example_outcomes",
    "fitted_contact",
    "fitted_for",
    "identifiability",
    "least_squares",
    "make_outcomes",
    "mismatch",
    "param_space",
    "random_search",
    "read_outcomes",
    "synthetic_outcomes",
    "write_outcomes",
    "write_result",
]


def random_search(
    problem, evaluations: int, batch: int = 16, seed: int = 0, target: float | None = None
) -> dict:
    """Uniform draws in the bounds until `evaluations` parameter vectors or `target`:
    the fit loop with estimator 'random' (kept for its callers). Returns the best
    values, its loss, the rollouts and wall time spent, and the trajectory."""
    steps = -(-evaluations // batch)
    res = calibrate(
        problem,
        estimator="random",
        steps=steps,
        batch=batch,
        seed=seed,
        target=target,
        identify=False,
    )
    return {
        "values": res.optimum,
        "loss": res.history[-1]["best_loss"] if res.history else float("inf"),
        "trace": [
            {
                "evaluations": (h["step"] + 1) * batch,
                "best_loss": h["best_loss"],
                "rollouts": h["rollouts"],
                "wall_s": h["wall_s"],
            }
            for h in res.history
        ],
        "rollouts": res.rollouts,
        "wall_s": res.wall_s,
    }
