"""Fit contact parameters to measured pick outcomes (optax; gradients through MJX).

Measured outcomes (CSV, one row per tested pick-point; examples in
``assets/outcomes/``):

=================  ===========================================================
x_mm, y_mm         the object's offset under the gripper centre (as for evaluate)
yaw_deg            its yaw
grip_force_n       F_d used on the real gripper
trials, successes  how often it was tried, how often it was lifted and held
lift_time_s        optional: time from the close command to the start of the lift
force_trace        optional: a CSV (t_s, force_n; path relative to the outcomes
                   file) of the mean pad force from the close command on
=================  ===========================================================

Loss: the cross-entropy between a smooth surrogate of each simulated outcome,
p = sigmoid((final lift - success height) / temperature), and the observed success
fraction, weighted by trials (the logit clipped to +-5); plus, where given, the mean
squared error of the force traces (over F_d) and of the lift times (over 50 ms).

Parameters live in a bounded space: each is lo + (hi - lo) * sigmoid(theta) (frictions)
or its logarithm likewise (stiffness, damping), so optax works on an unconstrained
theta and no step can leave the bounds. Stiffness and damping are capped above by the
stiffest contact MuJoCo integrates stably at the time step (``physics`` module): the
paper's Table 1 values lie above that cap, so a fit starts just below it.

Gradient estimators (measured; benchmarks/RESULTS.md, "calibration"):

* ``jvp`` -- forward-mode derivatives through the MJX rollout (``jax.jacfwd``: one
  tangent lane per parameter, in the same batch). Reverse mode (``jax.grad``) fails:
  MJX's constraint solver is a ``lax.while_loop`` (upstream issue #2259). A pathwise
  derivative is exact for the simulation as run, but an outcome that flips (held /
  dropped) has zero derivative almost everywhere, and contact chatter makes it noisy.
* ``smoothed`` -- the gradient of the loss smoothed with a Gaussian along each
  parameter, E[L(theta + sigma Z e_i)], by Gauss-Hermite quadrature (symmetric node
  pairs, all in one simulation batch): deterministic, no derivatives, so it also runs
  on the MuJoCo C engine (the fast CPU backend), and it sees across flips. The spread
  shrinks over the fit. (Random antithetic directions were tried first: with a few
  samples per step their noise sent the fit astray.)
"""

from __future__ import annotations

import csv
import dataclasses
import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_pick import pickpoints as pp
from mjx_pick.config import ConfigError, check_choice, check_range, to_dict, write_json
from mjx_pick.engine import Engine, differentiable_rollout
from mjx_pick.objects import ObjectModel
from mjx_pick.physics import ContactParams, per_unit_mass, stiffest_spring
from mjx_pick.rundir import claim, config_hash, finish
from mjx_pick.simulate import Settings, make_inputs

REQUIRED = ("x_mm", "y_mm", "yaw_deg", "grip_force_n", "trials", "successes")
OPTIONAL = ("lift_time_s", "force_trace")
FITTABLE = (
    "pad_friction",
    "table_friction",
    "pad_stiffness_n_per_mm",
    "pad_damping_ns_per_mm",
    "table_stiffness_n_per_mm",
    "table_damping_ns_per_mm",
)
ALIASES = {
    "friction": "pad_friction",
    "stiffness": "pad_stiffness_n_per_mm",
    "damping": "pad_damping_ns_per_mm",
}


# ----------------------------------------------------------------------------- data


@dataclasses.dataclass(frozen=True)
class Outcomes:
    """Measured outcomes, one entry per tested pick-point ((R,) arrays)."""

    x_mm: np.ndarray
    y_mm: np.ndarray
    yaw_deg: np.ndarray
    grip_force_n: np.ndarray
    trials: np.ndarray
    successes: np.ndarray
    lift_time_s: np.ndarray  # NaN where not measured
    force_traces: tuple  # per row: (K, 2) array of (t_s, force_n), or None

    def __len__(self) -> int:
        return len(self.x_mm)

    def take(self, index) -> Outcomes:
        index = np.atleast_1d(np.arange(len(self))[index])
        arrays = {
            f.name: getattr(self, f.name)[index]
            for f in dataclasses.fields(self)
            if isinstance(getattr(self, f.name), np.ndarray)
        }
        return dataclasses.replace(
            self, **arrays, force_traces=tuple(self.force_traces[i] for i in index)
        )

    @property
    def fraction(self) -> np.ndarray:
        return self.successes / self.trials


def example_outcomes() -> list[str]:
    """Names of the shipped example outcome files (assets/outcomes/*.csv)."""
    from importlib import resources

    folder = resources.files("mjx_pick.assets") / "outcomes"
    return sorted(p.name[:-4] for p in folder.iterdir() if p.name.endswith(".csv"))


def read_outcomes(path: str | Path) -> Outcomes:
    """Read and check a measured-outcomes CSV (see the module docstring); a shipped
    example may be named without a path (e.g. "block_1kg_rg2")."""
    path = Path(path)
    if not path.is_file() and str(path) in example_outcomes():
        from importlib import resources

        with resources.as_file(
            resources.files("mjx_pick.assets") / "outcomes" / f"{path}.csv"
        ) as p:
            return read_outcomes(p)
    if not path.is_file():
        raise ConfigError(
            f"outcomes file {str(path)!r} does not exist (shipped examples: "
            f"{', '.join(example_outcomes())})"
        )
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise ConfigError(
                f"outcomes file {path.name}: missing column(s) {', '.join(missing)}; "
                f"found {header}; required: {', '.join(REQUIRED)}"
            )
        unknown = [c for c in header if c not in REQUIRED + OPTIONAL]
        if unknown:
            raise ConfigError(
                f"outcomes file {path.name}: unknown column(s) {', '.join(unknown)}; "
                f"allowed: {', '.join(REQUIRED + OPTIONAL)}"
            )
        rows = list(reader)
    if not rows:
        raise ConfigError(f"outcomes file {path.name} has no rows")
    cols = {c: [] for c in REQUIRED}
    lift, traces = [], []
    for line, row in enumerate(rows, start=2):
        where = f"outcomes file {path.name}, row {line}"
        for c in REQUIRED:
            try:
                v = float(row[c])
            except (TypeError, ValueError):
                raise ConfigError(f"{where}, column {c}: {row[c]!r} is not a number") from None
            if not math.isfinite(v):
                raise ConfigError(f"{where}, column {c}: {v} must be finite")
            cols[c].append(v)
        t, s = cols["trials"][-1], cols["successes"][-1]
        if t < 1 or t != int(t):
            raise ConfigError(f"{where}, column trials: {t:g} must be a whole number >= 1")
        if s < 0 or s != int(s) or s > t:
            raise ConfigError(
                f"{where}, column successes: {s:g} must be a whole number in 0..trials ({t:g})"
            )
        if cols["grip_force_n"][-1] <= 0:
            raise ConfigError(f"{where}, column grip_force_n: must be > 0")
        text = (row.get("lift_time_s") or "").strip()
        try:
            lift.append(float(text) if text else math.nan)
        except ValueError:
            raise ConfigError(f"{where}, column lift_time_s: {text!r} is not a number") from None
        trace = (row.get("force_trace") or "").strip()
        traces.append(_read_trace(path.parent / trace, where) if trace else None)
    return Outcomes(
        **{c: np.asarray(cols[c], float) for c in REQUIRED},
        lift_time_s=np.asarray(lift, float),
        force_traces=tuple(traces),
    )


def _read_trace(path: Path, where: str) -> np.ndarray:
    if not path.is_file():
        raise ConfigError(f"{where}, column force_trace: {str(path)!r} does not exist")
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
        t, f = np.asarray(data["t_s"], float), np.asarray(data["force_n"], float)
    except (ValueError, KeyError) as err:
        raise ConfigError(
            f"{where}, column force_trace: {path.name} needs columns t_s, force_n ({err})"
        ) from err
    if len(t) < 2 or not np.all(np.diff(t) > 0) or not np.isfinite(f).all():
        raise ConfigError(f"{where}, force_trace {path.name}: times must increase, forces finite")
    return np.stack([t, f], axis=1)


def write_outcomes(path: str | Path, outcomes: Outcomes) -> None:
    """Write outcomes as CSV; force traces go beside it as <stem>_trace_<row>.csv."""
    from mjx_pick.config import write_atomic

    path = Path(path)
    lines = [",".join(REQUIRED + OPTIONAL)]
    for i in range(len(outcomes)):
        trace = ""
        if outcomes.force_traces[i] is not None:
            trace = f"{path.stem}_trace_{i}.csv"
            t = outcomes.force_traces[i]
            write_atomic(
                path.parent / trace, "t_s,force_n\n" + "".join(f"{a:.5f},{b:.4f}\n" for a, b in t)
            )
        lift = outcomes.lift_time_s[i]
        lines.append(
            f"{outcomes.x_mm[i]:.4f},{outcomes.y_mm[i]:.4f},{outcomes.yaw_deg[i]:.4f},"
            f"{outcomes.grip_force_n[i]:.6g},{int(outcomes.trials[i])},"
            f"{int(outcomes.successes[i])},{'' if math.isnan(lift) else f'{lift:.4f}'},{trace}"
        )
    write_atomic(path, "\n".join(lines) + "\n")


# ----------------------------------------------------------------------- parameters


@dataclasses.dataclass(frozen=True)
class ParamSpace:
    """Bounded parameters: value = lo + (hi - lo) * sigmoid(theta), in log for log ones."""

    names: tuple[str, ...]
    lo: np.ndarray
    hi: np.ndarray
    log: np.ndarray  # bool

    def values(self, theta):
        """theta (P,) -> parameter values (P,) (jnp: differentiable)."""
        u = jax.nn.sigmoid(theta)
        lo = jnp.where(self.log, jnp.log(self.lo), self.lo)
        hi = jnp.where(self.log, jnp.log(self.hi), self.hi)
        v = lo + (hi - lo) * u
        return jnp.where(self.log, jnp.exp(v), v)

    def theta(self, values) -> np.ndarray:
        """values -> theta, kept 2% inside the bounds (sigmoid' vanishes at them)."""
        v = np.asarray(values, float)
        lo = np.where(self.log, np.log(self.lo), self.lo)
        hi = np.where(self.log, np.log(self.hi), self.hi)
        u = (np.where(self.log, np.log(v), v) - lo) / (hi - lo)
        u = np.clip(u, 0.02, 0.98)
        return np.log(u / (1 - u)).astype(np.float32)

    def as_dict(self, theta) -> dict[str, float]:
        return {
            n: float(v) for n, v in zip(self.names, np.asarray(self.values(theta)), strict=True)
        }


def canonical_params(names) -> tuple[str, ...]:
    """User parameter names (aliases allowed) -> ContactParams field names."""
    if isinstance(names, str):
        names = [n for n in names.split(",") if n.strip()]
    out = []
    for n in names:
        full = ALIASES.get(n.strip(), n.strip())
        if full not in FITTABLE:
            raise ConfigError(
                f"unknown calibration parameter {n!r}: choose from {', '.join(FITTABLE)} "
                f"(aliases: {', '.join(f'{k}={v}' for k, v in ALIASES.items())})"
            )
        if full in out:
            raise ConfigError(f"calibration parameter {full} is given twice")
        out.append(full)
    if not out:
        raise ConfigError("calibration needs at least one parameter (e.g. pad_friction)")
    return tuple(out)


def param_space(names, settings: Settings, mass_kg: float, bounds: dict | None = None):
    """Default bounds: frictions 0.05-2 (table 0.01-2); stiffness and damping from 1/100
    of the stiffest stable contact to it (see the module docstring)."""
    k_max, b_max = stiffest_spring(mass_kg, settings.solver.timeconst_s)  # N/mm, N s/mm
    default = {
        "pad_friction": (0.05, 2.0),
        "table_friction": (0.01, 2.0),
        "pad_stiffness_n_per_mm": (k_max / 100, k_max),
        "table_stiffness_n_per_mm": (k_max / 100, k_max),
        "pad_damping_ns_per_mm": (b_max / 100, b_max),
        "table_damping_ns_per_mm": (b_max / 100, b_max),
    }
    bounds = {canonical_params([k])[0]: v for k, v in (bounds or {}).items()}
    lo, hi = [], []
    for n in names:
        a, b = bounds.get(n, default[n])
        if not (0 < a < b and math.isfinite(b)):
            raise ConfigError(f"calibration bounds of {n}: {a:g}..{b:g} must have 0 < lo < hi")
        lo.append(a)
        hi.append(b)
    log = np.array([("stiffness" in n or "damping" in n) for n in names])
    return ParamSpace(tuple(names), np.asarray(lo), np.asarray(hi), log)


def fitted_contact(base: ContactParams, values: dict[str, float]) -> ContactParams:
    return dataclasses.replace(base, **values)


# ---------------------------------------------------------------------------- problem


class Problem:
    """The simulations and the loss for one outcomes set, object and settings."""

    def __init__(
        self,
        obj: ObjectModel,
        outcomes: Outcomes,
        names,
        settings: Settings | None = None,
        *,
        temperature_mm: float = 2.0,
        force_weight: float = 1.0,
        time_weight: float = 1.0,
        bounds: dict | None = None,
        pick_config: pp.PickConfig | None = None,
        backend: str = "auto",
    ) -> None:
        from mjx_pick.grasp import broadcast_params
        from mjx_pick.scene import build_scene

        check_range("calibrate", "temperature_mm", temperature_mm, 0, lo_open=True)
        self.settings = s = settings or Settings()
        self.object, self.outcomes = obj, outcomes
        self.names = canonical_params(names)
        self.space = param_space(self.names, s, obj.mass_kg, bounds)
        g = s.gripper
        bad_f = np.flatnonzero(
            (outcomes.grip_force_n < g.force_min_n) | (outcomes.grip_force_n > g.force_max_n)
        )
        if len(bad_f):
            shown = ", ".join(f"row {i + 2} ({outcomes.grip_force_n[i]:g} N)" for i in bad_f[:8])
            raise ConfigError(
                f"outcomes {shown}, column grip_force_n: outside {g.name}'s range "
                f"{g.force_min_n:g}-{g.force_max_n:g} N"
            )
        checker = pp.FeasibilityChecker(obj, g, pick_config, s.grasp)
        res = checker(outcomes.x_mm, outcomes.y_mm, outcomes.yaw_deg)
        bad = np.flatnonzero(res["reason"] != pp.fk.FEASIBLE)
        if len(bad):
            shown = ", ".join(f"row {i + 2} ({pp.REASONS[res['reason'][i]]})" for i in bad[:8])
            raise ConfigError(
                f"{len(bad)} of {len(outcomes)} measured pick-points are infeasible for "
                f"{g.name}: {shown}"
            )
        self.picks = checker.batch(
            np.arange(len(outcomes)), outcomes.x_mm, outcomes.y_mm, outcomes.yaw_deg, "calibration"
        )
        self.scene = build_scene(obj, g, s.contact, s.solver, s.grasp)
        per_row = [
            dataclasses.replace(s.grasp, grip_force_n=float(f)).params(obj, g)
            for f in outcomes.grip_force_n
        ]
        stacked = {k: np.array([getattr(p, k) for p in per_row]) for k in per_row[0]._fields}
        params = broadcast_params(per_row[0], len(outcomes), **stacked)
        self.inputs = make_inputs(
            self.scene, s.grasp, self.picks, s.overrides(self.scene, len(outcomes))
        ).replace(params=params)
        self.high_mm = s.grasp.success_height_fraction * s.grasp.lift_height_mm
        self.temperature_mm = float(temperature_mm)
        self.force_weight, self.time_weight = float(force_weight), float(time_weight)
        self.record = any(t is not None for t in outcomes.force_traces)
        n_ticks = s.grasp.n_ticks()
        t_ticks = np.arange(n_ticks) * s.grasp.control_period_s - s.grasp.settle_s
        target = np.zeros((len(outcomes), n_ticks), np.float32)
        mask = np.zeros((len(outcomes), n_ticks), np.float32)
        for i, tr in enumerate(outcomes.force_traces):
            if tr is not None:
                inside = (t_ticks >= tr[0, 0]) & (t_ticks <= tr[-1, 0])
                target[i, inside] = np.interp(t_ticks[inside], tr[:, 0], tr[:, 1])
                mask[i, inside] = 1.0
        self.trace_target, self.trace_mask = target, mask
        self.backend_name = backend
        # plain simulations (loss values, accuracy) run through the engine; a batch holds
        # every row of at least one theta
        self.engine = Engine(backend, batch_size=max(256, len(outcomes)))
        self._backend = None
        self._rollout = None
        self.rollouts = 0
        self.diverged = np.zeros(0, int)  # diverged rows per theta of the last loss()

    # --- per-pick contact arrays from parameter values (jnp: differentiable)
    def contact_arrays(self, values):
        """(R, npair, 5) friction and (R, npair, 2) solref for parameter values (P,)."""
        fr = jnp.asarray(self.inputs.pair_friction)
        ref = jnp.asarray(self.inputs.pair_solref)
        pads, table = list(self.scene.index.pad_pairs), list(self.scene.index.table_pairs)
        m = self.object.mass_kg
        for name, v in zip(self.names, values, strict=True):
            pairs = pads if name.startswith("pad") else table
            if name.endswith("friction"):
                fr = fr.at[:, pairs, 0].set(v).at[:, pairs, 1].set(v)
                if pairs is pads:  # the pads' torsional friction follows mu_pad
                    fr = fr.at[:, pairs, 2].set(v * self.scene.contact.torsion_per_friction_m)
            elif "stiffness" in name:
                ref = ref.at[:, pairs, 0].set(-per_unit_mass(v, m))
            else:
                ref = ref.at[:, pairs, 1].set(-per_unit_mass(v, m))
        return fr, ref

    # --- the loss of simulated outputs
    def loss_terms(self, lift_mm, t_reached_s, diverged, force_rows=None):
        """(loss, p) from simulated per-row outputs ((R,) or (S, R) arrays)."""
        o = self.outcomes
        shape = jnp.shape(lift_mm)
        y = jnp.broadcast_to(jnp.asarray(o.fraction, jnp.float32), shape)
        w = jnp.broadcast_to(jnp.asarray(o.trials, jnp.float32), shape)
        # clipped: a drop (margin -90 mm) must not outweigh a hold (+10 mm) 10 to 1,
        # or smoothing over the cliff between them biases the fit
        logit = jnp.clip((lift_mm - self.high_mm) / self.temperature_mm, -5.0, 5.0)
        p = jax.nn.sigmoid(logit)
        bce = w * (optax.sigmoid_binary_cross_entropy(logit, y) - _entropy(y))
        # a diverged simulation is a failure of the parameters, never a fit: its row
        # costs what the most wrong prediction the clipped logit allows would
        worst = w * (
            jnp.maximum(
                optax.sigmoid_binary_cross_entropy(jnp.full(shape, -5.0), y),
                optax.sigmoid_binary_cross_entropy(jnp.full(shape, 5.0), y),
            )
            - _entropy(y)
        )
        ok = ~diverged
        loss = jnp.sum(jnp.where(ok, bce, worst), axis=-1) / float(o.trials.sum())
        if self.time_weight and np.isfinite(o.lift_time_s).any():
            meas = jnp.broadcast_to(jnp.asarray(np.nan_to_num(o.lift_time_s), jnp.float32), shape)
            has = jnp.broadcast_to(jnp.asarray(np.isfinite(o.lift_time_s)), shape) & ok
            # a simulation that never reached F_d waited the whole close timeout
            g = self.settings.grasp
            sim = jnp.where(t_reached_s >= 0, t_reached_s - g.settle_s, g.close_timeout_s)
            err = jnp.where(has, ((sim - meas) / 0.05) ** 2, 0.0)
            loss = loss + self.time_weight * jnp.sum(err, axis=-1) / float(
                max(1, np.isfinite(o.lift_time_s).sum())
            )
        if self.force_weight and force_rows is not None:
            fshape = jnp.shape(force_rows)
            f_d = jnp.broadcast_to(jnp.asarray(o.grip_force_n, jnp.float32)[:, None], fshape)
            target = jnp.broadcast_to(jnp.asarray(self.trace_target), fshape)
            mask = jnp.broadcast_to(jnp.asarray(self.trace_mask), fshape) * jnp.expand_dims(
                ok, -1
            ).astype(jnp.float32)
            err = ((force_rows - target) / f_d) ** 2 * mask
            loss = loss + self.force_weight * jnp.sum(err, axis=(-2, -1)) / max(
                1.0, float(self.trace_mask.sum())
            )
        return loss, p

    # --- backends
    def _forward_backend(self):
        """The backend of plain simulations (loss values, accuracy): as chosen ("auto":
        MJX on an accelerator, else the C engine)."""
        if self._backend is None:
            self._backend = self.engine.make(self.scene, self.settings.grasp)
        return self._backend

    def simulate(self, thetas: np.ndarray) -> dict:
        """Simulate every row for each theta (S, P) in ONE batch; outputs (S, R)."""
        thetas = np.atleast_2d(np.asarray(thetas, np.float32))
        s_n, r = len(thetas), len(self.outcomes)
        values = np.asarray(jax.vmap(self.space.values)(thetas))
        frs, refs = zip(*(self.contact_arrays(v) for v in values), strict=True)
        inputs = jax.tree.map(lambda a: np.concatenate([a] * s_n), self.inputs)
        inputs = inputs.replace(
            pair_friction=np.concatenate([np.asarray(f) for f in frs]),
            pair_solref=np.concatenate([np.asarray(x) for x in refs]),
        )
        out, rows, _ = self.engine.run(self._forward_backend(), inputs, record=self.record)
        self.rollouts += len(inputs)
        res = {k: np.asarray(v).reshape(s_n, r) for k, v in out.items()}
        if rows is not None:
            from mjx_pick.kernels.grasp import TRACE_FIELDS

            left = rows[..., TRACE_FIELDS.index("force_left_n")]
            right = rows[..., TRACE_FIELDS.index("force_right_n")]
            res["force"] = (0.5 * (left + right)).reshape(s_n, r, -1)
        return res

    def loss(self, thetas: np.ndarray) -> np.ndarray:
        """Loss at each theta (S,) (no derivatives). Diverged rows are left out of the
        loss and counted: ``diverged`` holds their number per theta (S,)."""
        out = self.simulate(thetas)
        self.diverged = out["diverged"].sum(axis=-1)
        loss, _ = self.loss_terms(
            out["lift_height_mm"], out["t_reached_s"], out["diverged"], out.get("force")
        )
        return np.asarray(loss, float)

    def mjx_loss_and_grad(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """Loss and its forward-mode gradient through the MJX rollout.

        The one simulation outside ``Engine.run``: ``jax.jacfwd`` needs the rollout in
        its trace (``engine.differentiable_rollout`` says why)."""
        if self._rollout is None:
            roll = differentiable_rollout(self.scene, self.settings.grasp, self.record)
            inp = self.inputs

            def loss_fn(th):
                fr, ref = self.contact_arrays(self.space.values(th))
                out, rows = roll(inp.qpos0, inp.params, fr, ref, inp.pair_solimp)
                force = None
                if rows is not None:
                    from mjx_pick.kernels.grasp import TRACE_FIELDS

                    force = 0.5 * (
                        rows[..., TRACE_FIELDS.index("force_left_n")]
                        + rows[..., TRACE_FIELDS.index("force_right_n")]
                    )
                loss, _ = self.loss_terms(
                    out["lift_height_mm"], out["t_reached_s"], out["diverged"], force
                )
                return loss

            self._rollout = jax.jit(lambda th: (loss_fn(th), jax.jacfwd(loss_fn)(th)))
        loss, grad = self._rollout(jnp.asarray(theta, jnp.float32))
        self.rollouts += len(self.outcomes) * (1 + len(self.names))
        return float(loss), np.asarray(grad, float)

    def smoothed_grad(self, theta, samples: int, sigma: float):
        """Gradient of the Gaussian-smoothed loss along each parameter, by Gauss-Hermite
        quadrature: dE[L(theta + sigma Z e_i)]/dtheta_i = E[Z L(theta + sigma Z e_i)] /
        sigma, with `samples` symmetric node pairs per parameter. Deterministic (no
        sampling noise); every node of every parameter runs in ONE simulation batch.
        Returns (loss at theta, gradient (P,))."""
        nodes, weights = np.polynomial.hermite_e.hermegauss(2 * samples)
        weights = weights / weights.sum()
        pos = nodes > 0
        z, w = nodes[pos], weights[pos]
        p = len(theta)
        shifts = [np.eye(p, dtype=np.float32)[i] * sigma * zk for i in range(p) for zk in z]
        thetas = np.concatenate(
            [theta[None], theta + np.asarray(shifts), theta - np.asarray(shifts)]
        ).astype(np.float32)
        losses = self.loss(thetas)
        n = len(shifts)
        diff = (losses[1 : n + 1] - losses[n + 1 :]).reshape(p, len(z))
        grad = (diff * (w * z)[None, :]).sum(axis=1) / sigma
        return float(losses[0]), grad

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


def _entropy(y):
    """Binary entropy of the observed fractions: the cross-entropy's floor, so that a
    perfect fit has loss 0."""
    y = jnp.clip(y, 1e-7, 1 - 1e-7)
    h = -(y * jnp.log(y) + (1 - y) * jnp.log(1 - y))
    return jnp.where((y <= 1e-6) | (y >= 1 - 1e-6), 0.0, h)


# -------------------------------------------------------------------------------- fit


@dataclasses.dataclass
class CalibrationResult:
    contact: ContactParams  # the fitted contact parameters (TOML-ready)
    values: dict[str, float]
    initial: dict[str, float]
    history: list[dict]  # per step: step, loss, values, wall_s, rollouts
    accuracy_before: dict | None
    accuracy_after: dict | None
    out_dir: Path | None


class _Checkpoints:
    """Fit state (theta, optimiser state, step, history) saved with orbax-checkpoint."""

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


def calibrate(
    problem: Problem,
    *,
    steps: int = 200,
    learning_rate: float = 0.1,
    estimator: str = "smoothed",
    samples: int = 2,
    sigma: float = 0.2,
    checkpoint_every: int = 10,
    out: str | Path | None = None,
    resume: bool = False,
    holdout: Problem | None = None,
    log=None,
) -> CalibrationResult:
    """Fit problem's parameters with optax Adam; see the module docstring.

    Args:
      estimator: "smoothed" (any backend) or "jvp" (MJX forward mode).
      samples, sigma: quadrature node pairs per parameter and the smoothing's spread
        in theta space (it shrinks to 0.3 sigma over the fit).
      checkpoint_every: steps between orbax checkpoints (with out); resume continues.
      holdout: a Problem on held-out pick-points for the accuracy before and after.
      log: called with each step's history entry (progress output).
    """
    check_choice("calibrate", "estimator", estimator, ("smoothed", "jvp"))
    check_range("calibrate", "steps", steps, 0, 1_000_000)
    check_range("calibrate", "samples", samples, 1, 10_000)
    check_range("calibrate", "sigma", sigma, 0, 10, lo_open=True)
    check_range("calibrate", "checkpoint_every", checkpoint_every, 1)
    space = problem.space
    base = problem.settings.contact
    initial = {n: float(getattr(base, n)) for n in problem.names}
    theta = space.theta([initial[n] for n in problem.names])
    # the step shrinks to a tenth over the run: early steps cross plateaus of the
    # outcome, late ones settle (the smoothed gradient is noisy)
    schedule = optax.cosine_decay_schedule(learning_rate, max(1, steps), alpha=0.1)
    opt = optax.adam(schedule)
    opt_state = opt.init(jnp.asarray(theta))
    step, history, wall0, thetas = 0, [], 0.0, []
    out_dir = Path(out) if out is not None else None
    ckpt = None
    if out_dir is not None:
        if (out_dir / "checkpoint").is_dir() and not resume:
            raise ConfigError(f"{out_dir} holds an earlier fit: pass --resume or another --out")
        request = {"object": problem.object.summary(), "names": list(problem.names)}
        request.update(settings=to_dict(problem.settings), steps=steps, estimator=estimator)
        request.update(learning_rate=learning_rate, samples=samples, sigma=sigma)
        claim(out_dir, "calibrate", config_hash(request), resume=resume)
        ckpt = _Checkpoints(out_dir / "checkpoint")
        saved = ckpt.latest() if resume else None
        if saved is not None:
            theta, opt_state, step, history, wall0, thetas = _unstate(saved, opt_state)
    acc_before = (
        holdout.accuracy(space.theta([initial[n] for n in problem.names]))
        if holdout is not None and step == 0
        else None
    )
    t0 = time.perf_counter() - wall0
    try:
        while step < steps:
            if estimator == "jvp":
                loss, grad = problem.mjx_loss_and_grad(theta)
            else:
                # the spread shrinks with the step (to 0.3 sigma): wide early to see
                # across flips of the outcome, narrow late so that the smoothing's
                # bias (the cliff where held grasps drop is steep) fades
                frac = step / max(1, steps - 1)
                spread = sigma * (0.3 + 0.7 * 0.5 * (1 + math.cos(math.pi * frac)))
                loss, grad = problem.smoothed_grad(theta, samples, spread)
            if not np.isfinite(grad).all():
                # a zeroed NaN would be a silent "no change": stop and say where
                raise ConfigError(
                    f"calibration step {step}: the {estimator!r} gradient is not finite at "
                    f"{space.as_dict(theta)} (a simulation diverged or its derivative "
                    "blew up); narrow the parameter ranges or use estimator 'smoothed'"
                )
            updates, opt_state = opt.update(jnp.asarray(grad, jnp.float32), opt_state)
            theta = np.asarray(optax.apply_updates(jnp.asarray(theta), updates), np.float32)
            thetas.append(theta)
            entry = {
                "step": step,
                "loss": loss,
                "values": space.as_dict(theta),
                "grad_norm": float(np.linalg.norm(grad)),
                # rows left out of the loss because they blew up (at theta itself)
                "diverged": int(problem.diverged[0]) if estimator == "smoothed" else None,
                "wall_s": round(time.perf_counter() - t0, 3),
                "rollouts": problem.rollouts,
            }
            history.append(entry)
            if log is not None:
                log(entry)
            step += 1
            if ckpt is not None and (step % checkpoint_every == 0 or step == steps):
                ckpt.save(
                    step,
                    _state(theta, opt_state, step, history, thetas, time.perf_counter() - t0),
                )
    finally:
        if ckpt is not None:
            ckpt.close()
    # the result averages the last quarter of the iterates (Polyak-Ruppert): the
    # smoothed gradient is noisy and the outcome data flat near the optimum
    if thetas:
        theta = np.mean(thetas[-max(1, len(thetas) // 4) :], axis=0).astype(np.float32)
    values = space.as_dict(theta)
    contact = fitted_contact(base, values)
    acc_after = holdout.accuracy(theta) if holdout is not None else None
    result = CalibrationResult(contact, values, initial, history, acc_before, acc_after, out_dir)
    if out_dir is not None:
        write_result(result, problem, out_dir)
        meta = problem.engine.describe(time.perf_counter() - t0)
        meta["timing"]["rollouts"] = problem.rollouts
        if estimator == "jvp":  # the gradients ran on MJX's JAX physics, beside the engine
            d = jax.devices()[0]
            meta.update(backend="mjx", device=f"{d.platform}:{d.device_kind}")
        finish(out_dir, command="calibrate", config=request, **meta)
    return result


def _state(theta, opt_state, step, history, thetas, wall_s) -> dict:
    """Everything a resumed fit needs to continue exactly (arrays only, for orbax)."""
    return {
        "theta": np.asarray(theta, np.float32),
        "opt_state": [np.asarray(x) for x in jax.tree.leaves(opt_state)],
        "step": np.int64(step),
        "wall_s": np.float64(wall_s),
        "iterates": np.asarray(thetas, np.float32).reshape(len(thetas), -1),
        "history": np.asarray(
            [[h["loss"], h["grad_norm"], h["wall_s"], h["rollouts"]] for h in history],
            np.float64,
        ).reshape(len(history), 4),
    }


def _unstate(saved: dict, opt_like):
    opt_state = jax.tree.unflatten(
        jax.tree.structure(opt_like), [jnp.asarray(x) for x in saved["opt_state"]]
    )
    history = [
        {
            "step": i,
            "loss": float(h[0]),
            "grad_norm": float(h[1]),
            "wall_s": float(h[2]),
            "rollouts": int(h[3]),
            "restored": True,
        }
        for i, h in enumerate(np.asarray(saved["history"]))
    ]
    thetas = [np.asarray(t, np.float32) for t in np.asarray(saved["iterates"])]
    return (
        np.asarray(saved["theta"], np.float32),
        opt_state,
        int(saved["step"]),
        history,
        float(saved["wall_s"]),
        thetas,
    )


def write_result(result: CalibrationResult, problem: Problem, out_dir: Path) -> None:
    """contact.toml (for evaluate --contact), calibration.json, loss.png, report.md."""
    from mjx_pick.config import to_toml, write_atomic

    write_atomic(out_dir / "contact.toml", to_toml(result.contact))
    write_json(
        out_dir / "calibration.json",
        {
            "parameters": list(problem.names),
            "initial": result.initial,
            "fitted": result.values,
            "bounds": {
                n: [float(a), float(b)]
                for n, a, b in zip(problem.names, problem.space.lo, problem.space.hi, strict=True)
            },
            "contact": to_dict(result.contact),
            "accuracy_before": result.accuracy_before,
            "accuracy_after": result.accuracy_after,
            "rows": len(problem.outcomes),
            "rollouts": problem.rollouts,
            "history": result.history,
        },
    )

    from mjx_pick.plots import new_figure, save_png

    fig, ax = new_figure(figsize=(6, 3.5))
    ax.plot([h["step"] for h in result.history], [h["loss"] for h in result.history])
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, out_dir / "loss.png")
    lines = [
        "# Calibration",
        "",
        f"{len(problem.outcomes)} measured pick-points, {problem.rollouts} simulations.",
        "",
        "| parameter | initial | fitted |",
        "|---|---|---|",
    ]
    lines += [f"| {n} | {result.initial[n]:.4g} | {result.values[n]:.4g} |" for n in problem.names]
    if result.history:
        lines += [
            "",
            f"Loss {result.history[0]['loss']:.4f} -> {result.history[-1]['loss']:.4f}"
            f" in {len(result.history)} steps.",
        ]
    for label, acc in (("before", result.accuracy_before), ("after", result.accuracy_after)):
        if acc:
            lines.append(f"Held-out accuracy {label}: {acc['correct']}/{acc['total']}.")
    lines += ["", "Use: `mjx-pick evaluate OBJECT --contact contact.toml`."]
    write_atomic(out_dir / "report.md", "\n".join(lines) + "\n")


def random_search(
    problem: Problem, evaluations: int, batch: int = 16, seed: int = 0, target: float | None = None
) -> dict:
    """Gradient-free baseline: uniform draws in the bounded space, best so far.

    Stops at `evaluations` or as soon as the best loss reaches `target`. Returns the
    best values, its loss, the rollouts and wall time spent, and the trajectory.
    """
    rng = np.random.default_rng(seed)
    best, best_theta, spent, trace = math.inf, None, 0, []
    t0 = time.perf_counter()
    start = problem.rollouts
    while spent < evaluations:
        u = rng.uniform(0.02, 0.98, (min(batch, evaluations - spent), len(problem.names)))
        thetas = np.log(u / (1 - u)).astype(np.float32)
        losses = problem.loss(thetas)
        spent += len(thetas)
        i = int(np.argmin(losses))
        if losses[i] < best:
            best, best_theta = float(losses[i]), thetas[i]
        trace.append(
            {
                "evaluations": spent,
                "best_loss": best,
                "rollouts": problem.rollouts - start,
                "wall_s": round(time.perf_counter() - t0, 3),
            }
        )
        if target is not None and best <= target:
            break
    return {
        "values": problem.space.as_dict(best_theta),
        "loss": best,
        "trace": trace,
        "rollouts": problem.rollouts - start,
        "wall_s": time.perf_counter() - t0,
    }


def synthetic_outcomes(
    obj: ObjectModel,
    hidden: Settings,
    x_mm,
    y_mm,
    yaw_deg,
    grip_force_n,
    *,
    traces: bool = False,
    lift_times: bool = False,
    backend: str = "mujoco",
) -> Outcomes:
    """Outcomes as a real cell would report them, simulated with hidden settings.

    One trial per row (the simulation is deterministic); with traces, each row gets
    its mean pad force from the close command on; with lift_times, the time F_d was
    reached. For validating calibration: fit from other settings, compare with hidden.
    """
    x_mm, y_mm, yaw_deg, f = (
        np.atleast_1d(np.asarray(a, float)) for a in (x_mm, y_mm, yaw_deg, grip_force_n)
    )
    n = len(x_mm)
    dummy = Outcomes(
        x_mm, y_mm, yaw_deg, f, np.ones(n), np.zeros(n), np.full(n, np.nan), tuple([None] * n)
    )
    problem = Problem(obj, dummy, ["pad_friction"], hidden, backend=backend)
    problem.record = traces
    theta = problem.space.theta([hidden.contact.pad_friction])
    out = problem.simulate(theta[None])
    g = hidden.grasp
    t = np.arange(g.n_ticks()) * g.control_period_s - g.settle_s
    keep = t >= 0
    rows = (
        tuple(np.stack([t[keep], out["force"][0, i, keep]], axis=1) for i in range(n))
        if traces
        else tuple([None] * n)
    )
    lift = out["t_reached_s"][0] - g.settle_s
    lift = np.where(out["t_reached_s"][0] >= 0, lift, np.nan) if lift_times else np.full(n, np.nan)
    return dataclasses.replace(
        dummy, successes=out["success"][0].astype(float), lift_time_s=lift, force_traces=rows
    )
