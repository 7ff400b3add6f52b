"""The parameter space of a fit: which parameters, their bounds and priors, and how a
parameter vector becomes simulation inputs (through ``physics`` and ``Settings``: the
one ContactParams -> MuJoCo mapping, nothing re-derived here).

Details: docs/calibration.md (studies/calibration/parameters.py).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.physics import (
    ContactParams,
    pad_torsion_m,
    solref_terms,
    stiffest_spring,
    torsion_share,
)
from mjx_pick.engine.inputs import contact_values, scene_contact, set_contact


class ParamInfo(NamedTuple):
    unit: str
    log: bool  # bounded and searched in log space
    meaning: str


# every parameter a fit may take; ContactParams fields except force_offset_n
PARAMS = {
    "pad_friction": ParamInfo("-", False, "Coulomb friction of the finger pads"),
    "pad_torsion_mm": ParamInfo(
        "mm", True, "torsional friction of the pad contact (torque per N of grip force)"
    ),
    "table_friction": ParamInfo("-", False, "Coulomb friction of the object on the table"),
    "pad_stiffness_n_per_mm": ParamInfo("N/mm", True, "pad contact stiffness (capped: physics)"),
    "pad_damping_ns_per_mm": ParamInfo("N s/mm", True, "pad contact damping (capped: physics)"),
    "table_stiffness_n_per_mm": ParamInfo("N/mm", True, "table contact stiffness (capped)"),
    "table_damping_ns_per_mm": ParamInfo("N s/mm", True, "table contact damping (capped)"),
    "force_offset_n": ParamInfo(
        "N", False, "the gripper's force error: it squeezes F_d + offset when set to F_d"
    ),
}
FITTABLE = tuple(PARAMS)
ALIASES = {
    "friction": "pad_friction",
    "torsion": "pad_torsion_mm",
    "stiffness": "pad_stiffness_n_per_mm",
    "damping": "pad_damping_ns_per_mm",
    "force_offset": "force_offset_n",
}


def canonical_params(names) -> tuple[str, ...]:
    """User parameter names (aliases allowed) -> parameter names (PARAMS)."""
    if isinstance(names, str):
        names = [n for n in names.split(",") if n.strip()]
    out = []
    for n in names:
        full = ALIASES.get(n.strip(), n.strip())
        if full not in PARAMS:
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


@dataclasses.dataclass(frozen=True)
class ParamSpace:
    """Bounded parameters with Gaussian priors in z (value, or log value for log ones).

    (P,) arrays: lo, hi (natural units), log (bool), prior_mean, prior_sd (in z).
    """

    names: tuple[str, ...]
    lo: np.ndarray
    hi: np.ndarray
    log: np.ndarray
    prior_mean: np.ndarray
    prior_sd: np.ndarray

    @property
    def z_lo(self) -> np.ndarray:
        return _z(self.lo, self.log)

    @property
    def z_hi(self) -> np.ndarray:
        return _z(self.hi, self.log)

    def values(self, theta):
        """theta (..., P) -> parameter values (..., P) (jnp: differentiable)."""
        theta = jnp.asarray(theta, jnp.float32)

        def full(a):
            return jnp.broadcast_to(jnp.asarray(a), theta.shape)

        z = full(self.z_lo) + (full(self.z_hi) - full(self.z_lo)) * jax.nn.sigmoid(theta)
        return jnp.where(full(self.log), jnp.exp(z), z)

    def z(self, values) -> np.ndarray:
        return _z(values, self.log)

    def natural(self, z) -> np.ndarray:
        return np.where(self.log, np.exp(z), z)

    def theta(self, values) -> np.ndarray:
        """values (..., P) -> theta, kept 2% inside the bounds (sigmoid' vanishes there)."""
        u = (self.z(values) - self.z_lo) / (self.z_hi - self.z_lo)
        u = np.clip(u, 0.02, 0.98)
        return np.log(u / (1 - u)).astype(np.float32)

    def as_dict(self, theta) -> dict[str, float]:
        v = np.asarray(self.values(np.asarray(theta, np.float32)))
        return {n: float(x) for n, x in zip(self.names, v, strict=True)}

    def prior_residuals(self, values) -> np.ndarray:
        """(..., P) standardised distances from the prior means (z units / prior sd)."""
        return (self.z(values) - self.prior_mean) / self.prior_sd


def _z(values, log) -> np.ndarray:
    """Natural values -> z (the log of the log ones); arrays (..., P)."""
    v = np.asarray(values, float)
    return np.where(log, np.log(np.where(log, np.maximum(v, 1e-300), 1.0)), v)


def start_values(names, settings, scene) -> dict[str, float]:
    """The starting value of each parameter: what the base settings simulate --
    pad_torsion_mm as ``physics`` derives it for this object and gripper when none is
    set, stiffness and damping as clamped to the stiffest stable contact."""
    base = settings.contact
    k_max, b_max = stiffest_spring(scene.object.mass_kg, settings.solver.timeconst_s)
    out = {}
    for n in names:
        if n == "force_offset_n":
            out[n] = 0.0
        elif n == "pad_torsion_mm":
            out[n] = float(scene.contact.pad_torsion_m * 1e3)
        elif "stiffness" in n:
            out[n] = min(float(getattr(base, n)), k_max)
        elif "damping" in n:
            out[n] = min(float(getattr(base, n)), b_max)
        else:
            out[n] = float(getattr(base, n))
    return out


def param_space(
    names,
    settings,
    mass_kg: float,
    bounds: dict | None = None,
    *,
    start: dict | None = None,
    priors: dict | None = None,
    grip_force_n=None,
) -> ParamSpace:
    """Bounds and priors of names.

    Default bounds: frictions 0.05-2 (table 0.01-2); pad torsion 0.05-20 mm;
    stiffness and damping from 1/100 of the stiffest stable contact to it (``physics``:
    stiffer ones are clamped, so they are all the same simulation); force offset
    +-40 % of the smallest F_d measured (grip_force_n; else +-5 N).
    Default priors: mean = the starting value (start, else the bounds' middle), sd =
    half the bounds' width in z (weak: the data must do the work). priors maps a
    name to (mean, sd) in natural units (sd in log units for log parameters).
    """
    names = canonical_params(names)
    f_min = float(np.min(grip_force_n)) if grip_force_n is not None and len(grip_force_n) else 12.5
    default = _default_bounds(mass_kg, settings.solver.timeconst_s, f_min)
    bounds = {canonical_params([k])[0]: v for k, v in (bounds or {}).items()}
    priors = {canonical_params([k])[0]: v for k, v in (priors or {}).items()}
    lo, hi = _checked_bounds(names, bounds, default, f_min)
    log = np.array([PARAMS[n].log for n in names])
    mean, sd = _prior_moments(names, lo, hi, log, start, priors)
    return ParamSpace(names, lo, hi, log, mean, sd)


def _default_bounds(mass_kg: float, timeconst_s: float, f_min: float) -> dict:
    """{name: (lo, hi)} natural units, every parameter's default bounds (param_space's
    docstring); f_min: the smallest F_d measured (N)."""
    k_max, b_max = stiffest_spring(mass_kg, timeconst_s)  # N/mm, N s/mm
    return {
        "pad_friction": (0.05, 2.0),
        "pad_torsion_mm": (0.05, 20.0),
        "table_friction": (0.01, 2.0),
        "pad_stiffness_n_per_mm": (k_max / 100, k_max),
        "table_stiffness_n_per_mm": (k_max / 100, k_max),
        "pad_damping_ns_per_mm": (b_max / 100, b_max),
        "table_damping_ns_per_mm": (b_max / 100, b_max),
        "force_offset_n": (-0.4 * f_min, 0.4 * f_min),
    }


def _checked_bounds(names, bounds: dict, default: dict, f_min: float):
    """(lo, hi) (P,) natural units: bounds' value of each name, else default's; a ConfigError
    names a pair that is empty, not finite, not positive (all but the force offset) or
    whose force offset would make the smallest F_d (f_min, N) zero or negative."""
    lo, hi = [], []
    for n in names:
        a, b = (float(x) for x in bounds.get(n, default[n]))
        positive = n != "force_offset_n"
        if not (a < b and math.isfinite(a) and math.isfinite(b)) or (positive and a <= 0):
            rule = "0 < lo < hi" if positive else "lo < hi, both finite"
            raise ConfigError(f"calibration bounds of {n}: {a:g}..{b:g} must have {rule}")
        if n == "force_offset_n" and a <= -f_min:
            raise ConfigError(
                f"calibration bounds of force_offset_n: {a:g} would make the smallest F_d "
                f"({f_min:g} N) zero or negative; allowed lo > {-f_min:g}"
            )
        lo.append(a)
        hi.append(b)
    return np.asarray(lo), np.asarray(hi)


def _prior_moments(names, lo, hi, log, start: dict | None, priors: dict):
    """(mean, sd) (P,) of each parameter's prior in z: priors' (mean, sd) where given
    (checked: mean within lo..hi, sd > 0), else the start (or the bounds' middle) and
    half the bounds' width in z."""
    zlo, zhi = _z(lo, log), _z(hi, log)
    mean, sd = [], []
    for i, n in enumerate(names):
        if n in priors:
            m, s = (float(x) for x in priors[n])
            if not (s > 0 and math.isfinite(s)) or not lo[i] <= m <= hi[i]:
                raise ConfigError(
                    f"calibration prior of {n}: mean {m:g} must lie in the bounds "
                    f"{lo[i]:g}..{hi[i]:g} and sd {s:g} must be > 0"
                )
            mean.append(math.log(m) if log[i] else m)
            sd.append(s)
            continue
        v = (start or {}).get(n)
        if v is None or not lo[i] <= v <= hi[i]:
            z = 0.5 * (zlo[i] + zhi[i])
        else:
            z = math.log(v) if log[i] else v
        mean.append(z)
        sd.append(0.5 * (zhi[i] - zlo[i]))
    return np.asarray(mean), np.asarray(sd)


def check_start(space: ParamSpace, start: dict[str, float]) -> None:
    """A starting value outside its bounds is an error naming it."""
    for n, a, b in zip(space.names, space.lo, space.hi, strict=True):
        v = start[n]
        if not a <= v <= b:
            raise ConfigError(
                f"calibration start of {n} = {v:g} lies outside its bounds {a:g}..{b:g}: "
                "widen the bounds or start elsewhere"
            )


def fitted_contact(base: ContactParams, values: dict[str, float]) -> ContactParams:
    """ContactParams with the fitted contact values (force_offset_n is not one)."""
    return dataclasses.replace(base, **{k: v for k, v in values.items() if k != "force_offset_n"})


# the pair values a fit moves (its solimps stay the scene's)
FITTED_PAIR_VALUES = ("pad_friction", "pad_torsion", "table_friction", "pad_solref", "table_solref")


def row_inputs(problem_inputs, scene, settings, grip_force_n, values: dict[str, float]):
    """Per-row simulation inputs for one parameter vector: the contact through
    ``engine.inputs.scene_contact`` (``physics.mujoco_contact``: solref clamping,
    torsion from the patch) and F_d + force offset per row."""
    over = contact_values(
        scene_contact(scene, fitted_contact(settings.contact, values), settings.solver)
    )
    f = np.asarray(grip_force_n, np.float32) + np.float32(values.get("force_offset_n", 0.0))
    friction, solref, _ = set_contact(
        scene,
        problem_inputs.pair_friction,
        problem_inputs.pair_solref,
        problem_inputs.pair_solimp,
        {k: over[k] for k in FITTED_PAIR_VALUES},
    )
    return problem_inputs.replace(
        pair_friction=friction,
        pair_solref=solref,
        params=problem_inputs.params._replace(grip_force_n=f.astype(np.float32)),
    )


def contact_arrays_jnp(names, values, inputs, scene, settings, mass_kg):
    """(R, npair, 5) friction, (R, npair, 2) solref and (R,) grip_force_n for values (P,),
    as jnp (differentiable: forward mode through MJX). The same mapping as
    :func:`row_inputs` (``engine.backend.set_contact``, ``physics.solref_terms`` and
    ``physics.pad_torsion_m``)."""
    v = dict(zip(names, values, strict=True))
    base = settings.contact
    tc = settings.solver.timeconst_s
    mu = v.get("pad_friction", base.pad_friction)
    torsion_mm = v.get("pad_torsion_mm", base.pad_torsion_mm)
    contact = {
        "pad_friction": mu,
        "pad_torsion": pad_torsion_m(mu, torsion_mm, scene.pad_patch_mm)
        * (1.0 if "pad_torsion_mm" in v else torsion_share(base, settings.solver, scene.box_pads)),
        "table_friction": v.get("table_friction", base.table_friction),
    }
    for side in ("pad", "table"):
        k_in = v.get(f"{side}_stiffness_n_per_mm", getattr(base, f"{side}_stiffness_n_per_mm"))
        b_in = v.get(f"{side}_damping_ns_per_mm", getattr(base, f"{side}_damping_ns_per_mm"))
        k, b = solref_terms(k_in, b_in, mass_kg, tc, xp=jnp)
        contact[f"{side}_solref"] = jnp.stack([-k, -b])
    fr, ref, _ = set_contact(
        scene,
        jnp.asarray(inputs.pair_friction),
        jnp.asarray(inputs.pair_solref),
        jnp.asarray(inputs.pair_solimp),
        contact,
        xp=jnp,
    )
    force = jnp.asarray(inputs.params.grip_force_n) + v.get("force_offset_n", 0.0)
    return fr, ref, force
