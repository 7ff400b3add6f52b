"""Contact parameters (the paper's Table 1) and solver settings, and their MuJoCo mapping.

The paper's ADAMS model uses an impact contact: force = K * depth**e + B * depth_rate,
with K = 1e5 N/mm, B = 5.5 N s/mm (finger-object) or 10 N s/mm (object-ground),
exponents 1.2 / 2.2, full damping at 1 um / 10 um penetration, and static/dynamic
Coulomb friction with stiction and friction transition velocities (Table 1).

MuJoCo has a different, soft-constraint contact model, so the mapping is partial:

* Friction: MuJoCo has one Coulomb coefficient per contact (pyramidal or elliptic
  cone). The pads use the paper's static coefficient (0.86, equal to its dynamic one):
  holding is sticking. The object-table contact uses the *dynamic* coefficient (0.2):
  the object slides on the table when the first finger pushes it, and MuJoCo's soft
  contacts creep under any tangential load, so stiction is not representable anyway.
* Stiffness and damping: a negative ``solref = (-k, -b)`` gives MuJoCo a mass-normalised
  spring k [1/s^2] and damper b [1/s]. We take k = K / m and b = B / m with m the
  object's mass (the contact's effective mass: the fingers are held by stiff servos and
  the table is fixed). MuJoCo integrates this reference spring once per time step, so
  it is stable only for a contact time constant of at least about two time steps (its
  own ``refsafe`` rule for positive solref). Table 1's values are 4-5 orders of
  magnitude stiffer than that at any practical time step (ADAMS used a variable-step
  stiff integrator and ~1 um penetration), so they are clamped to the stiffest stable
  contact: critically damped with time constant ``SolverParams.timeconst_s``.
  Softer values (e.g. from calibration) pass through unclamped. ``mujoco_contact``
  reports what was clamped.
* Pad contacts are soft-finger contacts (``condim`` 4): besides Coulomb friction in
  the pad plane they resist spinning about the contact normal -- the grip axis -- up
  to a torque of mu_t * N. A single point contact with condim 3 cannot: a part held
  off its centre of mass turned in the grasp and slid out at any force. A real pad
  carries that torque with its contact patch: under uniform pressure p = N / A, the
  friction of each patch element acts at its distance r from the patch centre, so the
  largest torque is mu * N * mean(r). Hence mu_t = mu_pad * r_mean(patch), with the
  patch a rectangle: the pad's width (or the object's, if narrower) by the height of
  the object's side wall within the pads' band (``ObjectModel.wall_height_mm``; a rigid
  curved side touches a flat rubber pad only near its widest section).
  ``pad_torsion_mm`` sets mu_t directly. Where the collider spreads a contact over
  several points (the four corners of a pad's overlap with a flat face, the two ends of
  a line contact), their Coulomb friction also resists spin, at the corners: with
  pyramidal cones a corner at (a, b) from the patch centre resists with mu N max(|a|,
  |b|) of its normal force N. With the whole pad colliding (``pad_collision = "pad"``,
  the default before issue 32) the grasp then holds 1.5-1.9x (pyramidal) or 1.5-2.8x
  (elliptic) the torque of a uniformly pressed pad,
  whose limit in pure torsion is mu N r_mean (the uniform-pressure result for a flat
  contact, a disc's 2/3 mu N R; Goyal, Ruina and Papadopoulos, "Planar sliding with dry
  friction", Wear 143, 1991). ``pad_collision = "mean_radius"`` makes a parametric pad
  collide through a box cut to the patch's mean radius
  (``mjx_pick.core.scene.pad_collision_box_mm``: its corners at most r_mean from the
  patch centre), which brings the torque close to a rubber pad's where the load is a
  small part of the pads' friction capacity. With elliptic cones (the default) a corner
  resists with mu N sqrt(a^2 + b^2) and its point torsion adds in quadrature, so the box
  is cut so that the overlap's corners sit at r_mean cos(30 deg) and each point keeps
  mu r_mean sin(30 deg) of torsion (``ELLIPTIC_TORSION_SHARE``). Why a narrower geom
  and not more contact points: MuJoCo's solver shares a pad's normal force among its
  coplanar contacts as the friction demand asks, not as a pressure field would, so
  under torsion the force moves to the outermost points and the capacity follows the
  largest lever (a 2 x 2 grid of pad cells held 1.6-2.3x a rubber pad). The box alone
  touches a part only within it: a pick at a part's corner or end under the pad's
  outer region is missed (no_contact, force_not_reached), and a part the pads turn into
  line with them on closing turns less than under the real pad. ``pad_collision =
  "rimmed"``, the default, keeps the box and adds the whole pad recessed
  ``PAD_RIM_RECESS_MM`` behind it with the same friction: a flat face the box presses
  stays clear of the rim, so its torque is the box's, and a part the box misses meets
  the rim and is gripped and aligned as by the whole pad. Where the part's surface
  reaches the rim beside the box (a curved or tapered part), the rim's contacts add
  their own lever, as a real pad pressed harder at its edge would. An MJCF gripper
  whose pads are boxes gets the same box and rim over its pad geoms' bounding box
  (``mjx_pick.core.scene``); other MJCF pads, and ``"pad"``, keep the gripper's own
  geoms. ``mjx_pick.core.holding`` states the
  model's capacity from the contact points and a rubber pad's for comparison;
  benchmarks/RESULTS.md ("Torque", "Torsion like rubber") gives the figures.
* Not mappable: the force exponent (MuJoCo's spring is linear in depth; solimp shapes
  the impedance instead), the penetration depth for full damping (solimp's width plays a
  similar role), the static/dynamic split and the stiction/friction transition
  velocities (no velocity-dependent friction in MuJoCo).
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

# the largest time step whose grasp labels match those of smaller steps (the default
# procedure, MuJoCo C; benchmarks/RESULTS.md, "Time-step convergence"): larger ones are warned about
CONVERGED_TIMESTEP_S = 0.002


# what a parametric pad collides through (ContactParams.pad_collision)
PAD_COLLISIONS = ("pad", "mean_radius", "rimmed")

# "rimmed": the "mean_radius" box and, behind it, the whole pad recessed by
# PAD_RIM_RECESS_MM as a second collision geom with the same friction. A face the box
# touches stays clear of the rim (the box's contacts sit a few micrometres deep), so
# the torque is the box's; a part the box misses (a corner or end under the pad's outer
# region) meets the rim after that much more travel and is gripped as by the whole pad.
# 0.1 mm: well beyond the box's depth at the largest grip forces, and within a rubber
# pad's compression; labels moved by 1-2 in 128 picks between 0.05 and 0.2 mm
# (benchmarks/RESULTS.md, "A rim behind the pad box")
PAD_RIM_RECESS_MM = 0.1

# elliptic cones with the "mean_radius" box: the share sin(theta) of the rubber pad's
# torsion that each contact point's soft-finger torsion carries; the box's corners sit
# at r_mean cos(theta) (mjx_pick.core.scene.pad_collision_box_mm). 0.5 (theta 30 deg):
# without point torsion a 2 kg, 3 mm plate on the RG2 turned out of a grip that must
# hold (benchmarks/RESULTS.md, "Elliptic cones, impratio 10 and a rubber-like pad box")
ELLIPTIC_TORSION_SHARE = 0.5


@dataclasses.dataclass(frozen=True)
class ContactParams:
    """Contact parameters. Defaults: the paper's Table 1 (see the module docstring)."""

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
    # torsional friction of the pad contacts (length: torque limit per newton of
    # normal force); None: derived from the pad's contact patch (module docstring)
    pad_torsion_mm: float | None = setting(
        None, "mm", "pads' torsional friction: torque limit per N of normal force "
        "(none: pad_friction x the contact patch's mean radius)",
        lo=0, hi=100,
    )  # fmt: skip
    # MuJoCo impedance (dmin, dmax, width[m], midpoint, power). The pads: 0.99 instead
    # of MuJoCo's default 0.9-0.95: a soft constraint's regularisation lets a held part
    # creep down through friction at a rate that grows with (1 - d) / d; at 0.99 the
    # creep over lift and hold dropped several-fold. The table keeps MuJoCo's default:
    # made as stiff, a part pushed and spun over it by the first pad changed its label
    # with the time step (benchmarks/RESULTS.md, "creep").
    pad_solimp: tuple[float, float, float, float, float] = (0.99, 0.99, 0.001, 0.5, 2.0)
    table_solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    # what a pad collides through, on the parametric jaw and on an MJCF gripper's box
    # pads (module docstring, "Pad contacts"): "pad", the whole pad (an MJCF gripper's
    # own geoms; MuJoCo's corner contacts resist spin at the patch's edges: 1.3-2.8x
    # a rubber pad's torque); "mean_radius", a box cut so that the corners and the
    # points' own torsion hold a uniformly pressed rubber pad's torque for the solver's
    # cone (mjx_pick.core.scene.pad_collision_box_mm), touching a part only within the
    # box; or "rimmed" (the default), that box with the whole pad recessed behind it,
    # so that a part the box misses is still gripped (PAD_RIM_RECESS_MM)
    pad_collision: str = "rimmed"
    # MuJoCo's pair margin on the pad contacts: the collider keeps every point of a
    # pad's overlap with a part that lies within this distance of touching, and the
    # solver pushes from there (the pad's face acts this much proud of its geom, as a
    # rubber layer's surface does before it is compressed). At 0 only penetrating points
    # count; on a thin strip or a line contact (a plate's edge, a handle) they come and
    # go as the part rocks by micrometres, each engine's collider picks them its own
    # way, and the pads chattered and labels differed between MuJoCo C and Warp. 0.05 mm,
    # within a rubber pad's compression, keeps them (benchmarks/RESULTS.md, "A contact
    # margin on the pads"). MJX's JAX collider has none for boxes against meshes:
    # mjx_backend.jax_model leaves it out
    pad_margin_mm: float = setting(
        0.05, "mm", "pad contacts: points within this distance of touching join the contact",
        lo=0, hi=1,
    )  # fmt: skip

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
    """MuJoCo solver settings shared by both backends.

    Defaults chosen by measurement on the shipped presets with the default procedure
    (benchmarks/RESULTS.md, "Elliptic cones, impratio 10 and a rubber-like pad box" and
    "impratio 100", issue 32): elliptic cones (pyramidal: 26 wrong labels on
    the 288-pick preset grid, pad chatter on 71 must-hold picks), MuJoCo's own 50
    line-search iterations (at 8, elliptic cones diverged) and impratio 100.

    impratio sets how soft friction is against the normal direction: MuJoCo regularises
    an elliptic contact's friction rows by R_0 mu_0^2 / (mu_i^2 impratio), and a part
    held below its friction limit still creeps through the pads at a steady
    (1 - d) / d * a / (b * impratio). Over a lift and a hold that creep decides labels
    near the slip and rotation limits, and it divides among a pad's contact points, so
    it made those labels depend on how many points the collider returns (MuJoCo C's
    multi-contact against MuJoCo Warp's, which the engines do not share). At 1 the
    rubber-like pad box crept out of grips (banana 46 %), at 10 parts gripped far from
    their centre of mass still crept millimetres; 100 leaves the friction limit where
    it is (Coulomb's law: the preset grid stays at 0 wrong labels and 0 diverged on
    MuJoCo C and Warp) and cuts the creep about tenfold.

    MJX-JAX: its forward-mode gradient (calibration's ``jvp`` estimator) is NaN with
    elliptic cones (measured, issue 32): that estimator refuses them and asks for
    ``cone = "pyramidal"``, ``impratio = 1``; the other estimators simulate with these
    settings. Forward simulation on MJX uses them too (not measured there).
    """

    # 1 ms with 50 solver iterations (benchmarks/RESULTS.md, "Pad chatter"): at 10
    # iterations the solver stopped unconverged on the pads' stiff low-friction contacts
    # (pyramidal cones stiffen them as 1 / mu^2) and heavy or slippery parts diverged;
    # 50 removed that at the 1 ms step for little extra cost (a smaller step cuts the
    # wrong labels further but doubles the steps, and lets pad forces pass the limit)
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
    # the solver stops once its improvement or gradient falls below this (MuJoCo's
    # default; MuJoCo Warp keeps iterating every simulation of a call until the last
    # one is there or the iteration cap is hit)
    tolerance: float = setting(
        1e-8, "-", "solver stops below this relative improvement", lo=0, hi=1e-2
    )
    # MuJoCo's no-slip post-solver (iterations; 0: off)
    noslip_iterations: int = setting(
        0, "iterations", "MuJoCo's no-slip post-solver (0: off; C and Warp only)", lo=0, hi=1000
    )
    integrator: str = "implicitfast"
    # softest-allowed contact time constant: stiffer requests (Table 1) are clamped to
    # it. Fixed in seconds, so halving the time step refines the integration of the
    # same contact; never below two time steps (MuJoCo's refsafe rule).
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
                "the largest step measured to leave the labels as they are at smaller steps: "
                "successes may turn into failures or diverge (benchmarks/RESULTS.md, "
                f"'Time-step convergence'); use --timestep-s {CONVERGED_TIMESTEP_S:g} or less",
                PlausibilityWarning,
                stacklevel=3,
            )

    @property
    def timeconst_s(self) -> float:
        """The contact time constant in effect: at least two time steps."""
        return max(self.contact_timeconst_s, 2 * self.timestep_s)


@dataclasses.dataclass(frozen=True)
class MujocoContact:
    """What ContactParams become in MuJoCo for one object (see the module docstring)."""

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
    import tomllib
    from pathlib import Path

    from mjx_pick.core.config import from_mapping

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"ContactParams file {str(path)!r} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{str(path)!r} is not valid TOML: {err}") from err
    meta = {k: data.pop(k) for k in CONTACT_META_TABLES if isinstance(data.get(k), dict)}
    return from_mapping(ContactParams, data, where=path.name), meta
