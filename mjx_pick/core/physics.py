"""Contact parameters (the paper's Table 1), solver settings, and their MuJoCo mapping.

The mapping and the defaults' reasons: docs/physics.md.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from mjx_pick.core.config import (
    ConfigError,
    PlausibilityWarning,
    check_choice,
    check_fields,
    check_range,
    setting,
)

# the largest time step whose labels match smaller steps' (docs/physics.md, "Time step")
CONVERGED_TIMESTEP_S = 0.002


# what a parametric pad collides through (ContactParams.pad_collision)
PAD_COLLISIONS = ("pad", "mean_radius", "rimmed")

# "rimmed": how far the whole pad sits behind the "mean_radius" box (docs/physics.md,
# "What a pad collides through")
PAD_RIM_RECESS_MM = 0.1

# elliptic cones with the "mean_radius" box: the share sin(30 deg) of a rubber pad's
# torsion each contact point carries, its corners at r_mean cos(30 deg) (docs/physics.md)
ELLIPTIC_TORSION_SHARE = 0.5


@dataclasses.dataclass(frozen=True)
class ContactParams:
    """Contact parameters. Defaults: the paper's Table 1 (docs/physics.md)."""

    # Coulomb coefficients (MuJoCo: one per contact; sliding, both tangent directions)
    pad_friction: float = setting(
        0.86, "-", "pad-object Coulomb friction (Table 1: static = dynamic = 0.86)",
        lo=0, hi=5, lo_open=True,
    )  # fmt: skip
    table_friction: float = setting(
        0.2, "-", "object-table Coulomb friction (Table 1's dynamic value; static 0.4)",
        lo=0, hi=5,
    )  # fmt: skip
    # ADAMS impact stiffness/damping (Table 1); mapped to negative solref, clamped
    pad_stiffness_n_per_mm: float = setting(
        1e5, "N/mm", "pad-object contact stiffness (above the stable limit: clamped)",
        lo=0, lo_open=True,
    )  # fmt: skip
    pad_damping_ns_per_mm: float = setting(
        5.5, "N s/mm", "pad-object contact damping (above the stable limit: clamped)",
        lo=0, lo_open=True,
    )  # fmt: skip
    table_stiffness_n_per_mm: float = setting(
        1e5, "N/mm", "object-table contact stiffness (above the stable limit: clamped)",
        lo=0, lo_open=True,
    )  # fmt: skip
    table_damping_ns_per_mm: float = setting(
        10.0, "N s/mm", "object-table contact damping (above the stable limit: clamped)",
        lo=0, lo_open=True,
    )  # fmt: skip
    # torsional friction of the pad contacts; None: from the pad's contact patch
    pad_torsion_mm: float | None = setting(
        None, "mm", "pads' torsional friction: torque limit per N of normal force "
        "(none: pad_friction x the contact patch's mean radius)",
        lo=0, hi=100,
    )  # fmt: skip
    # MuJoCo impedance (dmin, dmax, width [m], midpoint, power): docs/physics.md,
    # "Impedance"
    pad_solimp: tuple[float, float, float, float, float] = (0.99, 0.99, 0.001, 0.5, 2.0)
    table_solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    # what a pad collides through: "pad", "mean_radius" or "rimmed" (docs/physics.md,
    # "What a pad collides through")
    pad_collision: str = "rimmed"
    # MuJoCo's pair margin on the pad contacts (docs/physics.md, "A contact margin");
    # MJX's JAX collider has none between boxes and meshes: the 'mjx' backend runs 0
    pad_margin_mm: float = setting(
        0.05, "mm", "pad contacts: points within this distance of touching join the contact",
        lo=0, hi=1,
    )  # fmt: skip

    @classmethod
    def differentiable(cls, base: ContactParams | None = None) -> ContactParams:
        """base (default: the defaults) with the pad margin MJX's JAX engine runs
        (``DIFFERENTIABLE_PAD_MARGIN_MM``: none)."""
        return dataclasses.replace(base or cls(), pad_margin_mm=DIFFERENTIABLE_PAD_MARGIN_MM)

    def __post_init__(self):
        o = "contact"
        check_fields(self, o)
        check_choice(o, "pad_collision", self.pad_collision, PAD_COLLISIONS)
        for name in ("pad_solimp", "table_solimp"):
            value = getattr(self, name)
            if len(value) != 5:
                raise ConfigError(f"contact.{name} = {value!r} must have 5 numbers")
            dmin, dmax, width, mid, power = value
            check_range(o, f"{name}[0] (dmin)", dmin, 0, 1, lo_open=True, hi_open=True)
            check_range(o, f"{name}[1] (dmax)", dmax, dmin, 1, hi_open=True)
            check_range(o, f"{name}[2] (width)", width, 0, lo_open=True)
            check_range(o, f"{name}[3] (midpoint)", mid, 0, 1, lo_open=True, hi_open=True)
            check_range(o, f"{name}[4] (power)", power, 1)


@dataclasses.dataclass(frozen=True)
class SolverParams:
    """MuJoCo solver settings shared by every backend (the defaults' reasons:
    docs/physics.md, "The solver defaults")."""

    timestep_s: float = setting(0.001, "s", "physics time step", lo=1e-5, hi=0.01)
    cone: str = "elliptic"
    impratio: float = setting(
        100.0, "-", "frictional-to-normal constraint impedance ratio (MuJoCo's impratio)",
        lo=1, hi=1000,
    )  # fmt: skip
    iterations: int = setting(50, "iterations", "constraint solver iterations", lo=1, hi=1000)
    ls_iterations: int = setting(
        50, "iterations", "line-search iterations per solver iteration", lo=1, hi=1000
    )
    tolerance: float = setting(
        1e-8, "-", "solver stops below this relative improvement", lo=0, hi=1e-2
    )
    # MuJoCo's no-slip post-solver (iterations; 0: off)
    noslip_iterations: int = setting(
        0, "iterations", "MuJoCo's no-slip post-solver (0: off; C and Warp only)", lo=0, hi=1000
    )
    integrator: str = "implicitfast"
    # the stiffest contact allowed (Table 1's values are clamped to it): docs/physics.md
    contact_timeconst_s: float = setting(
        0.002, "s", "stiffest contact allowed: its time constant (at least 2 time steps)",
        lo=0, hi=1, lo_open=True,
    )  # fmt: skip

    def __post_init__(self):
        o = "solver"
        check_fields(self, o)
        check_choice(o, "cone", self.cone, ("elliptic", "pyramidal"))
        check_choice(o, "integrator", self.integrator, ("implicitfast", "euler"))
        if self.timestep_s > CONVERGED_TIMESTEP_S:
            warnings.warn(
                f"solver.timestep_s = {self.timestep_s:g} is above {CONVERGED_TIMESTEP_S:g} s, "
                "the largest step known to leave the labels as they are at smaller steps: "
                "successes may turn into failures or diverge (docs/physics.md, 'Time step'); "
                f"use --timestep-s {CONVERGED_TIMESTEP_S:g} or less",
                PlausibilityWarning,
                stacklevel=3,
            )

    @property
    def timeconst_s(self) -> float:
        """The contact time constant in effect: at least two time steps."""
        return max(self.contact_timeconst_s, 2 * self.timestep_s)

    @classmethod
    def differentiable(cls, base: SolverParams | None = None) -> SolverParams:
        """The solver MJX's JAX engine runs: base (default: the defaults) with the
        fields of ``DIFFERENTIABLE_SOLVER``."""
        return dataclasses.replace(base or cls(), **DIFFERENTIABLE_SOLVER)


# The solver fields MJX's JAX engine runs with, whatever the defaults are: "the
# differentiable physics", with pads without a contact margin (docs/physics.md, "MJX's
# JAX physics"). The other solver fields (time step, tolerance, integrator, contact time
# constant) are the user's
DIFFERENTIABLE_SOLVER = {
    "cone": "pyramidal",
    "impratio": 1.0,
    "iterations": 20,
    "ls_iterations": 8,
    "noslip_iterations": 0,
}

# MJX's JAX collider has no margin between a box and a mesh: its pads touch where they
# penetrate
DIFFERENTIABLE_PAD_MARGIN_MM = 0.0


def differentiable_mismatches(solver: SolverParams, pad_margin_mm: float) -> tuple[str, ...]:
    """The settings that keep MJX's JAX engine from running as asked, as
    "section.field = value" (empty: it runs them)."""
    wrong = [
        f"solver.{k} = {getattr(solver, k)!r}"
        for k, v in DIFFERENTIABLE_SOLVER.items()
        if getattr(solver, k) != v
    ]
    if abs(pad_margin_mm - DIFFERENTIABLE_PAD_MARGIN_MM) > 1e-12:
        wrong.append(f"contact.pad_margin_mm = {pad_margin_mm:g}")
    return tuple(wrong)


def differentiable_physics() -> str:
    """The differentiable physics in words, for notes and errors."""
    s = DIFFERENTIABLE_SOLVER
    return (
        f"{s['cone']} cones, impratio {s['impratio']:g}, {s['iterations']} solver and "
        f"{s['ls_iterations']} line-search iterations, no no-slip solver, pads without a "
        "contact margin"
    )


@dataclasses.dataclass(frozen=True)
class MujocoContact:
    """What ContactParams become in MuJoCo for one object (docs/physics.md)."""

    pad_friction: float
    pad_torsion_m: float  # torsional friction coefficient of the pad contacts, m
    table_friction: float
    pad_solref: tuple[float, float]  # negative form (-k [1/s^2], -b [1/s])
    table_solref: tuple[float, float]
    pad_solimp: tuple[float, float, float, float, float]
    table_solimp: tuple[float, float, float, float, float]
    pad_margin_m: float  # MuJoCo's pair margin on the pad contacts, m
    clamped: tuple[str, ...]  # which Table-1 values were limited by the time step

    @property
    def torsion_per_friction_m(self) -> float:
        """Torsional friction per unit of pad friction, m (the patch's mean radius, or
        the ratio a user's pad_torsion_mm set): another pad friction scales mu_t by it."""
        return self.pad_torsion_m / self.pad_friction


def per_unit_mass(n_per_mm, mass_kg):
    """A spring's stiffness (N/mm) or damping (N s/mm) per kg of the body it holds: the
    magnitude of MuJoCo's negative solref terms (1/s^2, 1/s). Works on arrays (jnp too:
    calibration differentiates through it)."""
    return n_per_mm * 1e3 / mass_kg


def stiffest_spring(mass_kg: float, timeconst_s: float) -> tuple[float, float]:
    """(stiffness N/mm, damping N s/mm) of the critically damped contact with that time
    constant on a body of mass_kg: the stiffest one MuJoCo integrates stably."""
    return mass_kg / timeconst_s**2 * 1e-3, 2.0 * mass_kg / timeconst_s * 1e-3


def spring_solref(
    stiffness_n_per_mm: float, damping_ns_per_mm: float, mass_kg: float, timeconst_s: float
) -> tuple[tuple[float, float], tuple[str, ...]]:
    """Negative solref for a physical spring-damper on a body of mass_kg, clamped.

    Returns:
      (-k, -b) with k in 1/s^2 and b in 1/s, and the names of the clamped terms.
    """
    k, b = solref_terms(stiffness_n_per_mm, damping_ns_per_mm, mass_kg, timeconst_s)
    k_max, b_max = (per_unit_mass(v, mass_kg) for v in stiffest_spring(mass_kg, timeconst_s))
    clamped = []
    if per_unit_mass(stiffness_n_per_mm, mass_kg) > k_max:
        clamped.append("stiffness")
    if per_unit_mass(damping_ns_per_mm, mass_kg) > b_max:
        clamped.append("damping")
    return (-float(k), -float(b)), tuple(clamped)


def solref_terms(stiffness_n_per_mm, damping_ns_per_mm, mass_kg, timeconst_s, xp=np):
    """(k [1/s^2], b [1/s]), the magnitudes of the negative solref of a spring-damper on
    a body of mass_kg, each clamped to the stiffest stable contact. The one stiffness
    and damping -> solref mapping: :func:`spring_solref` and calibration (arrays; xp=jnp
    where it is differentiated) both use it."""
    k_max, b_max = (per_unit_mass(v, mass_kg) for v in stiffest_spring(mass_kg, timeconst_s))
    k = xp.minimum(per_unit_mass(stiffness_n_per_mm, mass_kg), k_max)
    b = xp.minimum(per_unit_mass(damping_ns_per_mm, mass_kg), b_max)
    return k, b


def pad_torsion_m(pad_friction, pad_torsion_mm, patch_mm: tuple[float, float]):
    """Torsional friction coefficient of the pad contacts, m: pad_torsion_mm when set,
    else mu_pad * the patch's mean radius (module docstring). Works on arrays."""
    if pad_torsion_mm is not None:
        return pad_torsion_mm * 1e-3
    return pad_friction * patch_mean_radius_mm(*patch_mm) * 1e-3


def torsion_share(contact: ContactParams, solver: SolverParams, pad_box: bool = True) -> float:
    """The factor on the pad contacts' derived torsion mu r_mean: ELLIPTIC_TORSION_SHARE
    with elliptic cones and the "mean_radius" box on a pad it applies to (its corners then
    carry the rest of the rubber pad's torsion in quadrature; "rimmed" likewise), else 1.
    A pad_torsion_mm the user set is kept as set."""
    if not pad_box or contact.pad_torsion_mm is not None:
        return 1.0
    if contact.pad_collision in ("mean_radius", "rimmed") and solver.cone == "elliptic":
        return ELLIPTIC_TORSION_SHARE
    return 1.0


def patch_mean_radius_mm(width_mm: float, height_mm: float, n: int = 200) -> float:
    """Mean distance from the centre of a uniformly loaded width x height rectangle, mm.

    (For a square of side s it is 0.383 s; for a line of length L, L / 4.)
    """
    u = (np.arange(n) + 0.5) / n - 0.5
    x, y = np.meshgrid(u * width_mm, u * height_mm)
    return float(np.mean(np.hypot(x, y)))


def mujoco_contact(
    contact: ContactParams,
    solver: SolverParams,
    mass_kg: float,
    patch_mm: tuple[float, float],
    pad_box: bool = True,
) -> MujocoContact:
    """Map ContactParams to MuJoCo pair parameters for an object of mass_kg.

    patch_mm: (width, height) of the pads' contact patch on this object, mm.
    pad_box: ContactParams.pad_collision applies to the pads (the parametric jaw's, or
    an MJCF gripper's box pads; other MJCF pads keep their own geoms).
    """
    tc = solver.timeconst_s
    pad_ref, pad_c = spring_solref(
        contact.pad_stiffness_n_per_mm, contact.pad_damping_ns_per_mm, mass_kg, tc
    )
    tab_ref, tab_c = spring_solref(
        contact.table_stiffness_n_per_mm, contact.table_damping_ns_per_mm, mass_kg, tc
    )
    mu = contact.pad_friction
    return MujocoContact(
        pad_friction=mu,
        pad_torsion_m=float(
            pad_torsion_m(mu, contact.pad_torsion_mm, patch_mm)
            * torsion_share(contact, solver, pad_box)
        ),
        table_friction=contact.table_friction,
        pad_solref=pad_ref,
        table_solref=tab_ref,
        pad_solimp=tuple(contact.pad_solimp),
        table_solimp=tuple(contact.table_solimp),
        pad_margin_m=contact.pad_margin_mm * 1e-3,
        clamped=tuple(f"pad_{c}" for c in pad_c) + tuple(f"table_{c}" for c in tab_c),
    )


# tables a calibration writes into contact.toml besides ContactParams' own keys
CONTACT_META_TABLES = ("fitted_for", "calibrated")


def load_contact(path) -> tuple[ContactParams, dict]:
    """ContactParams from a TOML file, and its metadata tables (CONTACT_META_TABLES: what
    a calibration fitted them for and its other results; empty for a plain file)."""
    from pathlib import Path

    from mjx_pick.core.config import from_mapping, read_toml

    path = Path(path)
    data = read_toml(path, "ContactParams")
    meta = {k: data.pop(k) for k in CONTACT_META_TABLES if isinstance(data.get(k), dict)}
    return from_mapping(ContactParams, data, where=path.name), meta
