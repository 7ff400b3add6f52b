"""A calibration problem: measured rows, the parameter space and the simulations that
compare them, all through the one runner (``engine.runner.Runner``).

:class:`Problem` holds no fit state: every method is a function of the parameter
vectors it is given (the runner counts the simulations run).
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import ConfigError, check_range
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.settings import Settings
from mjx_pick.engine import registry
from mjx_pick.engine.inputs import pick_inputs, scene_of
from mjx_pick.engine.registry import AUTO
from mjx_pick.engine.runner import Runner
from mjx_pick.engine.simulator import differentiable_rollout
from mjx_pick.studies.calibration import loss as L
from mjx_pick.studies.calibration.data import Outcomes
from mjx_pick.studies.calibration.parameters import (
    ParamSpace,
    canonical_params,
    check_start,
    contact_arrays_jnp,
    param_space,
    row_inputs,
    start_values,
)
from mjx_pick.studies.calibration.provenance import check_measured


class Evaluation(NamedTuple):
    """The loss of S parameter vectors and where it comes from."""

    loss: np.ndarray  # (S,)
    terms: dict  # term -> (S,) loss of that term (outcome, lift_time, force_n, ..., prior)
    diverged: np.ndarray  # (S,) rows whose simulation blew up
    residuals: np.ndarray  # (S, M) every residual, noise units (least squares)
    n_data: int  # the first n_data of the M residuals are data (the rest: prior)


def _check_grip_forces(outcomes: Outcomes, g) -> None:
    """A ConfigError naming the rows whose grip force is outside gripper g's range."""
    bad_f = np.flatnonzero(
        (outcomes.grip_force_n < g.force_min_n) | (outcomes.grip_force_n > g.force_max_n)
    )
    if len(bad_f):
        shown = ", ".join(f"row {i + 2} ({outcomes.grip_force_n[i]:g} N)" for i in bad_f[:8])
        raise ConfigError(
            f"outcomes {shown}, column grip_force_n: outside {g.name}'s range "
            f"{g.force_min_n:g}-{g.force_max_n:g} N"
        )


def _check_feasible(checker, outcomes: Outcomes, g) -> None:
    """A ConfigError naming the measured pick-points gripper g cannot take."""
    res = checker(outcomes.x_mm, outcomes.y_mm, outcomes.yaw_deg)
    bad = np.flatnonzero(res["reason"] != pp.fk.FEASIBLE)
    if len(bad):
        shown = ", ".join(f"row {i + 2} ({pp.REASONS[res['reason'][i]]})" for i in bad[:8])
        raise ConfigError(
            f"{len(bad)} of {len(outcomes)} measured pick-points are infeasible for "
            f"{g.name}: {shown}"
        )


class Problem:
    """The simulations and the loss for one outcomes set, object and settings.

    Args:
      names: the parameters to fit (``parameters.PARAMS``; aliases allowed).
      settings: the procedure, gripper, solver and starting contact parameters.
      temperature_mm, force_weight, time_weight: shortcuts for ``noise``'s fields.
      noise: the spread of each measurement (``loss.Noise``).
      bounds, priors: per parameter (see ``parameters.param_space``).
      start: starting values (default: the settings' own).
      backend: the runner's backend ('auto', 'mujoco', 'mjx', 'warp').
      replicates: K, simulations of each row with a measured trace -- the pick-point
        and K - 1 copies moved by +-``replica_jitter_mm`` in x and y -- whose spread is
        the model's own uncertainty about the trace (``loss.py``). Outcomes and lift
        times are those of the pick-point itself. 1: one simulation per row.
      replica_jitter_mm: the copies' offset (mm); small: the chaos of a slipping
        grasp decorrelates them, not the offset.
      force_mismatch: fit although the outcomes record (``outcomes.measured``) another
        mass, gripper or procedure than obj and settings (a warning instead of a
        ConfigError; ``provenance.py``).
    """

    def __init__(
        self,
        obj: ObjectModel,
        outcomes: Outcomes,
        names,
        settings: Settings | None = None,
        *,
        temperature_mm: float | None = None,
        force_weight: float | None = None,
        time_weight: float | None = None,
        noise: L.Noise | None = None,
        bounds: dict | None = None,
        priors: dict | None = None,
        start: dict | None = None,
        pick_config: pp.PickConfig | None = None,
        backend: str = AUTO,
        replicates: int = 3,
        replica_jitter_mm: float = 0.05,
        force_mismatch: bool = False,
    ) -> None:
        from mjx_pick.core.procedure import broadcast_params

        noise = noise or L.Noise()
        extra = {
            "temperature_mm": temperature_mm,
            "trace_weight": force_weight,
            "time_weight": time_weight,
        }
        noise = dataclasses.replace(noise, **{k: v for k, v in extra.items() if v is not None})
        if temperature_mm is not None:
            check_range("calibrate", "temperature_mm", temperature_mm, 0, lo_open=True)
        self.noise = noise
        self.settings = s = settings or Settings()
        self.object, self.outcomes = obj, outcomes
        self.names = canonical_params(names)
        # outcomes of another mass, gripper or procedure fit confidently and wrongly
        self.mismatches = check_measured(outcomes.measured, obj, s, force_mismatch)
        # what the fit could not check, said with its results (report.md, calibration.json)
        self.notes: list[str] = []
        if outcomes.measured is None:
            self.notes.append(
                "the outcomes have no record of what they were measured with (a TOML of "
                "the CSV's name beside it): the part's mass, the gripper and the procedure "
                "were not checked against this fit's"
            )
        if self.mismatches:
            self.notes.append(
                "fitted although the outcomes were measured with other settings "
                "(--force-mismatch): " + "; ".join(self.mismatches)
            )
            warnings.warn(
                "fitting outcomes measured with other settings (forced): "
                + "; ".join(self.mismatches),
                stacklevel=2,
            )
        g = s.gripper
        _check_grip_forces(outcomes, g)
        check_range("calibrate", "replicates", replicates, 1, 64)
        check_range("calibrate", "replica_jitter_mm", replica_jitter_mm, 0, 5)
        if outcomes.grasps is not None:  # grasps given as poses, checked where they were read
            self._grasp_rows(outcomes.grasps)
        else:
            checker = pp.FeasibilityChecker(obj, g, pick_config, s.grasp)
            _check_feasible(checker, outcomes, g)
            self._add_replicas(checker, replicates, replica_jitter_mm)
        self.grip_force_n = outcomes.grip_force_n[self.row_of]  # (R + replicas,)
        self.scene = scene_of(obj, s)
        if backend == registry.differentiable():
            from mjx_pick.engine.mjx_backend import check_physics

            # MJX-JAX runs the differentiable physics alone: said before any run
            check_physics(self.scene)
        self.start = start_values(self.names, s, self.scene)
        self.start.update({canonical_params([k])[0]: float(v) for k, v in (start or {}).items()})
        self.space: ParamSpace = param_space(
            self.names,
            s,
            obj.mass_kg,
            bounds,
            start=self.start,
            priors=priors,
            grip_force_n=outcomes.grip_force_n,
        )
        check_start(self.space, self.start)
        per_row = [
            dataclasses.replace(s.grasp, grip_force_n=float(f)).params(obj, g)
            for f in self.grip_force_n
        ]
        stacked = {k: np.array([getattr(p, k) for p in per_row]) for k in per_row[0]._fields}
        params = broadcast_params(per_row[0], len(self.row_of), **stacked)
        self.inputs = pick_inputs(self.scene, s, self.picks).replace(params=params)
        traces = self._set_loss_data(s.grasp)
        self.record = traces is not None
        self.backend_name = backend
        # a batch holds every row of at least one parameter vector
        self.runner = Runner(backend, batch_size=max(256, len(self.row_of)))
        self._backend = None
        self._jvp = None

    def _grasp_rows(self, grasps) -> None:
        """The simulated rows of outcomes whose grasps are poses: one per row, no
        replicas (row_of, traced_rows, replicates, picks)."""
        n = len(self.outcomes)
        self.replicates = 1
        self.traced_rows = np.zeros(0, int)
        self.row_of = np.arange(n)
        self.picks = dataclasses.replace(grasps, pick_id=np.arange(n, dtype=np.int64))

    def _add_replicas(self, checker, replicates: int, replica_jitter_mm: float) -> None:
        """The simulated rows: every measured row, then K - 1 replicas of each row with
        a measured trace, moved by replica_jitter_mm (row_of, traced_rows, replicates,
        picks)."""
        # rows with a measured trace get K - 1 replicas: row_of maps every simulated row
        # (R pick-points, then the replicas, replica-major) to its measured row
        r_n = len(self.outcomes)
        traced = np.flatnonzero([bool(tr) for tr in self.outcomes.traces])
        self.replicates = int(replicates) if len(traced) else 1
        self.traced_rows = traced if self.replicates > 1 else np.zeros(0, int)
        offsets = replica_offsets(self.replicates - 1, replica_jitter_mm)  # (K - 1, 2)
        self.row_of = np.concatenate([np.arange(r_n)] + [self.traced_rows] * len(offsets))
        xs = np.concatenate(
            [self.outcomes.x_mm] + [self.outcomes.x_mm[traced] + o[0] for o in offsets]
        )
        ys = np.concatenate(
            [self.outcomes.y_mm] + [self.outcomes.y_mm[traced] + o[1] for o in offsets]
        )
        yaws = self.outcomes.yaw_deg[self.row_of]
        # a replica whose offset makes it infeasible (a pick-point at a clearance edge)
        # stays at the pick-point: it adds no spread
        moved = checker(xs, ys, yaws)["reason"] != pp.fk.FEASIBLE
        xs = np.where(moved, self.outcomes.x_mm[self.row_of], xs)
        ys = np.where(moved, self.outcomes.y_mm[self.row_of], ys)
        self.picks = checker.batch(np.arange(len(xs)), xs, ys, yaws, "calibration")

    def _set_loss_data(self, gr) -> dict | None:
        """What the loss compares with (high_mm, t_ticks, data) under procedure gr;
        returns the measured traces on the control ticks (None without traces)."""
        outcomes = self.outcomes
        self.high_mm = gr.success_height_fraction * gr.lift_height_mm
        self.t_ticks = np.arange(gr.n_ticks()) * gr.control_period_s - gr.settle_s
        traces = L.trace_targets(outcomes, self.t_ticks) if outcomes.trace_kinds() else None
        self.data = L.LossData(
            fraction=outcomes.fraction,
            trials=outcomes.trials,
            grip_force_n=outcomes.grip_force_n,
            lift_time_s=outcomes.lift_time_s,
            traces=traces,
            high_mm=self.high_mm,
            settle_s=gr.settle_s,
            close_timeout_s=gr.close_timeout_s,
            dt_s=gr.control_period_s,
        )
        return traces

    @property
    def rollouts(self) -> int:
        """Pick-point simulations run so far (the runner's count)."""
        return self.runner.rollouts + getattr(self, "_jvp_rollouts", 0)

    def start_theta(self) -> np.ndarray:
        return self.space.theta([self.start[n] for n in self.names])

    # --- simulations
    def _forward_backend(self):
        if self._backend is None:
            self._backend = self.runner.make(self.scene, self.settings.grasp)
        return self._backend

    def simulate(self, thetas: np.ndarray) -> dict:
        """Simulate every row (and its replicas) for each theta (S, P) in ONE runner call;
        outputs (S, R) (and (S, R, T) per measured trace kind, with their replicas:
        :meth:`split`)."""
        thetas = np.atleast_2d(np.asarray(thetas, np.float32))
        s_n, n = len(thetas), len(self.row_of)
        parts = [
            row_inputs(
                self.inputs,
                self.scene,
                self.settings,
                self.grip_force_n,
                self.space.as_dict(th),
            )
            for th in thetas
        ]
        inputs = jax.tree.map(lambda *a: np.concatenate(a), *parts)
        out, rows, _ = self.runner.run(self._forward_backend(), inputs, record=self.record)
        out = {k: np.asarray(v).reshape(s_n, n) for k, v in out.items()}
        if rows is not None:
            rows = rows.reshape(s_n, n, *rows.shape[1:])
        return self.split(out, rows)

    def split(self, out: dict, rows=None, xp=np) -> dict:
        """Per simulated row outputs (..., R + replicas) and traces (..., R + replicas,
        T, F) -> the measured rows' own (..., R) and (..., R, T) per trace kind, plus
        '<kind>_replicas' (..., R, K - 1, T) and 'diverged_replicas' (..., R, K - 1)
        where K > 1 (rows without a trace repeat their own simulation there)."""
        r = len(self.outcomes)
        res = {k: v[..., :r] for k, v in out.items()}
        if rows is None:
            return res
        kinds = trace_outputs(rows, xp=xp)
        res.update({k: v[..., :r, :] for k, v in kinds.items()})
        if self.replicates > 1:
            k1, tr = self.replicates - 1, self.traced_rows
            div = out["diverged"]
            rd = xp.repeat(div[..., :r, None], k1, axis=-1)
            extra = div[..., r:].reshape(*div.shape[:-1], k1, len(tr))
            if xp is np:
                rd[..., tr, :] = np.swapaxes(extra, -1, -2)
            else:
                rd = rd.at[..., tr, :].set(jnp.swapaxes(extra, -1, -2))
            res["diverged_replicas"] = rd
            for k, v in kinds.items():
                rep = xp.repeat(v[..., :r, None, :], k1, axis=-2)  # (..., R, K - 1, T)
                extra = v[..., r:, :].reshape(*v.shape[:-2], k1, len(tr), v.shape[-1])
                extra = xp.swapaxes(extra, -2, -3)  # (..., traced, K - 1, T)
                if xp is np:
                    rep[..., tr, :, :] = extra
                else:
                    rep = rep.at[..., tr, :, :].set(extra)
                res[f"{k}_replicas"] = rep
        return res

    # --- loss
    def evaluate(self, thetas: np.ndarray) -> Evaluation:
        """The loss of each theta (S, P), its terms and residuals (no derivatives)."""
        thetas = np.atleast_2d(np.asarray(thetas, np.float32))
        out = self.simulate(thetas)
        values = np.asarray(self.space.values(thetas))
        blocks = L.residuals(out, self.data, self.noise, self.space.prior_residuals(values))
        total, terms = L.loss_of(blocks, self.data.total_trials)
        data = [np.asarray(v, float) for k, v in blocks.items() if k != "prior"]
        prior = [np.asarray(blocks["prior"], float)] if "prior" in blocks else []
        res = np.concatenate(data + prior, axis=-1)
        n_data = sum(b.shape[-1] for b in data)
        return Evaluation(
            np.asarray(total, float),
            {k: np.asarray(v, float) for k, v in terms.items()},
            out["diverged"].sum(axis=-1),
            res,
            n_data,
        )

    def loss(self, thetas: np.ndarray) -> np.ndarray:
        """Loss at each theta (S,)."""
        return self.evaluate(thetas).loss

    def loss_terms(self, lift_mm, t_reached_s, diverged, force_rows=None):
        """(loss, p) of simulated per-row outputs ((R,) or (S, R) arrays), the prior
        left out (for tests and plots of the data terms)."""
        sim = {"lift_height_mm": lift_mm, "t_reached_s": t_reached_s, "diverged": diverged}
        if force_rows is not None:
            sim["force_n"] = force_rows
        blocks = L.residuals(sim, self.data, self.noise)
        total, _ = L.loss_of(blocks, self.data.total_trials)
        _, p = L.outcome_residuals(
            lift_mm,
            diverged,
            self.data.fraction,
            self.data.trials,
            self.high_mm,
            self.noise.temperature_mm,
        )
        return total, p

    def mjx_loss_and_grad(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """Loss and its forward-mode gradient through the MJX rollout.

        The one simulation outside ``Runner.run``: ``jax.jacfwd`` needs the rollout in
        its trace (``simulator.differentiable_rollout`` says why)."""
        if self._jvp is None:
            # refuses a scene of other physics (mjx_backend.jax_physics) before compiling
            roll = differentiable_rollout(self.scene, self.settings.grasp, self.record)
            inp = self.inputs

            def loss_fn(th):
                values = self.space.values(th)
                fr, ref, force = contact_arrays_jnp(
                    self.names, values, inp, self.scene, self.settings, self.object.mass_kg
                )
                params = inp.params._replace(grip_force_n=force)
                out, rows = roll(inp.qpos0, params, fr, ref, inp.pair_solimp)
                sim = self.split(dict(out), rows, xp=jnp)
                sp = self.space
                z = jnp.where(sp.log, jnp.log(jnp.where(sp.log, values, 1.0)), values)
                prior = (z - sp.prior_mean) / sp.prior_sd
                blocks = L.residuals(sim, self.data, self.noise, prior)
                return L.loss_of(blocks, self.data.total_trials)[0]

            self._jvp = jax.jit(lambda th: (loss_fn(th), jax.jacfwd(loss_fn)(th)))
        loss, grad = self._jvp(jnp.asarray(theta, jnp.float32))
        self._jvp_rollouts = getattr(self, "_jvp_rollouts", 0) + len(self.row_of) * (
            1 + len(self.names)
        )
        return float(loss), np.asarray(grad, float)

    def accuracy(self, theta) -> dict:
        """Predicted (simulated) success against the observed majority, per row."""
        out = self.simulate(np.asarray(theta)[None])
        predicted = out["success"][0]
        observed = self.outcomes.fraction >= 0.5
        return {
            "correct": int(np.sum(predicted == observed)),
            "total": len(self.outcomes),
            "predicted": predicted.tolist(),
            # a blown-up simulation predicts no success; counted so it is never silent
            "diverged": int(out["diverged"][0].sum()),
        }


def replica_offsets(n: int, jitter_mm: float) -> np.ndarray:
    """(n, 2) x, y offsets (mm) of a row's replicas: the corners of a square of half
    side jitter_mm, in turn, then again at 2x, 3x, ... (deterministic: the loss is a
    function of the parameters alone)."""
    corners = np.array([[1, 1], [-1, -1], [1, -1], [-1, 1]], float)
    return np.array([corners[i % 4] * jitter_mm * (1 + i // 4) for i in range(n)]).reshape(n, 2)


def trace_outputs(rows, xp=np) -> dict:
    """Traces (..., T, F) -> the measurable kinds (..., T): force_n (mean pad force),
    lift_mm (object rise above its start), rotation_deg (turn about the vertical since
    the start; counter-clockwise seen from above is positive)."""
    from mjx_pick.kernels.types import TRACE_FIELDS

    f = TRACE_FIELDS.index
    yaw = rows[..., f("object_yaw_rad")]
    yaw = xp.unwrap(yaw, axis=-1) if xp is np else jnp.unwrap(yaw, axis=-1)
    z = rows[..., f("object_z_m")]
    return {
        "force_n": 0.5 * (rows[..., f("force_left_n")] + rows[..., f("force_right_n")]),
        "lift_mm": (z - z[..., :1]) * 1e3,
        "rotation_deg": xp.degrees(yaw - yaw[..., :1]),
    }
