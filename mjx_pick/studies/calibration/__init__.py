"""Sim-to-real calibration: fit contact parameters (and the gripper's force offset) to
measured pick outcomes and traces.

Details: docs/calibration.md (studies/calibration/__init__.py).
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
