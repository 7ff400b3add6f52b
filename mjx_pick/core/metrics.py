"""Results table (one row per pick-point) and run summary.

Columns are stable and named with units. Per-pick metrics come from the shared kernel
(``mjx_pick.kernels.grasp.finalize``); this module only labels and aggregates them.
"""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.kernels import types as kt

# the results table's columns, in order (dtype, description)
COLUMNS = {
    "pick_id": ("int64", "index of the pick-point in its generator's stream"),
    "x_mm": ("float64", "object x offset under the gripper centre"),
    "y_mm": ("float64", "object y offset"),
    "yaw_deg": ("float64", "object yaw relative to the gripper"),
    "opening_mm": ("float64", "starting distance between the pads"),
    "coverage": ("float64", "object fraction of the region between the fingertips"),
    "success": ("bool", "lifted >= 90% of the lift, off the table, upright, at the hold's end"),
    "score": ("float64", "eq. (2) grasp quality in [0, 1]; NaN when diverged"),
    "t_grasp": ("float64", "fraction of the grasp window the grip force was held"),
    "phi_max_deg": ("float64", "largest rotation of the object from its start pose"),
    "t_grasp_nc": ("float64", "fraction of the grasp window the object was off the table"),
    "failure": (
        "string",
        f"the outcome: {kt.SUCCESS}, or why it failed: {', '.join(kt.FAILURES[1:])}",
    ),
    "diverged": ("bool", "the simulation blew up (NaN/Inf, MuJoCo reset, absurd speed)"),
    "max_force_left_n": ("float64", "largest left pad force"),
    "max_force_right_n": ("float64", "largest right pad force"),
    "lift_height_mm": ("float64", "object lift at the end of the hold"),
    "yaw_max_deg": ("float64", "largest yaw change (about the vertical)"),
    "tilt_max_deg": ("float64", "largest tilt of the object's vertical axis"),
    "slip_mm": ("float64", "largest lag of the object behind the gripper while grasped"),
    "t_reached_s": ("float64", "time F_d was reached (-1: never)"),
    "height_compensation_mm": (
        "float64",
        "how far the gripper starts raised so its pads meet the part at the grasp height "
        "(an MJCF linkage's; 0 for a parallel jaw)",
    ),
    "chatter": (
        "int64",
        "times a pad's force fell below pad_contact_fraction x F_d and came back while "
        "the part was held (lift and hold)",
    ),
    "rotation_final_deg": (
        "float64",
        "rotation of the object from its start pose at the end of the hold (the success "
        "test's); null when the hold did not end",
    ),
    "label_margin": (
        "float64",
        "how clearly the label was decided: the smaller of the final lift above the success "
        "height and the final rotation below max_rotation_deg, each as a fraction of its "
        "tolerance (1: no slip, no turn; 0: on a threshold; < 0: past it, a failure; a "
        "part on the table counts as not lifted); null when the force was never reached "
        "or the simulation diverged",
    ),
}

# columns with no value (null; NaN in NumPy and pandas) where a pick was not judged
JUDGED_ONLY = ("rotation_final_deg", "label_margin")

# labels whose |label_margin| is below this are counted as decided by a hair in the
# summary: a tenth of the tolerance, 1 mm of slip in the default 100 mm lift's 10 mm,
# 4.5 deg of the default 45 deg
MARGINAL_BAND = 0.1


def results_table(
    picks: GraspBatch, out: dict, gripper: GripperSpec, extra: dict | None = None
) -> pa.Table:
    """One row per pick-point: the pick's pose and every metric, named with units.

    gripper: the one that simulated them (its height compensation per pick). extra:
    further (N,) columns (e.g. swept parameters), appended after COLUMNS, and after the
    pose columns of grasps that are not pick-points (``GraspBatch.pose_columns``).
    """
    # here, not at the top: the scene module loads MuJoCo, which reading tables back (a
    # report, the GUI) does not need
    from mjx_pick.core.scene import height_compensation_mm

    cols = dict(picks.columns())
    cols["height_compensation_mm"] = height_compensation_mm(gripper, picks)
    for name in COLUMNS:
        if name in cols:
            continue
        if name == "failure":
            cols[name] = np.asarray(kt.FAILURES, dtype=object)[np.asarray(out["failure"])]
        else:
            cols[name] = np.asarray(out[name])
    arrays = {
        name: pa.array(cols[name], type=_type(COLUMNS[name][0]), from_pandas=name in JUDGED_ONLY)
        for name in COLUMNS
    }
    # grasps given as poses: their height, tilt and pose (none for pick-points)
    for name, values in {**picks.pose_columns(math.nan), **(extra or {})}.items():
        arrays[name] = pa.array(values if name == "grasp_pose" else np.asarray(values))
    return pa.table(arrays)


def _type(name: str) -> pa.DataType:
    return {
        "int64": pa.int64(),
        "float64": pa.float64(),
        "bool": pa.bool_(),
        "string": pa.string(),
    }[name]


def summarize(table: pa.Table) -> dict:
    """Counts, success rate with its Wilson 95 % interval, score quantiles and outcome
    counts ("failures": per label of ``kernels.grasp.FAILURES``, "success" included)."""
    n = table.num_rows
    success = np.asarray(table["success"])
    diverged = np.asarray(table["diverged"])
    score = np.asarray(table["score"], float)
    failures = np.asarray(table["failure"].to_pylist(), dtype=object)
    valid = score[~np.isnan(score)]
    q = (
        {
            f"p{int(p * 100):02d}": float(np.quantile(valid, p))
            for p in (0.05, 0.25, 0.5, 0.75, 0.95)
        }
        if len(valid)
        else {}
    )
    return {
        "n": int(n),
        "successes": int(success.sum()),
        "success_rate": float(success.mean()) if n else float("nan"),
        "success_ci": list(wilson_interval(int(success.sum()), int(n))),
        "diverged": int(diverged.sum()),
        "chattered": int(np.sum(np.asarray(table["chatter"]) > 0))
        if "chatter" in table.column_names
        else 0,
        "labels_marginal": marginal_count(table),
        "failures": {name: int(np.sum(failures == name)) for name in kt.FAILURES},
        "score_mean": float(valid.mean()) if len(valid) else float("nan"),
        "score_quantiles": q,
    }


def marginal_count(table: pa.Table, band: float = MARGINAL_BAND) -> int:
    """Pick-points whose label was decided within ``band`` of a threshold
    (|label_margin| < band); 0 for tables written before the column existed."""
    if "label_margin" not in table.column_names:
        return 0
    margin = np.asarray(table["label_margin"], float)
    return int(np.sum(np.abs(margin[np.isfinite(margin)]) < band))


def label_check_rows(s: dict) -> list[tuple[str, str]]:
    """A run summary's rows on how clearly its labels were decided -- by a hair, and
    those the stability and step checks changed -- as (name, text), those it holds
    (a run without the checks, or of an older version, holds fewer)."""
    rows = []
    if "labels_marginal" in s:
        rows.append(
            (
                "labels by a hair",
                f"{s['labels_marginal']} of {s['n']} (|label_margin| < {MARGINAL_BAND:g} "
                "of a threshold's tolerance)",
            )
        )
    if s.get("stability_um"):
        rows.append(
            (
                "labels a shift flips",
                f"{s['labels_unstable']} of {s['n']} (object moved {s['stability_um']:g} um; "
                "label_stable in the results)",
            )
        )
    if "labels_unconverged" in s:
        rows.append(
            (
                "labels the step changes",
                f"{s['labels_unconverged']} of {s['n']} (half the time step; "
                "label_converged in the results)",
            )
        )
    return rows


def wilson_interval(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95% Wilson score interval of a binomial proportion k/n."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (float(max(0.0, centre - half)), float(min(1.0, centre + half)))


def rate_text(successes: int, n: int) -> str:
    """A success rate as people read it: '0.812 (95 % CI 0.726-0.876; 81/100)', the
    interval Wilson's."""
    if not n:
        return "- (no pick-points)"
    lo, hi = wilson_interval(int(successes), int(n))
    return f"{successes / n:.3f} (95 % CI {lo:.3f}-{hi:.3f}; {successes}/{n})"


def mean_interval(values, z: float = 1.959964) -> tuple[float, float, float]:
    """Mean of the finite values and its 95% normal-approximation interval."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return (float("nan"), float("nan"), float("nan"))
    m = float(v.mean())
    half = z * float(v.std(ddof=1)) / math.sqrt(len(v)) if len(v) > 1 else math.inf
    return (m, m - half, m + half)


def mcnemar_p(a, b) -> float:
    """Exact McNemar test of paired binary outcomes a, b (N,): two-sided p-value that
    both have the same success probability (binomial test on the discordant pairs)."""
    from scipy.stats import binomtest

    a, b = np.asarray(a, bool), np.asarray(b, bool)
    only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
    if only_a + only_b == 0:
        return 1.0
    return float(binomtest(only_a, only_a + only_b, 0.5).pvalue)


def rate_summary(success, score) -> dict:
    """Success rate with its Wilson interval and mean score with its interval."""
    success = np.asarray(success, bool)
    k, n = int(success.sum()), len(success)
    lo, hi = wilson_interval(k, n)
    m, mlo, mhi = mean_interval(score)
    return {
        "n": n,
        "successes": k,
        "success_rate": k / n if n else float("nan"),
        "success_ci": [lo, hi],
        "score_mean": m,
        "score_ci": [mlo, mhi],
    }


def best_successes(success, score, k: int) -> np.ndarray:
    """Indices of the k best-scoring successful pick-points, best first (ties: earlier
    first); diverged ones (score NaN) are never successes."""
    success, score = np.asarray(success, bool), np.asarray(score, float)
    key = np.where(success & np.isfinite(score), score, -np.inf)
    order = np.argsort(-key, kind="stable")[:k]
    return order[np.isfinite(key[order])]
