"""Which parameters the data pin down: intervals from the curvature of the loss.

Details: docs/calibration.md (studies/calibration/identify.py).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from mjx_pick.core.config import ConfigError, check_range
from mjx_pick.studies.calibration import estimators as E

Z95 = 1.959964
CHI2_95 = 3.841459  # chi-square, 1 degree of freedom, 95 %


def identifiability(
    problem,
    theta,
    *,
    step: float = 0.05,
    ratio: float = 0.25,
    profile_points: int = 12,
    visited=None,
    profile_steps: int = 4,
    profile_popsize: int = 6,
    profile_sigma: float = 1.0,
    profile_scales=(1.0, 1.5, 3.0),
    seed: int = 0,
) -> dict:
    """Intervals and identifiability of problem's parameters at theta (docs/calibration.md).

    Args:
      step: finite-difference step, a fraction of each parameter's bounds in z.
      ratio: identified iff the data-only 95 % half-width < ratio x the prior's.
      profile_points: G, slice points per parameter over its bounds; 0 skips the slice.
      visited: (thetas (N, P), data negative log likelihoods (N,)) the fit simulated,
        for the empirical profile (no simulation); None: none.
      profile_steps, profile_popsize: CMA-ES generations, and vectors per generation,
        of the refit profile per point; 0 steps: only its two starts.
      profile_sigma: CMA-ES's initial step, in the others' interval half-widths
        (clipped to 2-25 % of their bounds).
      profile_scales: multiples (>= 1) of the half-width in z, both sides, profiled; (): none.
      seed: the refit's CMA-ES seed.

    Returns:
      {name: that parameter's entry (keys: docs/calibration.md), 'correlation' (P x P,
      data + prior), 'rollouts', 'profile_rollouts', 'rows', 'residuals', 'wall_s'}.
    """
    scales = _check_options(
        step, ratio, profile_points, profile_steps, profile_popsize, profile_sigma, profile_scales
    )
    t_start = time.perf_counter()
    space = problem.space
    theta = np.asarray(theta, np.float32)
    p = len(theta)
    z0 = space.z(np.asarray(space.values(theta), float))
    seen = _visited(visited, p)
    zs, grid = _shifted(space, z0, step, profile_points)
    spent0 = problem.rollouts
    ev = problem.evaluate(theta_of_z(space, zs))
    loc = _local_tests(problem, ev, zs, z0, step, profile_points)
    out = {"rows": len(problem.outcomes), "residuals": ev.n_data}
    limit = ratio * (Z95 * space.prior_sd)  # the local test's narrowness rule, per parameter
    entries, thr, wide_z = _verdicts(space, loc, zs, z0, grid, limit, profile_points)
    out.update(entries)
    options = (profile_points, profile_steps, profile_popsize, profile_sigma, seed)
    j_data = loc.jac[: ev.n_data]
    _profile(out, problem, z0, loc.nll[0], thr, wide_z, limit, seen, scales, j_data, options)
    _mark_at_bound(out, space, z0)
    out["correlation"] = _correlation(loc.jac)
    out["rollouts"] = problem.rollouts - spent0
    out.setdefault("profile_rollouts", 0)
    out["wall_s"] = time.perf_counter() - t_start
    return out


def _mark_at_bound(out: dict, space, z0: np.ndarray) -> None:
    """Sets each parameter's 'at_bound' in out (in place) and withdraws 'identified'
    where the optimum z0 (P,) is pressed on a bound or its interval is cut by one: not
    fitted. What a message may say of it (:func:`bound_facts`) apart: whether the
    optimum itself lies on the bound, or only its interval reaches it."""
    for i, name in enumerate(space.names):
        side = at_bound(space, z0, i, out[name]["half_width_z"])
        out[name]["at_bound"] = side
        out[name].update(bound_facts(space, z0, i, out[name].get("interval")))
        if side is not None:
            out[name]["identified"] = False


def bound_facts(space, z, i: int, interval=None) -> dict:
    """What is true of parameter i and its bounds, for messages: its bounds (natural
    units), the bound its value z[i] lies on ('on_bound': 'lower', 'upper' or None) and
    the bounds its 95 % interval reaches ('interval_reaches': a list, empty without an
    interval)."""
    lo, hi = float(space.lo[i]), float(space.hi[i])
    reaches = []
    if interval is not None:
        close = 1e-3 * (hi - lo)
        reaches = [
            s
            for s, hit in (
                ("lower", interval[0] <= lo + close),
                ("upper", interval[1] >= hi - close),
            )
            if hit
        ]
    return {"bounds": [lo, hi], "on_bound": at_bound(space, z, i), "interval_reaches": reaches}


def _correlation(jac: np.ndarray) -> list:
    """The parameters' correlation matrix (P x P nested lists, rounded to 4 places; 0
    where undefined) from the residuals' Jacobian jac (M, P), data + prior rows."""
    cov = _covariance(jac)
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(sd, sd)
    return np.where(np.isfinite(corr), corr, 0.0).round(4).tolist()


def _check_options(
    step, ratio, profile_points, profile_steps, profile_popsize, profile_sigma, profile_scales
) -> tuple:
    """identifiability's options checked (ConfigError naming the one out of range);
    returns the profile's scales as a tuple."""
    check_range("calibrate", "identify step", step, 0, 0.5, lo_open=True)
    check_range("calibrate", "ratio", ratio, 0, lo_open=True)
    check_range("calibrate", "profile_points", profile_points, 0, 1000)
    check_range("calibrate", "profile_steps", profile_steps, 0, 1000)
    check_range("calibrate", "profile_popsize", profile_popsize, 2, 10_000)
    check_range("calibrate", "profile_sigma", profile_sigma, 0, 6, lo_open=True)
    scales = tuple(profile_scales)
    for c in scales:
        check_range("calibrate", "profile_scales", c, 1, 100)
    return scales


def _visited(visited, p: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The fit's own vectors (thetas (N, P), nll (N,)) as float arrays, checked; or None."""
    if visited is None:
        return None
    v_theta, v_nll = (np.asarray(a, float) for a in visited)
    if v_theta.ndim != 2 or v_theta.shape[1] != p or v_nll.shape != v_theta.shape[:1]:
        raise ConfigError(
            f"identifiability: visited must be (thetas (N, {p}), nll (N,)); got "
            f"{v_theta.shape} and {v_nll.shape}"
        )
    return v_theta, v_nll


def _shifted(space, z0, step: float, profile_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Every vector of the local tests and the slices, for ONE engine batch: z0, then
    the central steps (parameter i at +-h, for h = step and step / 4 of its bounds),
    then each parameter's slice over its bounds (the others at z0). Returns (zs (S, P),
    the slices' grid (P, G))."""
    p = len(z0)
    zs = [z0]
    # central differences at two steps (h and h / 4), all in one batch: on a smooth loss
    # they agree; where the residuals jump (an outcome flips, a slipping part drops a
    # few ticks earlier) the difference does not shrink with the step, J grows like
    # 1 / h, and the local curvature says nothing about the data's reach
    for frac in (step, step / 4):
        h = frac * (space.z_hi - space.z_lo)
        for i in range(p):
            for sign in (1.0, -1.0):
                z = z0.copy()
                z[i] = np.clip(z0[i] + sign * h[i], space.z_lo[i], space.z_hi[i])
                zs.append(z)
    # the slices: parameter i over its bounds, the others at theta
    grid = (
        np.linspace(0.01, 0.99, profile_points)[None, :] * (space.z_hi - space.z_lo)[:, None]
        + space.z_lo[:, None]
    )  # (P, G)
    for i in range(p if profile_points else 0):
        for g in grid[i]:
            z = z0.copy()
            z[i] = g
            zs.append(z)
    return np.asarray(zs), grid


class _Local(NamedTuple):
    """The local tests of every parameter (see the module docstring): the Jacobians'
    intervals at the two steps and the likelihood's rises."""

    jac: np.ndarray  # (M, P) at the coarse step, data and prior residuals
    half_data: np.ndarray  # (P,) the data's 95 % half-widths, coarse step (z)
    half_fine: np.ndarray  # (P,) the same at the fine step
    half_all: np.ndarray  # (P,) data and prior, cut to the coarse step in a basin
    agree: np.ndarray  # (P,) the two steps' intervals within 2x
    curv: np.ndarray  # (P,) J^T J's diagonal, data only
    nll: np.ndarray  # (S,) the data's -log likelihood of every shifted vector
    rise: np.ndarray  # (2, P, 2): step, parameter, side; relative to theta
    slice_rise: np.ndarray  # (P | 0, G)
    coarse: np.ndarray  # (P,) the smaller rise at the coarse step
    fine: np.ndarray  # (P,) the larger at the fine step
    basin: np.ndarray  # (P,)
    lo: np.ndarray  # (P,) the local interval, natural units
    hi: np.ndarray


def _local_tests(problem, ev, zs, z0, step: float, profile_points: int) -> _Local:
    """The local tests from the batch of :func:`_shifted` (evaluated as ev)."""
    space = problem.space
    p = len(z0)
    n = ev.n_data
    jacs = []
    for k in range(2):
        res = ev.residuals[1 + 2 * p * k : 1 + 2 * p * (k + 1)]
        zk = zs[1 + 2 * p * k : 1 + 2 * p * (k + 1)]
        dz = np.diag(zk[0::2] - zk[1::2])  # (P,): the actual central steps
        jacs.append(((res[0::2] - res[1::2]) / dz[:, None]).T)  # (M, P)
    jac = jacs[0]
    half_data = _intervals(jac[:n])
    half_fine = _intervals(jacs[1][:n])
    half_all = _intervals(jac)
    with np.errstate(divide="ignore", invalid="ignore"):
        agree = np.abs(np.log(half_fine / half_data)) < np.log(2.0)
    # the data's negative log likelihood at every shifted vector, relative to theta's
    nll = data_nll(problem, ev)
    rise = (nll[1 : 1 + 4 * p] - nll[0]).reshape(2, p, 2)  # (step, parameter, side)
    slice_rise = (nll[1 + 4 * p :] - nll[0]).reshape(-1, max(profile_points, 1))  # (P | 0, G)
    coarse, fine = rise[0].min(axis=-1), rise[1].max(axis=-1)
    # a basin: both coarse steps are excluded at 95 % (likelihood ratio, 1 dof) and the
    # loss grows with the distance (jagged residuals rise as much at the fine step)
    basin = (coarse > CHI2_95 / 2) & (fine < 0.5 * coarse)
    h = step * (space.z_hi - space.z_lo)
    half_all = np.where(~agree & basin, np.minimum(half_all, h), half_all)
    lo = space.natural(np.maximum(z0 - half_all, space.z_lo))
    hi = space.natural(np.minimum(z0 + half_all, space.z_hi))
    curv = np.sum(jac[:n] ** 2, axis=0)
    return _Local(
        jac,
        half_data,
        half_fine,
        half_all,
        agree,
        curv,
        nll,
        rise,
        slice_rise,
        coarse,
        fine,
        basin,
        lo,
        hi,
    )


def _slice(space, loc: _Local, zs, z0, grid, spacing, i: int, steps_rise) -> dict:
    """Parameter i's global check (the slice over its bounds, joined by its four local
    steps): the report's 'global' entry, natural values and interval included."""
    p = len(z0)
    steps_z = (
        zs[1 + 2 * i : 3 + 2 * i, i].tolist() + zs[1 + 2 * (p + i) : 3 + 2 * (p + i), i].tolist()
    )
    glob = _global(
        grid[i], loc.slice_rise[i], z0[i], loc.half_all[i], spacing[i], steps_z, steps_rise
    )
    glob["values"] = space.natural(_at(z0, i, grid[i]))[:, i].tolist()
    ends = [max(glob.pop("lo_z"), space.z_lo[i]), min(glob.pop("hi_z"), space.z_hi[i])]
    glob["interval"] = space.natural(_at(z0, i, np.array(ends)))[:, i].tolist()
    return glob


def _verdicts(space, loc: _Local, zs, z0, grid, narrow_z, profile_points: int):
    """Every parameter's report after the local tests and its slice (the profile
    updates its interval, half_width_z, profile and identified). narrow_z (P,): the
    data's half-width under which a parameter is narrow. Returns (name -> report, the
    likelihood-ratio thresholds (P,) relative to theta, the half-widths (P,) widened by
    the slices, z)."""
    p = len(z0)
    value = space.natural(z0)
    spacing = (space.z_hi - space.z_lo) * 0.98 / max(profile_points - 1, 1)
    wide_z = loc.half_all.copy()  # the local half-widths, widened by the slice
    thr = np.zeros(p)  # the likelihood-ratio threshold per parameter, relative to theta
    out = {}
    for i, name in enumerate(space.names):
        narrow = bool(np.isfinite(loc.half_data[i]) and loc.half_data[i] < narrow_z[i])
        local = (narrow and bool(loc.agree[i])) or bool(loc.basin[i])
        glob, interval = None, [float(loc.lo[i]), float(loc.hi[i])]
        steps_rise = np.concatenate([loc.rise[0, i], loc.rise[1, i]])
        thr[i] = _threshold(steps_rise)
        if profile_points:
            glob = _slice(space, loc, zs, z0, grid, spacing, i, steps_rise)
            wide = glob["half_width_z"]
            if wide is not None:  # the local interval, widened to what the slice keeps
                wide_z[i] = wide
                interval = _interval(space, z0, i, wide)
        ok = local and (glob is None or glob["passed"])
        out[name] = {
            "value": float(value[i]),
            "interval": interval,
            "local_interval": [float(loc.lo[i]), float(loc.hi[i])],
            "half_width_z": _num(wide_z[i]),
            "data_half_width_z": _num(loc.half_data[i]),
            "data_half_width_z_fine_step": _num(loc.half_fine[i]),
            "prior_half_width_z": float(Z95 * space.prior_sd[i]),
            "curvature": float(loc.curv[i]),
            "log": bool(space.log[i]),
            # the two steps' intervals within 2x of each other
            "locally_quadratic": bool(loc.agree[i]),
            # the data's -log likelihood rise at the coarse step (the smaller side) and
            # at the fine one (the larger)
            "nll_rise": [float(loc.coarse[i]), float(loc.fine[i])],
            "basin": bool(loc.basin[i]),
            "local": local,
            "global": glob,
            # the verdict and interval of the local tests and the slice: given the
            # others' values (what the profile below checks)
            "slice_identified": ok,
            "slice_interval": interval,
            "profile": None,
            "identified": ok,
        }
    return out, thr, wide_z


AT_BOUND = 0.02  # of a parameter's bounds (in z): theta's own margin (ParamSpace.theta)


def at_bound(space, z, i: int, half_width_z: float | None = None) -> str | None:
    """'lower' or 'upper' when z[i] lies within AT_BOUND of that bound of parameter i,
    or its 95 % interval (half-width in z) is cut by it; else None. An optimum there is
    where the bound stopped the search, not where the data put it: the best value may
    lie beyond, and an interval cut at the bound is no 95 % interval -- such a
    parameter is never reported identified."""
    # theta keeps every value AT_BOUND inside the bounds: a value on that margin is on
    # the bound, whatever float32's sigmoid rounds it to
    tol = AT_BOUND * (1 + 1e-3) * (space.z_hi[i] - space.z_lo[i])
    if half_width_z is not None and np.isfinite(half_width_z):
        tol = max(tol, float(half_width_z))
    if z[i] <= space.z_lo[i] + tol:
        return "lower"
    if z[i] >= space.z_hi[i] - tol:
        return "upper"
    return None


def _profile(out, problem, z0, nll0, thr, wide_z, limit, seen, scales, j_data, options):
    """The profile likelihood check (module docstring), in place on out: for each
    parameter the local tests and the slice identify, the empirical profile from seen
    (thetas (N, P), nll (N,)) or None, then the refit at ``scales`` x its half-width;
    out[name]'s interval, half_width_z, profile and identified are updated.

    nll0: theta's data -log likelihood; thr (P,): the likelihood-ratio thresholds
    relative to theta; wide_z (P,): the half-widths after the slice (z); limit (P,):
    the largest half-width still narrow; j_data: the data's Jacobian at theta (M, P);
    options: (profile_points, profile_steps, profile_popsize, profile_sigma, seed)."""
    space = problem.space
    # the profile: only parameters the tests above identify, and only with an interval
    todo = [i for i, nm in enumerate(space.names) if out[nm]["identified"]]
    todo = [i for i in todo if np.isfinite(wide_z[i])] if scales else []
    ctx = _ProfileContext(space, z0, nll0, thr, wide_z, limit)
    if seen is not None:
        todo = _empirical_profiles(out, ctx, todo, seen, max(options[0], 12))
    if todo:
        _refit_profiles(out, problem, ctx, todo, scales, j_data, options[1:])
    for i, name in enumerate(space.names):
        prof = out[name]["profile"]
        if prof is None:
            continue
        parts = [prof[k] for k in ("empirical", "refit") if prof.get(k) is not None]
        reach = max([q["reach_z"] for q in parts], default=0.0)
        half = max(wide_z[i], reach)
        prof["half_width_z"] = float(half)
        prof["interval"] = _interval(space, z0, i, half)
        prof["passed"] = all(q["passed"] for q in parts)
        out[name]["interval"] = prof["interval"]
        out[name]["half_width_z"] = _num(half)
        out[name]["identified"] = out[name]["slice_identified"] and prof["passed"]


class _ProfileContext(NamedTuple):
    """What every profile point is judged by (see :func:`_profile`'s arguments)."""

    space: object
    z0: np.ndarray
    nll0: float
    thr: np.ndarray
    wide_z: np.ndarray
    limit: np.ndarray

    def verdict(self, i: int, reach: float, open_end: bool = False) -> tuple[float, bool]:
        """Parameter i's half-width widened to the farthest value kept (reach, z), and
        whether it is still narrow (the local test's rule) and not open-ended."""
        half = max(self.wide_z[i], reach)
        return half, bool((half <= self.wide_z[i] or half < self.limit[i]) and not open_end)


def _empirical_profiles(out, ctx: _ProfileContext, todo: list, seen, bins: int) -> list:
    """The empirical profile of each parameter in todo from the fit's own vectors seen
    (thetas (N, P), nll (N,)), in place on out; returns the parameters still to refit
    (those the fit's vectors do not already widen out of the ratio)."""
    space, z0 = ctx.space, ctx.z0
    v_theta, v_nll = seen
    v_z = space.z(np.asarray(space.values(v_theta.astype(np.float32)), float))
    v_rise = np.where(np.isfinite(v_nll), v_nll - ctx.nll0, np.inf)
    for i in todo:
        emp = _empirical(space, z0, i, v_z, v_rise, ctx.thr[i], bins)
        half, emp["passed"] = ctx.verdict(i, emp["reach_z"])
        emp["interval"] = _interval(space, z0, i, half)
        prof = out[space.names[i]]["profile"] = {"threshold": float(ctx.thr[i])}
        prof.update(empirical=emp, refit=None)
    return [i for i in todo if out[space.names[i]]["profile"]["empirical"]["passed"]]


def _refit_profiles(out, problem, ctx: _ProfileContext, todo, scales, j_data, cma) -> None:
    """The refit profile of each parameter in todo, in place on out: its value fixed at
    scales x its half-width on both sides, the others re-optimised (:func:`_refit`);
    cma: (profile_steps, profile_popsize, profile_sigma, seed)."""
    space, z0, wide_z = ctx.space, ctx.z0, ctx.wide_z
    specs = []  # (parameter, scale, side, z)
    for i in todo:
        for side in (-1.0, 1.0):
            prev = z0[i]
            for c in sorted(scales):
                zi = float(np.clip(z0[i] + side * c * wide_z[i], space.z_lo[i], space.z_hi[i]))
                if abs(zi - prev) > 1e-9:  # clipped to a bound once: once is enough
                    specs.append((i, c, side, zi))
                prev = zi
    spent = problem.rollouts
    # the CMA-ES's unit per other parameter: its interval's half-width, within 2-25 %
    # of its bounds (an unbounded or unidentified one: a quarter of them)
    span = space.z_hi - space.z_lo
    scale = np.clip(np.where(np.isfinite(wide_z), wide_z, span), 0.02 * span, 0.25 * span)
    best_nll, best_z = _refit(problem, z0, specs, j_data, scale, *cma)
    out["profile_rollouts"] = problem.rollouts - spent
    for i in todo:
        ks = [k for k, s in enumerate(specs) if s[0] == i]
        refit = _refit_points(ctx, i, [(specs[k], best_nll[k], best_z[k]) for k in ks])
        prof = out[space.names[i]]["profile"]
        if prof is None:
            prof = out[space.names[i]]["profile"] = {
                "threshold": float(ctx.thr[i]),
                "empirical": None,
            }
        prof["refit"] = refit


def _refit_points(ctx: _ProfileContext, i: int, found: list) -> dict:
    """Parameter i's refit profile from its points found: [((i, scale, side, z), best
    data nll, best z (P,))], each side's in order of scale."""
    space, z0 = ctx.space, ctx.z0
    p = len(z0)
    points, reach, open_end = [], 0.0, False
    for side in (-1.0, 1.0):
        on_side = [f for f in found if f[0][2] == side]
        for (_, c, _, zi), nll, z in on_side:
            r = float(nll - ctx.nll0)
            kept = bool(r < ctx.thr[i])
            if kept:
                reach = max(reach, abs(zi - z0[i]))
            natural = space.natural(z)
            points.append(
                {
                    "z": zi,
                    "value": float(natural[i]),
                    "scale": side * c,
                    "nll_rise": r,
                    "others": {space.names[j]: float(natural[j]) for j in range(p) if j != i},
                    "kept": kept,
                }
            )
        # the outermost point kept and not at a bound: the 95 % set goes on
        if on_side:
            zi = on_side[-1][0][3]
            at_bound = zi <= space.z_lo[i] + 1e-9 or zi >= space.z_hi[i] - 1e-9
            open_end |= points[-1]["kept"] and not at_bound
    half, passed = ctx.verdict(i, reach, open_end)
    return {
        "points": points,
        "reach_z": reach,
        "open": open_end,
        "interval": _interval(space, z0, i, half),
        "passed": passed,
    }


def data_nll(problem, ev) -> np.ndarray:
    """The data's negative log likelihood (S,) of an Evaluation: the loss per trial
    without the prior, times the trials (``loss.py``)."""
    return (np.asarray(ev.loss, float) - ev.terms.get("prior", 0.0)) * problem.data.total_trials


def _threshold(steps_rise) -> float:
    """The likelihood-ratio threshold relative to theta from the four local steps'
    rises (coarse +-, fine +-): chi2_95(1) / 2 above the best of theta and its steps
    (theta may sit on a slope), plus the loss's own wiggle: the largest |rise| at the
    fine steps (on a quadratic loss a sixteenth of the coarse rise; on a jagged one as
    large as any: a rise smaller than what 1.25 % of the bounds already gives is no
    evidence)."""
    steps_rise = np.asarray(steps_rise, float)
    wiggle = float(np.max(np.abs(steps_rise[2:])))  # the fine steps
    ref = min(0.0, float(steps_rise.min()))
    return CHI2_95 / 2 + wiggle + ref


def _interval(space, z0, i, half) -> list[float]:
    """Parameter i's natural interval z0[i] +- half (z), clipped to the bounds."""
    ends = [max(z0[i] - half, space.z_lo[i]), min(z0[i] + half, space.z_hi[i])]
    return space.natural(_at(z0, i, np.array(ends)))[:, i].tolist()


def _empirical(space, z0, i, v_z, v_rise, thr, bins) -> dict:
    """The empirical profile of parameter i from the fit's own vectors v_z (N, P) in z
    and their rises v_rise (N,) above theta's: every vector under the threshold keeps
    its value of i (the profile there is at most its rise). Reported per bin of i's
    bounds: the lowest rise seen and the others' values there."""
    kept = v_rise < thr
    reach = float(np.max(np.abs(v_z[kept, i] - z0[i]), initial=0.0))
    edges = np.linspace(space.z_lo[i], space.z_hi[i], bins + 1)
    which = np.clip(np.searchsorted(edges, v_z[:, i], side="right") - 1, 0, bins - 1)
    points = []
    for b in range(bins):
        idx = np.flatnonzero(which == b)
        if not len(idx):
            continue
        k = idx[int(np.argmin(v_rise[idx]))]
        natural = space.natural(v_z[k])
        points.append(
            {
                "z": float(v_z[k, i]),
                "value": float(natural[i]),
                "nll_rise": float(v_rise[k]),
                "others": {nm: float(natural[j]) for j, nm in enumerate(space.names) if j != i},
                "vectors": len(idx),
            }
        )
    return {"points": points, "vectors": int(len(v_z)), "kept": int(kept.sum()), "reach_z": reach}


def _refit(problem, z0, specs, jac, scale, steps, popsize, sigma, seed):
    """The profile by re-optimisation: for each (i, scale, side, z) of specs, parameter
    i fixed at z and the others fitted to the data's negative log likelihood.

    Two starts per spec, both simulated in one first batch: theta's other values (the
    slice's point) and the valley's linear continuation, the others' Gauss-Newton
    optimum given z (jac: the data's Jacobian (M, P) at theta) -- along a valley across
    parameters the others must move with i, and a search started at theta's values
    would have to find the valley first. From the better one a small CMA-ES
    (``estimators.cma_es``) searches the others in units of scale (P,) (z per unit:
    their local half-widths, so that sigma 1 is a step of one interval), every spec's
    population in ONE engine batch per generation. Returns the lowest nll (K,) and its
    vector in z (K, P) per spec."""
    space = problem.space
    p, k_n = len(z0), len(specs)
    lo, hi = space.z_lo, space.z_hi
    z0 = np.asarray(z0, float)
    starts = np.repeat(z0[None], k_n, axis=0)
    for k, (i, _, _, zi) in enumerate(specs):
        starts[k, i] = zi
    best_nll = np.full(k_n, np.inf)
    best_z = starts.copy()

    def run(batch_z, owners):
        nll = data_nll(problem, problem.evaluate(theta_of_z(space, batch_z)))
        nll = np.where(np.isfinite(nll), nll, np.inf)
        for k in range(k_n):
            m = np.flatnonzero(owners == k)
            j = m[int(np.argmin(nll[m]))]
            if nll[j] < best_nll[k]:
                best_nll[k], best_z[k] = nll[j], batch_z[j]
        return nll

    if p == 1:  # nothing to re-optimise: the likelihood at the points
        run(starts, np.arange(k_n))
        return best_nll, best_z
    others = [np.delete(np.arange(p), s[0]) for s in specs]
    linear = _valley_starts(starts, z0, specs, others, jac, lo, hi)
    run(np.concatenate([starts, linear]), np.tile(np.arange(k_n), 2))
    mean = best_z.copy()  # the better start
    est = E.cma_es(popsize, sigma, seed)
    states = [est.init(np.zeros(p - 1)) for _ in range(k_n)]
    for _ in range(steps):
        asked = [est.ask(s) for s in states]  # (popsize, P - 1) each, in units of scale
        full = []
        for k in range(k_n):
            z = np.repeat(mean[k][None], len(asked[k]), axis=0)
            o = others[k]
            z[:, o] = np.clip(mean[k, o] + asked[k] * scale[o], lo[o], hi[o])
            full.append(z)
        owners = np.concatenate([np.full(len(a), k) for k, a in enumerate(asked)])
        nll = run(np.concatenate(full), owners)
        for k in range(k_n):
            m = np.flatnonzero(owners == k)
            states[k] = est.tell(states[k], asked[k], np.minimum(nll[m], 1e30))
    return best_nll, best_z


def _valley_starts(starts, z0, specs, others, jac, lo, hi) -> np.ndarray:
    """The refit's second starts (K, P) in z: for each spec (i, _, _, zi), starts' row
    with the others (indices others[k]) at their Gauss-Newton optimum given z_i = zi
    (jac: the data's Jacobian (M, P) at z0), clipped to the bounds lo, hi (P,)."""
    h = jac.T @ jac
    linear = starts.copy()
    for k, (i, _, _, zi) in enumerate(specs):
        o = others[k]
        linear[k, o] = z0[o] - np.linalg.pinv(h[np.ix_(o, o)]) @ h[o, i] * (zi - z0[i])
    return np.clip(linear, lo, hi)


def _global(grid, rise, z0, half, spacing, steps_z, steps_rise) -> dict:
    """The slice's verdict for one parameter: grid (G,) z values, rise (G,) the data's
    -log likelihood above theta's; half: the local 95 % half-width (z); steps_z,
    steps_rise (4,): the local steps (coarse +-, fine +-) and their rises.

    A value is kept (not excluded at 95 %) when its rise is under :func:`_threshold`
    (returned relative to theta)."""
    steps_z, steps_rise = np.asarray(steps_z, float), np.asarray(steps_rise, float)
    thr = _threshold(steps_rise)
    kept = rise < thr
    kept_z = np.concatenate([grid[kept], steps_z[steps_rise < thr]])
    reach = float(np.max(np.abs(kept_z - z0), initial=0.0))
    zk = np.append(grid[kept], z0)
    outside = np.abs(grid[kept] - z0) > half + spacing  # False where half is infinite
    return {
        "z": grid.tolist(),
        "nll_rise": rise.tolist(),
        "threshold": thr,
        "lo_z": float(zk.min() - spacing),
        "hi_z": float(zk.max() + spacing),
        # the local half-width, widened to the farthest value kept (z)
        "half_width_z": _num(max(half, reach)),
        # a value as likely as theta outside its local interval: another basin, a
        # plateau, or a better answer the fit missed
        "passed": bool(np.isfinite(half) and not outside.any()),
        "better_elsewhere": bool((rise < -thr).any()),
    }


def _at(z0, i, values) -> np.ndarray:
    """(G, P) copies of z0 with coordinate i set to each of values (G,)."""
    z = np.repeat(np.asarray(z0, float)[None], len(values), axis=0)
    z[:, i] = values
    return z


def _intervals(jac: np.ndarray) -> np.ndarray:
    """95 % half-widths from J (M, P) with unit noise (module docstring)."""
    from mujoco import sysid

    m, p = jac.shape
    if m <= p or not np.any(jac):
        return np.full(p, np.inf)
    # calculate_intervals estimates the noise variance as |r|^2 / (m - p): residuals of
    # that size make it exactly 1
    unit = np.full(m, np.sqrt((m - p) / m))
    _, half = sysid.calculate_intervals([unit], jac)
    # it uses Student's t; with unit variance known the normal quantile is the right one
    from scipy.special import stdtrit

    return np.asarray(half, float) * Z95 / stdtrit(m - p, 0.975)


def _covariance(jac: np.ndarray) -> np.ndarray:
    h = jac.T @ jac
    return np.linalg.pinv(h)


def _num(x) -> float | None:
    return float(x) if np.isfinite(x) else None


def theta_of_z(space, z: np.ndarray) -> np.ndarray:
    """z (..., P) -> theta without the 2 % margin of ParamSpace.theta (a step may reach
    the bounds)."""
    u = (np.asarray(z) - space.z_lo) / (space.z_hi - space.z_lo)
    u = np.clip(u, 1e-4, 1 - 1e-4)
    return np.log(u / (1 - u)).astype(np.float32)
