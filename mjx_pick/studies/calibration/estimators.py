"""Estimators: how the next parameter vectors to simulate are chosen.

Details: docs/calibration.md (studies/calibration/estimators.py).
"""

from __future__ import annotations

import math
import pickle
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np
import optax

from mjx_pick.core.config import ConfigError, check_choice, check_range

ESTIMATORS = ("smoothed", "random", "cma", "jvp")


class Estimator(NamedTuple):
    name: str
    init: Any
    ask: Any
    tell: Any
    best: Any


def hermite_nodes(samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Positive Gauss-Hermite nodes z (samples,) and weights (normalised over all nodes)."""
    nodes, weights = np.polynomial.hermite_e.hermegauss(2 * samples)
    weights = weights / weights.sum()
    pos = nodes > 0
    return nodes[pos], weights[pos]


def smoothing_points(theta: np.ndarray, samples: int, sigma: float) -> np.ndarray:
    """theta, then theta +- sigma z_k e_i for every parameter i and node k: (1 + 2 n, P)."""
    z, _ = hermite_nodes(samples)
    p = len(theta)
    shifts = np.asarray([np.eye(p)[i] * sigma * zk for i in range(p) for zk in z])
    return np.concatenate([theta[None], theta + shifts, theta - shifts]).astype(np.float32)


def smoothed_from_losses(losses: np.ndarray, p: int, samples: int, sigma: float) -> np.ndarray:
    """The smoothed gradient (P,) from the losses at :func:`smoothing_points`:
    dE[L(theta + sigma Z e_i)]/dtheta_i = E[Z L(theta + sigma Z e_i)] / sigma."""
    z, w = hermite_nodes(samples)
    n = p * len(z)
    diff = (losses[1 : n + 1] - losses[n + 1 :]).reshape(p, len(z))
    return (diff * (w * z)[None, :]).sum(axis=1) / sigma


def smoothed_gradient(loss_fn, theta: np.ndarray, samples: int, sigma: float):
    """(loss at theta, smoothed gradient (P,)); every point in ONE call of loss_fn."""
    losses = np.asarray(loss_fn(smoothing_points(theta, samples, sigma)))
    return float(losses[0]), smoothed_from_losses(losses, len(theta), samples, sigma)


# ----------------------------------------------------------------------- gradient


class GradState(NamedTuple):
    theta: np.ndarray  # (P,) current iterate
    opt_state: Any  # optax Adam state (pytree of (P,) arrays)
    step: int
    iterates: np.ndarray  # (step, P) every iterate simulated so far
    losses: np.ndarray  # (step,) the loss at each of them
    grad: np.ndarray  # (P,) last gradient


def _adam(learning_rate: float, steps: int):
    # the step shrinks to a tenth over the run: early steps cross plateaus of the
    # outcome, late ones settle (the smoothed gradient is noisy)
    return optax.adam(optax.cosine_decay_schedule(learning_rate, max(1, steps), alpha=0.1))


def smoothed(steps: int, learning_rate: float = 0.1, samples: int = 2, sigma: float = 0.2):
    """Adam on the Gauss-Hermite smoothed gradient (module docstring)."""
    check_range("calibrate", "samples", samples, 1, 10_000)
    check_range("calibrate", "sigma", sigma, 0, 10, lo_open=True)
    opt = _adam(learning_rate, steps)

    def spread(step):
        # wide early to see across flips of the outcome, narrow late (to 0.3 sigma) so
        # that the smoothing's bias (the cliff where held grasps drop is steep) fades
        frac = step / max(1, steps - 1)
        return sigma * (0.3 + 0.7 * 0.5 * (1 + math.cos(math.pi * frac)))

    def init(theta0):
        return _adam_init(opt, theta0)

    def ask(state):
        return smoothing_points(state.theta, samples, spread(state.step))

    def tell(state, thetas, losses, grad=None):
        losses = np.asarray(losses, float)
        p = len(state.theta)
        if grad is None:
            grad = smoothed_from_losses(losses, p, samples, spread(state.step))
        return _adam_step(opt, state, grad, float(losses[0]))

    return Estimator("smoothed", init, ask, tell, _best_iterate)


def jvp(steps: int, learning_rate: float = 0.1):
    """Adam on the forward-mode gradient (the fit loop passes it to tell)."""
    opt = _adam(learning_rate, steps)

    def init(theta0):
        return _adam_init(opt, theta0)

    def ask(state):
        return state.theta[None]

    def tell(state, thetas, losses, grad=None):
        if grad is None:
            raise ConfigError("the jvp estimator needs the forward-mode gradient")
        return _adam_step(opt, state, grad, float(np.asarray(losses)[0]))

    return Estimator("jvp", init, ask, tell, _best_iterate)


def _adam_init(opt, theta0) -> GradState:
    """The gradient estimators' start: no iterate yet, Adam's state at theta0."""
    theta0 = np.asarray(theta0, np.float32)
    p = len(theta0)
    return GradState(
        theta0,
        opt.init(jnp.asarray(theta0)),
        0,
        np.zeros((0, p), np.float32),
        np.zeros(0),
        np.zeros(p),
    )


def _adam_step(opt, state: GradState, grad, loss: float) -> GradState:
    grad = np.asarray(grad, float)
    if not np.isfinite(grad).all():
        raise FloatingPointError("gradient is not finite")
    updates, opt_state = opt.update(jnp.asarray(grad, jnp.float32), state.opt_state)
    theta = np.asarray(optax.apply_updates(jnp.asarray(state.theta), updates), np.float32)
    # the iterate just simulated (state.theta) and its loss
    iterates = np.concatenate([state.iterates, state.theta[None]])
    losses = np.append(state.losses, loss)
    return GradState(theta, opt_state, state.step + 1, iterates, losses, grad)


def _best_iterate(state: GradState) -> np.ndarray:
    """The simulated iterate with the lowest loss (the simulation is deterministic: its
    loss needs no averaging; an unsimulated last step is no answer)."""
    if not len(state.losses):
        return state.theta
    return state.iterates[int(np.nanargmin(state.losses))].astype(np.float32)


# ------------------------------------------------------------------------- search


class SearchState(NamedTuple):
    rng: np.random.Generator
    best_theta: np.ndarray  # (P,)
    best_loss: float
    step: int


def random_search(batch: int = 16, seed: int = 0):
    """Uniform draws in the bounded space (u in [0.02, 0.98] per parameter)."""
    check_range("calibrate", "batch", batch, 1, 100_000)

    def init(theta0):
        theta0 = np.asarray(theta0, np.float32)
        return SearchState(np.random.default_rng(seed), theta0, math.inf, 0)

    def ask(state):
        u = state.rng.uniform(0.02, 0.98, (batch, len(state.best_theta)))
        return np.log(u / (1 - u)).astype(np.float32)

    def tell(state, thetas, losses, grad=None):
        losses = np.asarray(losses, float)
        i = int(np.argmin(losses))
        if losses[i] < state.best_loss:
            return SearchState(
                state.rng, np.asarray(thetas[i], np.float32), float(losses[i]), state.step + 1
            )
        return state._replace(step=state.step + 1)

    return Estimator("random", init, ask, tell, lambda s: s.best_theta)


class CmaState(NamedTuple):
    es: Any  # cma.CMAEvolutionStrategy (holds mean, step size, covariance)
    best_theta: np.ndarray  # (P,)
    best_loss: float
    step: int


def cma_es(popsize: int | None = None, sigma0: float = 1.0, seed: int = 0):
    """CMA-ES in theta space (``cma``); popsize default: 4 + 3 ln P, at least 8."""

    def init(theta0):
        import cma

        theta0 = np.asarray(theta0, np.float64)
        p = len(theta0)
        pop = popsize or max(8, 4 + int(3 * math.log(max(p, 1))))
        opts = {
            "popsize": pop,
            "seed": seed + 1,
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
            "bounds": [-6.0, 6.0],
        }
        if p == 1:  # cma needs two dimensions: a second, dummy coordinate, ignored
            theta0 = np.append(theta0, 0.0)
        es = cma.CMAEvolutionStrategy(theta0, sigma0, opts)
        return CmaState(es, np.asarray(theta0[:p], np.float32), math.inf, 0)

    def ask(state):
        p = len(state.best_theta)
        xs = np.asarray(state.es.ask(), np.float64)
        state.es.mjx_pick_asked = xs  # the full vectors (dummy coordinate too) for tell
        return xs[:, :p].astype(np.float32)

    def tell(state, thetas, losses, grad=None):
        losses = np.asarray(losses, float)
        state.es.tell(list(state.es.mjx_pick_asked), losses.tolist())
        i = int(np.argmin(losses))
        if losses[i] < state.best_loss:
            return CmaState(
                state.es, np.asarray(thetas[i], np.float32), float(losses[i]), state.step + 1
            )
        return state._replace(step=state.step + 1)

    return Estimator("cma", init, ask, tell, lambda s: s.best_theta)


def make(name: str, steps: int, **kw) -> Estimator:
    """An estimator by name with its settings (learning_rate, samples, sigma: smoothed
    and jvp; batch, seed: random; popsize, seed: cma)."""
    check_choice("calibrate", "estimator", name, ESTIMATORS)
    if name == "smoothed":
        return smoothed(
            steps, kw.get("learning_rate", 0.1), kw.get("samples", 2), kw.get("sigma", 0.2)
        )
    if name == "jvp":
        return jvp(steps, kw.get("learning_rate", 0.1))
    if name == "random":
        return random_search(kw.get("batch") or 16, kw.get("seed", 0))
    return cma_es(kw.get("popsize"), kw.get("sigma0", 1.0), kw.get("seed", 0))


def dumps(state) -> np.ndarray:
    """An estimator state as bytes (uint8 array) for orbax: a resumed fit continues
    exactly (random generators and CMA-ES's covariance included)."""
    return np.frombuffer(pickle.dumps(state), np.uint8)


def loads(data: np.ndarray):
    return pickle.loads(np.asarray(data, np.uint8).tobytes())
