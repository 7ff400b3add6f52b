"""The fit: an estimator's ask/tell loop over a Problem, checkpointed with orbax; and a
least-squares fit with MuJoCo's system-identification optimiser (``mujoco.sysid``).
"""

from __future__ import annotations

import dataclasses
import io
import math
import time
from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError, check_range, to_dict
from mjx_pick.core.physics import ContactParams
from mjx_pick.engine import registry
from mjx_pick.outputs.progress import ProgressBar
from mjx_pick.outputs.rundir import claim, config_hash, finish, record_file, remove_recorded
from mjx_pick.studies.calibration import estimators as E
from mjx_pick.studies.calibration.identify import (
    at_bound,
    bound_facts,
    data_nll,
    identifiability,
    theta_of_z,
)
from mjx_pick.studies.calibration.parameters import fitted_contact
from mjx_pick.studies.options import RunOptions, split_fields


@dataclasses.dataclass
class CalibrationResult:
    contact: ContactParams  # the fitted contact parameters (TOML-ready)
    values: dict[str, float]  # the answer: identified parameters fitted, the rest at start
    initial: dict[str, float]
    history: list[dict]  # per step: step, loss, best_loss, values, wall_s, rollouts
    accuracy_before: dict | None
    accuracy_after: dict | None
    out_dir: Path | None
    estimator: str = "cma"
    optimum: dict[str, float] | None = None  # the estimator's answer, every parameter
    identifiability: dict | None = None
    not_identified: tuple[str, ...] = ()
    rollouts: int = 0
    wall_s: float = 0.0


class _Checkpoints:
    """Fit state (estimator state, step, history) saved with orbax-checkpoint."""

    def __init__(self, path: Path):
        import orbax.checkpoint as ocp

        self.ocp = ocp
        self.mngr = ocp.CheckpointManager(
            path.absolute(), options=ocp.CheckpointManagerOptions(max_to_keep=2, create=True)
        )

    def latest(self) -> dict | None:
        step = self.mngr.latest_step()
        if step is None:
            return None
        return self.mngr.restore(step, args=self.ocp.args.StandardRestore())

    def save(self, step: int, state: dict) -> None:
        self.mngr.save(step, args=self.ocp.args.StandardSave(state), force=True)
        self.mngr.wait_until_finished()

    def close(self) -> None:
        self.mngr.close()


@dataclasses.dataclass(frozen=True)
class FitRequest:
    """What :func:`calibrate` computes (how it runs: ``options.RunOptions``).

    Attributes:
      steps: estimator steps (each one engine batch).
      estimator: 'cma' (CMA-ES: the default, docs/calibration.md says why), 'smoothed',
        'random' or 'jvp' (forward mode through MJX's JAX physics).
      learning_rate, samples, sigma: Adam's step and the smoothing's quadrature node
        pairs per parameter and spread in theta (smoothed; learning_rate: jvp too).
      batch: draws per step (random); popsize: CMA-ES population.
      budget: stop once this many pick-point simulations were spent.
      target: stop once a simulated loss is at or below it.
      checkpoint_every: steps between orbax checkpoints (with out); resume continues.
      holdout: a Problem on held-out pick-points for the accuracy before and after.
      identify: after the fit, intervals and identifiability (``identify.py``); the
        parameters not identified keep their starting values in the answer.
    """

    steps: int = 200
    learning_rate: float = 0.1
    estimator: str = "cma"
    samples: int = 2
    sigma: float = 0.2
    batch: int | None = None
    popsize: int | None = None
    budget: int | None = None
    target: float | None = None
    checkpoint_every: int = 10
    holdout: object = None
    identify: bool = True


def calibrate(
    problem,
    options: RunOptions | None = None,
    *,
    request: FitRequest | None = None,
    log=None,
    **fields,
) -> CalibrationResult:
    """Fit problem's parameters; see ``estimators`` for the estimators.

    options: how it runs (``options.RunOptions``; the backend, batch size and
    pick-points are the problem's): seed (random, CMA-ES, smoothed draws), out (the
    results folder and its checkpoints), resume (continue from out's last checkpoint:
    the optimiser's state, not simulated chunks), progress (a bar of the steps on
    stderr; print log lines with ``progress.echo`` so that they do not break it).
    request: what it computes (:class:`FitRequest`). fields: fields of either by name.
    log: called with each step's history entry (progress output).
    """
    req, opts = split_fields(FitRequest, request, options, fields)
    opts.only("calibrate", "seed", "out", "resume", "progress")
    est = _estimator(req, opts.seed)
    initial = dict(problem.start)
    out_dir = Path(opts.out) if opts.out is not None else None
    fit = {"learning_rate": req.learning_rate, "samples": req.samples, "sigma": req.sigma}
    fit.update(seed=opts.seed)
    ckpt, request_key, state, history, step, wall0, visited = _open_fit(
        problem,
        out_dir,
        opts.resume,
        est.init(problem.start_theta()),
        steps=req.steps,
        estimator=req.estimator,
        **fit,
    )
    acc_before = None
    if req.holdout is not None and step == 0:
        acc_before = req.holdout.accuracy(problem.start_theta())
    t0 = time.perf_counter() - wall0
    spent0 = problem.rollouts - (history[-1]["rollouts"] if history else 0)
    loop = _FitLoop(problem, est, req, ckpt, visited, t0, spent0, log)
    state = loop.run(state, history, step, opts.progress)
    fitted = (est.best(state), initial, history, acc_before, req.holdout, req.identify)
    result = _finish(problem, *fitted, req.estimator, out_dir, problem.settings.contact, visited)
    result.rollouts = problem.rollouts - spent0
    result.wall_s = time.perf_counter() - t0
    if out_dir is not None:
        wall = time.perf_counter() - t0
        _write_fit(result, problem, out_dir, request_key, req.estimator, wall)
    return result


def _estimator(req: FitRequest, seed: int):
    """The request's estimator (``estimators.make``), its numbers checked."""
    est = E.make(
        req.estimator,
        req.steps,
        learning_rate=req.learning_rate,
        samples=req.samples,
        sigma=req.sigma,
        batch=req.batch,
        popsize=req.popsize,
        seed=seed,
    )
    check_range("calibrate", "steps", req.steps, 0, 1_000_000)
    check_range("calibrate", "checkpoint_every", req.checkpoint_every, 1)
    if req.budget is not None:
        check_range("calibrate", "budget", req.budget, 1)
    return est


@dataclasses.dataclass
class _FitLoop:
    """A fit's steps: ask, simulate, tell; each step's history entry, checkpoints."""

    problem: object
    est: object  # the estimator (``estimators``)
    req: FitRequest
    ckpt: _Checkpoints | None
    visited: list
    t0: float  # when the fit began (a resumed fit's earlier seconds counted in)
    spent0: int  # the problem's rollouts before this fit
    log: object

    def run(self, state, history: list, step: int, progress: bool):
        """Steps from step until req.steps, a budget or a target stops it: the final
        estimator state (history grows by an entry a step)."""
        req, problem = self.req, self.problem
        best = min([h["best_loss"] for h in history], default=math.inf)
        desc = f"calibrating ({req.estimator})"
        bar = ProgressBar(desc, "step", enabled=progress, total=req.steps)
        bar(step, req.steps)
        try:
            while step < req.steps:
                if req.budget is not None and problem.rollouts - self.spent0 >= req.budget:
                    break
                if req.target is not None and best <= req.target:
                    break
                state, entry = self._step(state, step, best)
                best = entry["best_loss"]
                history.append(entry)
                if self.log is not None:
                    self.log(entry)
                step += 1
                bar.note(f"best loss {best:.4g}")
                bar(step, req.steps)
                self._checkpoint(step, state, history)
        finally:
            bar.close()
            if self.ckpt is not None:
                self.ckpt.close()
        return state

    def _step(self, state, step: int, best: float) -> tuple:
        """One estimator step: (its new state, its history entry)."""
        req = self.req
        state, thetas, losses, diverged = _fit_step(
            self.problem, self.est, state, req.estimator, self.visited, step
        )
        best = min(best, float(np.nanmin(losses)))
        centre = req.estimator in ("smoothed", "jvp")
        entry = {
            "step": step,
            # smoothed / jvp: the loss at the iterate; search: the batch's best
            "loss": float(losses[0] if centre else np.nanmin(losses)),
            "best_loss": best,
            "values": self.problem.space.as_dict(self.est.best(state)),
            # rows that blew up (at the iterate, or the batch's fewest)
            "diverged": None
            if diverged is None
            else int(diverged[0] if centre else diverged.min()),
            "wall_s": round(time.perf_counter() - self.t0, 3),
            "rollouts": self.problem.rollouts - self.spent0,
        }
        return state, entry

    def _checkpoint(self, step: int, state, history: list) -> None:
        """The fit's state saved every checkpoint_every steps and at the last."""
        if self.ckpt is None or not (
            step % self.req.checkpoint_every == 0 or step == self.req.steps
        ):
            return
        self.ckpt.save(
            step,
            {
                "state": E.dumps(state),
                "history": E.dumps(history),
                "visited": E.dumps(self.visited),
                "step": np.int64(step),
                "wall_s": np.float64(time.perf_counter() - self.t0),
            },
        )


def _open_fit(problem, out_dir: Path | None, resume: bool, state, **fit):
    """A fit's folder and where it starts: (checkpoints, the folder's request, estimator
    state, history, step, wall seconds spent, visited vectors) -- a new fit's (out_dir
    claimed under its configuration), or with resume the last checkpoint's. fit: the
    estimator's settings that decide the folder's configuration key."""
    history, step, wall0 = [], 0, 0.0
    # every vector simulated and its data -log likelihood: the empirical profile of
    # the identifiability check (identify.py), at no simulation cost
    visited: list[tuple[np.ndarray, np.ndarray]] = []
    if out_dir is None:
        return None, None, state, history, step, wall0, visited
    if (out_dir / "checkpoint").is_dir() and not resume:
        raise ConfigError(f"{out_dir} holds an earlier fit: pass --resume or another --out")
    if resume and not out_dir.is_dir():
        raise ConfigError(
            f"--resume: {out_dir} does not exist, so there is no fit to continue; leave out "
            "--resume to start one there (or check the folder's name)"
        )
    space = problem.space
    request = {"object": problem.object.summary(), "names": list(problem.names)}
    request.update(settings=to_dict(problem.settings), steps=fit["steps"])
    request.update(estimator=fit["estimator"], learning_rate=fit["learning_rate"])
    request.update(samples=fit["samples"], sigma=fit["sigma"], seed=fit["seed"])
    request.update(noise=to_dict(problem.noise), bounds=[space.lo.tolist(), space.hi.tolist()])
    claim(out_dir, "calibrate", config_hash(request), resume=resume, settings=request)
    record_file(out_dir / "checkpoint", whole=True)  # orbax writes it: the folder is the fit's
    ckpt = _Checkpoints(out_dir / "checkpoint")
    saved = ckpt.latest() if resume else None
    if saved is not None:
        state = E.loads(saved["state"])
        history = E.loads(saved["history"])
        step, wall0 = int(saved["step"]), float(saved["wall_s"])
        if "visited" in saved:  # (checkpoints of earlier versions lack it)
            visited = E.loads(saved["visited"])
    return ckpt, request, state, history, step, wall0, visited


def _fit_step(problem, est, state, estimator: str, visited: list, step: int):
    """One estimator step (number step): ask for parameter vectors (S, P), simulate them (the data
    -log likelihood of each joins visited), tell the losses (S,); (state, thetas,
    losses, diverged rows per vector or None)."""
    thetas = est.ask(state)
    grad, diverged = None, None
    if estimator == "jvp":
        loss, grad = problem.mjx_loss_and_grad(thetas[0])
        losses = np.array([loss])
    else:
        ev = problem.evaluate(thetas)
        losses, diverged = ev.loss, ev.diverged
        visited.append((np.asarray(thetas, np.float32), data_nll(problem, ev)))
    try:
        state = est.tell(state, thetas, losses, grad)
    except FloatingPointError:
        # a zeroed NaN would be a silent "no change": stop and say where
        raise ConfigError(
            f"calibration step {step}: the {estimator!r} gradient is not finite at "
            f"{problem.space.as_dict(thetas[0])} (a simulation diverged or its derivative "
            "blew up); narrow the parameter ranges or use estimator 'smoothed'"
        ) from None
    return state, thetas, losses, diverged


def _write_fit(result, problem, out_dir: Path, request: dict, estimator: str, wall_s: float):
    """A finished fit's folder: its results (``outputs.write_result``) and run.json; the
    checkpoints, which served only a resume, removed."""
    from mjx_pick.studies.calibration.outputs import write_result

    write_result(result, problem, out_dir)
    meta = problem.runner.describe(wall_s)
    meta["timing"]["rollouts"] = result.rollouts
    if estimator == "jvp":  # the gradients ran on the differentiable backend's physics
        import jax

        d = jax.devices()[0]
        meta.update(backend=registry.differentiable(), device=f"{d.platform}:{d.device_kind}")
    finish(out_dir, command="calibrate", config=request, **meta)
    # the fit is complete and written: its checkpoints served only a resume
    remove_recorded(out_dir, "checkpoint/")


def _finish(
    problem,
    theta,
    initial,
    history,
    acc_before,
    holdout,
    identify,
    estimator,
    out_dir,
    base,
    visited=(),
) -> CalibrationResult:
    space = problem.space
    optimum = space.as_dict(theta)
    ident, lost = None, ()
    values = dict(optimum)
    if identify:
        seen = None
        if visited:
            seen = (
                np.concatenate([t for t, _ in visited]),
                np.concatenate([v for _, v in visited]),
            )
        ident = identifiability(problem, theta, visited=seen)
        lost = tuple(n for n in problem.names if not ident[n]["identified"])
        for n in lost:  # not pinned by the data: keep the start, do not pretend
            values[n] = ident[n]["written"] = kept_value(initial[n], ident[n]["interval"])
    else:  # no intervals: still, an optimum the bounds stopped is no answer
        z = space.z([optimum[n] for n in problem.names])
        ident = {}
        for i, n in enumerate(problem.names):
            side = at_bound(space, z, i)
            ident[n] = {"identified": None, "at_bound": side, "interval": None}
            ident[n].update(bound_facts(space, z, i))
            if side is not None:
                ident[n]["written"] = values[n] = initial[n]
        lost = tuple(n for n in problem.names if ident[n]["at_bound"])
    answer = space.theta([values[n] for n in problem.names])
    acc_after = holdout.accuracy(answer) if holdout is not None else None
    contact = fitted_contact(base, values)
    return CalibrationResult(
        contact,
        values,
        initial,
        history,
        acc_before,
        acc_after,
        out_dir,
        estimator,
        optimum,
        ident,
        lost,
    )


def kept_value(start: float, interval) -> float:
    """The value written for a parameter the data do not identify: its start, or --
    where the data's 95 % interval excludes the start -- the interval's nearest end (the
    value closest to the start that the data allow). A written value is never outside
    its reported interval."""
    lo, hi = interval
    return float(min(max(start, lo), hi))


class _Budget(Exception):
    pass


@dataclasses.dataclass(frozen=True)
class LeastSquaresRequest:
    """What :func:`least_squares` fits: at most max_iters iterations, relative
    finite-difference step eps, a simulation budget, identifiability after the fit and
    a holdout Problem for the accuracy before and after (as :class:`FitRequest`)."""

    max_iters: int = 30
    eps: float = 0.03
    budget: int | None = None
    identify: bool = True
    holdout: object = None


def least_squares(
    problem,
    options: RunOptions | None = None,
    *,
    request: LeastSquaresRequest | None = None,
    log=None,
    **fields,
) -> CalibrationResult:
    """Levenberg-Marquardt on the residuals with ``mujoco.sysid.optimize`` (MuJoCo's
    ``minimize.least_squares``; its finite-difference Jacobian runs all P shifted
    vectors as ONE engine batch).

    The sysid parameters are each parameter's position in its bounds, u in [0, 1]
    (z = z_lo + u (z_hi - z_lo)), so that one relative step ``eps`` suits them all.
    Where it fits: smooth residuals (traces, lift times). Outcome residuals are steps
    smoothed over ``temperature_mm``: a local method stalls on their plateaus.
    With ``out``, writes the results folder as ``calibrate`` does (no checkpoints: a
    killed fit starts again). progress: a progress bar of the residual evaluations
    (steps; their number is not known ahead) on stderr. options, or its fields as
    keywords (``options.RunOptions``): out and progress (a seed is allowed and unused:
    the method draws nothing); request: :class:`LeastSquaresRequest`, or its fields.
    """
    req, opts = split_fields(LeastSquaresRequest, request, options, fields)
    opts.only("least_squares", "seed", "out", "progress")
    out, progress = opts.out, opts.progress
    max_iters, eps, budget = req.max_iters, req.eps, req.budget
    identify, holdout = req.identify, req.holdout
    check_range("calibrate", "max_iters", max_iters, 1, 10_000)
    out_dir = None if out is None else Path(out)
    request = _claim_lsq(problem, out_dir, max_iters)
    initial = dict(problem.start)
    residuals = _lsq_fit(problem, initial, max_iters, eps, budget, log, progress)
    t0, spent0 = residuals.t0, residuals.spent0
    fitted = (residuals.best["theta"], initial, residuals.history, None, holdout, identify)
    result = _finish(
        problem, *fitted, "least_squares", out_dir, problem.settings.contact, residuals.visited
    )
    result.rollouts = problem.rollouts - spent0
    result.wall_s = time.perf_counter() - t0
    if out_dir is not None:
        from mjx_pick.studies.calibration.outputs import write_result

        write_result(result, problem, out_dir)
        meta = problem.runner.describe(result.wall_s)
        meta["timing"]["rollouts"] = result.rollouts
        finish(out_dir, command="calibrate", config=request, **meta)
    return result


def _lsq_fit(problem, initial, max_iters: int, eps: float, budget, log, progress: bool):
    """MuJoCo's Levenberg-Marquardt (``mujoco.sysid``) over the unit parameters until
    max_iters or the budget: the residuals' record (best, history, visited)."""
    from mujoco import sysid

    bar = ProgressBar("calibrating (lsq)", "step", enabled=progress)
    residuals = _Residuals(problem, budget, log, bar)
    try:
        # output: MuJoCo's optimiser prints every iteration unless given a stream
        sysid.optimize(
            _unit_params(problem, initial),
            residuals,
            optimizer="mujoco",
            verbose=False,
            max_iters=max_iters,
            eps=eps,
            output=io.StringIO(),
        )
    except _Budget:
        pass
    finally:
        bar.close()
    return residuals


def _claim_lsq(problem, out_dir: Path | None, max_iters: int) -> dict | None:
    """least_squares' output folder claimed for calibrate under its request (what
    decides the fit); the request, or None without out_dir."""
    if out_dir is None:
        return None
    request = {
        "object": problem.object.summary(),
        "names": list(problem.names),
        "estimator": "lsq",
        "max_iters": max_iters,
        "bounds": [problem.space.lo.tolist(), problem.space.hi.tolist()],
        "priors": [problem.space.prior_mean.tolist(), problem.space.prior_sd.tolist()],
    }
    claim(out_dir, "calibrate", config_hash(request), resume=False, settings=request)
    return request


def _unit_params(problem, initial: dict):
    """sysid's parameters: each one's position u in its bounds, in [0, 1] (see
    least_squares), starting at initial (kept 1 % off the bounds)."""
    from mujoco import sysid

    space = problem.space
    z0 = space.z([initial[n] for n in problem.names])
    u0 = (z0 - space.z_lo) / (space.z_hi - space.z_lo)
    params = sysid.ParameterDict()
    for i, n in enumerate(problem.names):
        params.add(sysid.Parameter(n, float(np.clip(u0[i], 0.01, 0.99)), 0.0, 1.0))
    return params


class _Residuals:
    """least_squares' residual function for ``sysid.optimize``: every call's vectors
    (positions u in the bounds) simulated in one batch, its residuals returned; keeps
    the history, the best vector and every vector visited (as calibrate does), and
    stops the fit (_Budget) once budget rollouts are spent."""

    def __init__(self, problem, budget: int | None, log, bar: ProgressBar):
        self.problem, self.budget, self.log, self.bar = problem, budget, log, bar
        self.history: list[dict] = []
        self.best = {"loss": math.inf, "theta": problem.start_theta()}
        self.visited: list[tuple[np.ndarray, np.ndarray]] = []
        self.t0 = time.perf_counter()
        self.spent0 = problem.rollouts

    def __call__(self, x, _params):
        problem, space, best = self.problem, self.problem.space, self.best
        x = np.asarray(x, float)
        cols = x[:, None] if x.ndim == 1 else x
        if self.budget is not None and problem.rollouts - self.spent0 >= self.budget:
            raise _Budget
        z = space.z_lo[:, None] + cols * (space.z_hi - space.z_lo)[:, None]
        thetas = theta_of_z(space, z.T)
        ev = problem.evaluate(thetas)
        self.visited.append((np.asarray(thetas, np.float32), data_nll(problem, ev)))
        i = int(np.argmin(ev.loss))
        if ev.loss[i] < best["loss"]:
            best.update(loss=float(ev.loss[i]), theta=thetas[i])
        entry = {
            "step": len(self.history),
            "loss": float(ev.loss[0]),
            "best_loss": best["loss"],
            "values": space.as_dict(best["theta"]),
            "diverged": int(ev.diverged.min()),
            "wall_s": round(time.perf_counter() - self.t0, 3),
            "rollouts": problem.rollouts - self.spent0,
        }
        self.history.append(entry)
        if self.log is not None:
            self.log(entry)
        self.bar.note(f"best loss {best['loss']:.4g}")
        self.bar.advance()
        r = ev.residuals.T  # (M, S)
        return [r[:, 0] if x.ndim == 1 else r], None, None
