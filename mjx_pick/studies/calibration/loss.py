"""Residuals and loss: how far simulated pick-points are from the measured ones.

Details: docs/calibration.md (studies/calibration/loss.py).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_pick.core.config import ConfigError, check_range
from mjx_pick.studies.calibration.data import Outcomes

CLIP = 5.0  # the outcome logit is clipped to +-CLIP: a drop (margin -90 mm) must not
# outweigh a hold (+10 mm) 10 to 1, or smoothing over the cliff between them biases a fit


@dataclasses.dataclass(frozen=True)
class Noise:
    """The spread of each measurement: residuals are divided by it (user settings)."""

    temperature_mm: float = 2.0  # the outcome's smoothing (mm of final lift margin)
    lift_time_s: float = 0.05
    force_fraction: float = 0.05  # of F_d
    lift_mm: float = 2.0
    rotation_deg: float = 3.0
    # moving average over which traces are compared (s; 0: tick by tick)
    trace_window_s: float = 0.05
    # weights of the terms (0 drops one)
    outcome_weight: float = 1.0
    time_weight: float = 1.0
    trace_weight: float = 1.0
    prior_weight: float = 1.0

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name.endswith("weight") or f.name == "trace_window_s":
                check_range("calibrate", f.name, v, 0, 1e6)
            else:
                check_range("calibrate", f.name, v, 0, 1e6, lo_open=True)


class TraceTargets(NamedTuple):
    """Measured traces on the simulation's control ticks: (K, R, T) targets and masks."""

    kinds: tuple[str, ...]
    target: np.ndarray
    mask: np.ndarray


def trace_targets(outcomes: Outcomes, t_ticks: np.ndarray) -> TraceTargets:
    """Interpolate each measured trace onto the simulated ticks (t from the close)."""
    kinds = outcomes.trace_kinds()
    r, t = len(outcomes), len(t_ticks)
    target = np.zeros((len(kinds), r, t), np.float32)
    mask = np.zeros((len(kinds), r, t), np.float32)
    for i, tr in enumerate(outcomes.traces):
        for k, kind in enumerate(kinds):
            if tr and kind in tr:
                m = tr[kind]
                inside = (t_ticks >= m[0, 0]) & (t_ticks <= m[-1, 0])
                if not inside.any():
                    raise ConfigError(
                        f"outcomes row {i + 2}: the {kind} trace ({m[0, 0]:g}-{m[-1, 0]:g} s) "
                        f"lies outside the simulated time 0-{t_ticks[-1]:g} s"
                    )
                target[k, i, inside] = np.interp(t_ticks[inside], m[:, 0], m[:, 1])
                mask[k, i, inside] = 1.0
    return TraceTargets(kinds, target, mask)


def _entropy(y):
    """Binary entropy of the observed fractions: the cross-entropy's floor."""
    y = jnp.clip(y, 1e-7, 1 - 1e-7)
    h = -(y * jnp.log(y) + (1 - y) * jnp.log(1 - y))
    return jnp.where((y <= 1e-6) | (y >= 1 - 1e-6), 0.0, h)


def outcome_residuals(lift_mm, diverged, fraction, trials, high_mm, temperature_mm):
    """(..., R) deviance residuals and (..., R) success probabilities p."""
    shape = jnp.shape(lift_mm)
    y = jnp.broadcast_to(jnp.asarray(fraction, jnp.float32), shape)
    w = jnp.broadcast_to(jnp.asarray(trials, jnp.float32), shape)
    margin = jnp.where(diverged, -1e3, jnp.nan_to_num(lift_mm, nan=-1e3))
    logit = jnp.clip((margin - high_mm) / temperature_mm, -CLIP, CLIP)
    p = jax.nn.sigmoid(logit)
    dev = optax.sigmoid_binary_cross_entropy(logit, y) - _entropy(y)
    worst = jnp.maximum(
        optax.sigmoid_binary_cross_entropy(jnp.full(shape, -CLIP), y),
        optax.sigmoid_binary_cross_entropy(jnp.full(shape, CLIP), y),
    ) - _entropy(y)
    dev = jnp.where(diverged, worst, dev)
    sign = jnp.where(diverged, -1.0, jnp.sign(y - p))
    sign = jnp.where(sign == 0, 1.0, sign)
    return sign * jnp.sqrt(2.0 * w * jnp.maximum(dev, 0.0)), p


def residuals(sim: dict, data, noise: Noise, prior=None):
    """Named residual blocks {term: (..., n_term)} of simulated outputs against data.

    sim: (..., R) 'lift_height_mm', 't_reached_s', 'diverged' and, where traces are
    measured, (..., R, T) arrays named as the trace kinds, and optionally their
    replicas '<kind>_replicas' (..., R, K - 1, T) with 'diverged_replicas'
    (..., R, K - 1) (docs/calibration.md). data: a ``LossData``.
    prior: (..., P) prior residuals of the parameters (or None).
    """
    out = {}
    diverged = sim["diverged"]
    if noise.outcome_weight:
        r, _ = outcome_residuals(
            sim["lift_height_mm"],
            diverged,
            data.fraction,
            data.trials,
            data.high_mm,
            noise.temperature_mm,
        )
        out["outcome"] = np.sqrt(noise.outcome_weight) * r
    has = np.isfinite(data.lift_time_s)
    if noise.time_weight and has.any():
        err = _lift_time_errors(sim, data, noise)
        out["lift_time"] = np.sqrt(noise.time_weight) * err[..., has]
    if noise.trace_weight and data.traces is not None:
        out.update(_trace_residuals(sim, data, noise))
    if prior is not None and noise.prior_weight:
        out["prior"] = np.sqrt(noise.prior_weight) * jnp.asarray(prior, jnp.float32)
    return out


def _lift_time_errors(sim: dict, data, noise: Noise):
    """(..., R) simulated minus measured time to lift (s, from the settle), in units of
    noise.lift_time_s; a pick that never lifted or diverged counts at the close timeout."""
    t = sim["t_reached_s"]
    sim_t = jnp.where(t >= 0, t - data.settle_s, data.close_timeout_s)
    sim_t = jnp.where(sim["diverged"], data.close_timeout_s, jnp.nan_to_num(sim_t))
    meas = jnp.broadcast_to(jnp.asarray(np.nan_to_num(data.lift_time_s), jnp.float32), t.shape)
    return (sim_t - meas) / noise.lift_time_s


def _trace_residuals(sim: dict, data, noise: Noise) -> dict:
    """{kind: (..., R_kind)}: per measured row of each trace kind, its RMS negative log
    likelihood over the ticks (``_trace_rms``), times the square root of the trace weight."""
    tt = data.traces
    diverged = sim["diverged"]
    r_n, t_n = tt.target.shape[1:]
    scale = {
        "force_n": np.repeat(noise.force_fraction * data.grip_force_n[:, None], t_n, 1),
        "lift_mm": np.full((r_n, t_n), noise.lift_mm),
        "rotation_deg": np.full((r_n, t_n), noise.rotation_deg),
    }
    width = int(round(noise.trace_window_s / data.dt_s)) if data.dt_s else 0
    out = {}
    for k, kind in enumerate(tt.kinds):
        rows = tt.mask[k].any(axis=-1)
        ens = _trace_ensemble(sim, kind, diverged)
        rms = _trace_rms(ens, tt.target[k], tt.mask[k], scale[kind], width, diverged)
        out[kind] = np.sqrt(noise.trace_weight) * rms[..., rows]
    return out


def _trace_ensemble(sim: dict, kind: str, diverged):
    """(..., R, K, T) the simulated traces of kind: the row's own simulation first, then
    its replicas ('<kind>_replicas', if any); a diverged simulation's trace is 0."""
    pred = jnp.where(diverged[..., None], 0.0, jnp.nan_to_num(sim[kind]))
    reps = sim.get(f"{kind}_replicas")
    ens = pred[..., None, :]
    if reps is not None:
        rd = sim.get("diverged_replicas", jnp.zeros(reps.shape[:-1], bool))
        reps = jnp.where(rd[..., None], 0.0, jnp.nan_to_num(reps))
        ens = jnp.concatenate([ens, reps], axis=-2)
    return ens


def _trace_rms(ens, target, mask, scale, width: int, diverged):
    """(..., R) RMS over the measured ticks of a trace's Gaussian negative log likelihood:
    ens (..., R, K, T) simulated traces, target and mask (R, T), scale (R, T) the noise
    (trace units), all smoothed over width ticks; the variance is the replicas' spread
    plus scale^2. A diverged row counts at least 1."""
    mask = np.asarray(mask, np.float32)
    target = moving_average(np.asarray(target) * mask, width)
    weight = moving_average(mask, width)
    target = np.where(weight > 0, target / np.maximum(weight, 1e-9), 0.0)
    ens = moving_average(ens, width)
    mean = ens.mean(axis=-2)
    var = ens.var(axis=-2, ddof=1) if ens.shape[-2] > 1 else jnp.zeros_like(mean)
    # a few replicas' variance is itself noisy (by chance they agree at a tick
    # where the grasp is chaotic): at least its mean over 4 windows around
    var = jnp.maximum(var, moving_average(var, 4 * width))
    shape = mean.shape

    def full(a):
        return jnp.broadcast_to(jnp.asarray(a, jnp.float32), shape)

    m = full(mask)
    s2 = full(scale) ** 2
    nll = (mean - full(target)) ** 2 / (s2 + var) + jnp.log1p(var / s2)
    rms = jnp.sqrt(jnp.sum(nll * m, axis=-1) / jnp.maximum(m.sum(-1), 1.0))
    floor = jnp.maximum(rms, 1.0)
    return jnp.where(diverged, floor, rms)


def moving_average(x, width: int):
    """Centred moving average of width samples along the last axis (edges: the mean of
    the samples inside); width <= 1 returns x. numpy or jax arrays (..., T)."""
    if width <= 1:
        return x
    xp = np if isinstance(x, np.ndarray) else jnp
    lo, hi = width // 2, width - 1 - width // 2
    n = x.shape[-1]
    csum = xp.cumsum(x, axis=-1)
    zero = xp.zeros(x.shape[:-1] + (1,), csum.dtype)
    csum = xp.concatenate([zero, csum], axis=-1)  # csum[..., i] = sum of x[..., :i]
    i = np.arange(n)
    a, b = np.clip(i - lo, 0, n), np.clip(i + hi + 1, 0, n)
    count = (b - a).astype(np.float32).reshape((1,) * (x.ndim - 1) + (n,))
    return (csum[..., b] - csum[..., a]) / count


def loss_of(blocks: dict, total_trials: float):
    """(..., ) loss = 0.5 |r|^2 / total trials, and the same per term."""
    terms = {k: 0.5 * jnp.sum(jnp.square(v), axis=-1) / total_trials for k, v in blocks.items()}
    total = sum(terms.values())
    return total, terms


@dataclasses.dataclass(frozen=True)
class LossData:
    """What the residuals compare with (built once per problem)."""

    fraction: np.ndarray  # (R,)
    trials: np.ndarray  # (R,)
    grip_force_n: np.ndarray  # (R,)
    lift_time_s: np.ndarray  # (R,), NaN where not measured
    traces: TraceTargets | None
    high_mm: float  # final lift counted as success
    settle_s: float
    close_timeout_s: float
    dt_s: float = 0.0  # the traces' sample period (the control tick); 0: no smoothing

    @property
    def total_trials(self) -> float:
        return float(self.trials.sum())
