"""Which parameters the data pin down: intervals from the curvature of the loss.

At the fitted point, the residuals' Jacobian J (noise units per unit of each
parameter's coordinate z: the value, or its log for log parameters) is taken by central
finite differences -- every shifted vector in ONE engine batch -- and
``mujoco.sysid.calculate_intervals`` turns J^T J (the Gauss-Newton curvature of the
negative log likelihood) into 95 % intervals. Its eigen-decomposition gives an infinite
interval to a parameter along a direction the data do not see at all.

The residuals are already in units of their noise (``loss.py``), so the noise variance
is 1 -- not re-estimated from the residuals, as ``calculate_intervals`` otherwise does
(a noiseless synthetic fit would have zero-width intervals).

The Jacobian is taken at two steps (5 % and 1.25 % of the bounds): where the two
intervals differ by more than 2x the loss is not locally quadratic -- residuals that
jump, as an outcome flips or a slipping part drops a tick earlier -- and the curvature
is no measure of what the data pin down. A parameter is identified when the two agree
and the data ALONE give it a 95 % interval narrower than a quarter of its prior's (with
the default priors: narrower than half its bounds, in z) -- or, where they disagree,
when theta lies in a basin: the data's likelihood ratio excludes both coarse steps at
95 % and the loss rises at most half as much at the fine step (jagged residuals rise as
much at any step; its interval is then at most the coarse step).

Both tests are local: on a jagged loss a point can sit in one narrow basin of several.
So a parameter must also pass a global check: the data's negative log likelihood along
each parameter over its whole bounds (``profile_points`` values evenly spaced in z, the
others at theta: a slice, in the same engine batch as the local steps). Every slice
point that the likelihood ratio does not exclude at 95 % (a rise of less than chi2_95(1)
/ 2 = 1.92 above the best of theta and its local steps, plus the loss's own wiggle: the
largest |rise| at the fine steps) must lie within the local interval widened by one
slice spacing -- no second basin, no plateau as deep as the answer, no better point
elsewhere. The reported interval is the local one widened to the farthest value kept (a
flat-bottomed basin is wider than its curvature says); the slice's own 95 % set (its
extent, plus one spacing) is reported as the global interval. The rest are reported as
not identified, and a fit keeps them at their starting values instead of pretending to
have fitted them.
"""

from __future__ import annotations

import numpy as np

from mjx_pick.config import check_range

Z95 = 1.959964
CHI2_95 = 3.841459  # chi-square, 1 degree of freedom, 95 %


def identifiability(
    problem, theta, *, step: float = 0.05, ratio: float = 0.25, profile_points: int = 12
) -> dict:
    """Intervals and identifiability of problem's parameters at theta.

    Args:
      step: finite-difference step, a fraction of each parameter's bounds in z.
      ratio: identified iff the data-only 95 % half-width < ratio x the prior's.
      profile_points: G, slice points per parameter over its bounds (the global check,
        module docstring; P x G more parameter vectors); 0 skips it.

    Returns:
      {name: {value, interval (lo, hi) natural units, half_width_z, data_half_width_z
      (and at the fine step), prior_half_width_z, curvature (J^T J diagonal, data only),
      locally_quadratic, basin, local (the local tests' verdict), global (the slice:
      z and natural values (G,), nll_rise (G,), interval, passed), identified}}, plus
      'correlation' (P x P, data + prior), 'rollouts' spent, 'rows'.
    """
    check_range("calibrate", "identify step", step, 0, 0.5, lo_open=True)
    check_range("calibrate", "profile_points", profile_points, 0, 1000)
    space = problem.space
    theta = np.asarray(theta, np.float32)
    p = len(theta)
    z0 = space.z(np.asarray(space.values(theta), float))
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
    zs = np.asarray(zs)
    spent0 = problem.rollouts
    ev = problem.evaluate(theta_of_z(space, zs))
    n = ev.n_data
    jacs = []
    for k in range(2):
        res = ev.residuals[1 + 2 * p * k : 1 + 2 * p * (k + 1)]
        zk = zs[1 + 2 * p * k : 1 + 2 * p * (k + 1)]
        dz = np.diag(zk[0::2] - zk[1::2])  # (P,): the actual central steps
        jacs.append(((res[0::2] - res[1::2]) / dz[:, None]).T)  # (M, P)
    jac = jacs[0]
    out = {"rows": len(problem.outcomes), "residuals": n}
    j_data = jac[:n]
    half_data = _intervals(j_data)
    half_fine = _intervals(jacs[1][:n])
    half_all = _intervals(jac)
    prior_half = Z95 * space.prior_sd
    curv = np.sum(j_data**2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        agree = np.abs(np.log(half_fine / half_data)) < np.log(2.0)
    # the data's negative log likelihood at every shifted vector, relative to theta's
    nll = (ev.loss - ev.terms.get("prior", 0.0)) * problem.data.total_trials
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
    value = space.natural(z0)
    spacing = (space.z_hi - space.z_lo) * 0.98 / max(profile_points - 1, 1)
    for i, name in enumerate(space.names):
        narrow = bool(np.isfinite(half_data[i]) and half_data[i] < ratio * prior_half[i])
        local = (narrow and bool(agree[i])) or bool(basin[i])
        glob, interval = None, [float(lo[i]), float(hi[i])]
        if profile_points:
            # the four local steps of parameter i and their rises join the slice
            steps_z = (
                zs[1 + 2 * i : 3 + 2 * i, i].tolist()
                + zs[1 + 2 * (p + i) : 3 + 2 * (p + i), i].tolist()
            )
            steps_rise = np.concatenate([rise[0, i], rise[1, i]])
            glob = _global(
                grid[i], slice_rise[i], z0[i], half_all[i], spacing[i], steps_z, steps_rise
            )
            glob["values"] = space.natural(_at(z0, i, grid[i]))[:, i].tolist()
            ends = [max(glob.pop("lo_z"), space.z_lo[i]), min(glob.pop("hi_z"), space.z_hi[i])]
            glob["interval"] = space.natural(_at(z0, i, np.array(ends)))[:, i].tolist()
            wide = glob["half_width_z"]
            if wide is not None:  # the local interval, widened to what the slice keeps
                ends = [max(z0[i] - wide, space.z_lo[i]), min(z0[i] + wide, space.z_hi[i])]
                interval = space.natural(_at(z0, i, np.array(ends)))[:, i].tolist()
        out[name] = {
            "value": float(value[i]),
            "interval": interval,
            "local_interval": [float(lo[i]), float(hi[i])],
            "half_width_z": _num(half_all[i]),
            "data_half_width_z": _num(half_data[i]),
            "data_half_width_z_fine_step": _num(half_fine[i]),
            "prior_half_width_z": float(prior_half[i]),
            "curvature": float(curv[i]),
            "log": bool(space.log[i]),
            # the two steps' intervals within 2x of each other
            "locally_quadratic": bool(agree[i]),
            # the data's -log likelihood rise at the coarse step (the smaller side) and
            # at the fine one (the larger)
            "nll_rise": [float(coarse[i]), float(fine[i])],
            "basin": bool(basin[i]),
            "local": local,
            "global": glob,
            "identified": local and (glob is None or glob["passed"]),
        }
    cov = _covariance(jac)
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(sd, sd)
    out["correlation"] = np.where(np.isfinite(corr), corr, 0.0).round(4).tolist()
    out["rollouts"] = problem.rollouts - spent0
    return out


def _global(grid, rise, z0, half, spacing, steps_z, steps_rise) -> dict:
    """The slice's verdict for one parameter: grid (G,) z values, rise (G,) the data's
    -log likelihood above theta's; half: the local 95 % half-width (z); steps_z,
    steps_rise (4,): the local steps (coarse +-, fine +-) and their rises.

    A value is kept (not excluded at 95 %) when its rise above the best of theta and
    its four steps (theta may sit on a slope) is under chi2_95(1) / 2 plus the loss's
    own wiggle: the largest |rise| at the fine steps (on a quadratic loss a sixteenth
    of the coarse rise; on a jagged one as large as any: a rise smaller than what 1.25 %
    of the bounds already gives is no evidence). The threshold returned is relative to
    theta."""
    steps_z, steps_rise = np.asarray(steps_z, float), np.asarray(steps_rise, float)
    wiggle = float(np.max(np.abs(steps_rise[2:])))  # the fine steps
    # rises counted from the best of theta and its steps: theta may sit on a slope
    ref = min(0.0, float(steps_rise.min()))
    thr = CHI2_95 / 2 + wiggle + ref
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
