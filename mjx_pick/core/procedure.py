"""The simulated pick procedure: force-controlled close, lift, hold (user settings).

:class:`GraspConfig` holds the user-facing settings (units in the names); ``params``
turns them into the kernels' per-pick SI arrays (``mjx_pick.kernels.grasp``), which
both backends share. Defaults follow the paper: F_d = 50 N (its UR5e test), a 5 ms
control period (its Simulink rate), lifting as soon as F_d is reached, a 100 mm lift.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection
from typing import TYPE_CHECKING

import numpy as np

from mjx_pick.core.config import ConfigError, check_fields, setting
from mjx_pick.core.physics import SolverParams
from mjx_pick.kernels import types as kt

if TYPE_CHECKING:  # annotations only: the procedure's module stays light to import
    from mjx_pick.core.gripper import GripperSpec
    from mjx_pick.core.objects import ObjectModel

G = 9.81


# The smallest sag, mm, a lifted part may show before it counts as not lifted:
# (1 - success_height_fraction) x lift_height_mm, i.e. a lift of at least 5 mm at the
# default fraction 0.9. Below it the label measures the pads' give and the table
# contact's reach, not the grasp. Measured 2026-11-28 (MuJoCo C, robotiq-2f85 at the
# default contact, 8 pick-points each): the 43 g block succeeds 3/8 at a 0.2 mm lift
# and 8/8 at 0.5 mm; the 123 g disc 0/8 at 0.5 mm and 8/8 at 1 mm (a sag of 0.05-0.1 mm
# decides them); this floor is five times that.
LIFT_TOLERANCE_MM = 0.5


@dataclasses.dataclass(frozen=True)
class GraspConfig:
    """Controller and phase settings of one simulated pick."""

    grip_force_n: float = setting(
        50.0,
        "N",
        "F_d, the desired pad force (within the gripper's force range)",
        lo=0,
        lo_open=True,
    )
    kp_mm_s_per_n: float = setting(
        2.0,
        "mm/s per N",
        "P gain: each finger's speed per newton of force error",
        lo=0,
        hi=1e4,
        lo_open=True,
    )
    # largest rate of closing of the opening; Robotiq 2F-85 range 20-150 mm/s
    closing_speed_mm_s: float = setting(
        100.0,
        "mm/s",
        "largest closing speed of the opening (within the gripper's range)",
        lo=0,
        hi=2000,
        lo_open=True,
    )
    opening_speed_mm_s: float = setting(
        10.0, "mm/s", "largest opening speed (backing off a force overshoot)", lo=0, hi=2000
    )
    control_period_s: float = setting(
        0.005,
        "s",
        "controller period (a whole multiple of solver.timestep_s)",
        lo=1e-4,
        hi=0.05,
    )
    reach_fraction: float = setting(
        0.95, "-", "F >= this fraction of F_d counts as the force reached", lo=0.5, hi=1.0
    )
    # ...once it has stayed between that and the drive's limit this long (the pads'
    # impact on a light part is a spike, not a grasp); 0 is the paper's literal rule
    reach_settle_s: float = setting(
        0.02, "s", "the force must stay reached this long before the lift", lo=0, hi=1
    )
    dwell_s: float = setting(0.0, "s", "wait between reaching F_d and lifting", lo=0, hi=10)
    settle_s: float = setting(
        0.02, "s", "the object settles on the table before closing", lo=0, hi=10
    )
    close_timeout_s: float = setting(
        1.5, "s", "longest close before 'force_not_reached'", lo=0, hi=60, lo_open=True
    )
    lift_height_mm: float = setting(
        100.0, "mm", "lift height (the paper's test: 10 cm)", lo=0, hi=2000, lo_open=True
    )
    lift_speed_mm_s: float = setting(
        200.0, "mm/s", "the arm's lift cruise speed", lo=0, hi=5000, lo_open=True
    )
    lift_accel_mm_s2: float = setting(
        2000.0,
        "mm/s^2",
        "the arm's lift acceleration (trapezoidal profile)",
        lo=0,
        hi=1e5,
        lo_open=True,
    )
    hold_s: float = setting(0.5, "s", "hold at the top of the lift", lo=0, hi=60)
    success_height_fraction: float = setting(
        0.9,
        "-",
        "success: the object lifted at least this fraction of the lift",
        lo=0,
        hi=1,
        lo_open=True,
    )
    max_rotation_deg: float = setting(
        45.0,
        "deg",
        "success: the object turned at most this much in the grip",
        lo=0,
        hi=180,
        lo_open=True,
    )
    pad_contact_fraction: float = setting(
        0.02, "-", "a pad touches above this fraction of F_d", lo=0, hi=0.5, lo_open=True
    )
    table_contact_fraction: float = setting(
        0.1,
        "-",
        "the object touches the table above this fraction of its weight",
        lo=0,
        hi=1,
        lo_open=True,
    )
    safety_factor: float = setting(
        1.1, "-", "S_f of eq. (1), the gripper safety margin in F_Gmin", lo=1.0
    )
    # |qvel| above this (m/s, rad/s) is a blow-up; a light block squeezed out of a
    # corner pinch legitimately spins at ~60 rad/s, a blow-up reaches 1e3+ or NaN
    divergence_speed: float = setting(
        200.0,
        "m/s or rad/s",
        "a joint speed above this counts as a blow-up ('diverged')",
        lo=0.1,
    )
    # where the pads grip (the paper: "picked at half the object depth"): "mid_band"
    # centres the pads on the object's mid-height, the fingertips no lower than
    # fingertip_clearance_mm above the table; "fingertip_mid" puts the fingertips at
    # half height (the paper's literal rule: the pads then cover the upper half only).
    # An object's own pick_height_mm (the CLI's --pick-height-mm) overrides both.
    grasp_height: str = setting(
        "mid_band",
        "-",
        "mid_band: pads centred on the object's mid-height; fingertip_mid: fingertips at "
        "half height (the paper's literal rule)",
        choices=("mid_band", "fingertip_mid"),
    )
    fingertip_clearance_mm: float = setting(
        2.0,
        "mm",
        "lowest fingertip height above the table (grasp_height mid_band)",
        lo=0,
        hi=100,
    )
    # the drive's force limit relative to F_d while the force loop runs: the real
    # gripper's current limit. The integrated speed command cannot wind the finger
    # servo up beyond it when the object slips or turns in the grasp.
    force_limit_fraction: float = setting(
        1.15,
        "-",
        "the drive's force limit while the force loop runs, as a fraction of F_d",
        lo=1.0,
        hi=3.0,
    )

    def __post_init__(self):
        o = "grasp"
        check_fields(self, o)
        self._check_lift_tolerance()

    def _check_lift_tolerance(self) -> None:
        """A lift whose success tolerance, (1 - success_height_fraction) x lift height, is
        below LIFT_TOLERANCE_MM labels the pads' give and the table contact's reach, not
        the grasp (a 0.001 mm lift fails every pick-point): refused, naming the lift
        that would do."""
        tolerance = (1.0 - self.success_height_fraction) * self.lift_height_mm
        if tolerance < LIFT_TOLERANCE_MM * (1 - 1e-9):  # 0.1 x 5 mm is 0.4999...  in floats
            need = LIFT_TOLERANCE_MM / (1.0 - self.success_height_fraction)
            raise ConfigError(
                f"grasp.lift_height_mm = {self.lift_height_mm:g} with success_height_fraction "
                f"= {self.success_height_fraction:g} leaves a lifted part {tolerance:.3g} mm "
                f"of sag before it counts as dropped, below {LIFT_TOLERANCE_MM:g} mm: a label "
                "would measure the pads' give and the table contact, not the grasp; allowed "
                f"lift_height_mm >= {need:.3g} at this fraction"
            )

    @property
    def duration_s(self) -> float:
        """Simulated time: every phase at its longest."""
        return self.settle_s + self.close_timeout_s + self.dwell_s + self.lift_s + self.hold_s

    @property
    def lift_s(self) -> float:
        """Duration of the trapezoidal (or triangular) lift."""
        v, a, h = self.lift_speed_mm_s, self.lift_accel_mm_s2, self.lift_height_mm
        return h / v + v / a if v * v / a < h else 2.0 * math.sqrt(h / a)

    def n_ticks(self) -> int:
        """Control periods simulated (one spare so the last transition is seen)."""
        return int(math.ceil(self.duration_s / self.control_period_s)) + 2

    def substeps(self, solver: SolverParams) -> int:
        """Physics steps per control period."""
        n = self.control_period_s / solver.timestep_s
        if abs(n - round(n)) > 1e-6 or round(n) < 1:
            raise ConfigError(
                f"grasp.control_period_s = {self.control_period_s:g} must be a whole multiple "
                f"of solver.timestep_s = {solver.timestep_s:g}"
            )
        return int(round(n))

    def fitted_to(
        self, gripper: GripperSpec, keep: Collection[str] = ()
    ) -> tuple[GraspConfig, str | None]:
        """The one rule fitting a procedure to a gripper: grip_force_n and
        closing_speed_mm_s moved to the nearest end of the gripper's range where they
        lie outside it, and a note saying so (None where nothing moved). keep: fields
        the user set, never moved (check_gripper refuses them out of range)."""
        ranges = {
            "grip_force_n": (gripper.force_min_n, gripper.force_max_n, "N", "grip force"),
            "closing_speed_mm_s": (
                gripper.speed_min_mm_s,
                gripper.speed_max_mm_s,
                "mm/s",
                "closing speed",
            ),
        }
        moved, notes = {}, []
        for name, (lo, hi, unit, what) in ranges.items():
            value = getattr(self, name)
            fitted = min(max(value, lo), hi)
            if name in keep or fitted == value:
                continue
            moved[name] = fitted
            default = "the default " if value == _DEFAULTS[name] else ""
            notes.append(
                f"{what}: {default}{value:g} {unit} is outside {gripper.name}'s "
                f"{lo:g}-{hi:g} {unit}: using {fitted:g} {unit} (set grasp.{name} to choose)"
            )
        if not moved:
            return self, None
        return dataclasses.replace(self, **moved), "; ".join(notes)

    def check_gripper(self, gripper: GripperSpec) -> None:
        """Settings the gripper cannot do are errors naming the field and the range."""
        if not gripper.force_min_n <= self.grip_force_n <= gripper.force_max_n:
            raise ConfigError(
                f"grasp.grip_force_n = {self.grip_force_n:g} is out of range for {gripper.name}: "
                f"allowed {gripper.force_min_n:g} <= grip_force_n <= {gripper.force_max_n:g}"
            )
        if not gripper.speed_min_mm_s <= self.closing_speed_mm_s <= gripper.speed_max_mm_s:
            raise ConfigError(
                f"grasp.closing_speed_mm_s = {self.closing_speed_mm_s:g} is out of range for "
                f"{gripper.name}: allowed {gripper.speed_min_mm_s:g} <= closing_speed_mm_s "
                f"<= {gripper.speed_max_mm_s:g}"
            )

    def params(self, obj: ObjectModel, gripper: GripperSpec) -> kt.GraspParams:
        """The kernels' parameters (float32 scalars, SI)."""
        f32 = np.float32
        return kt.GraspParams(
            grip_force_n=f32(self.grip_force_n),
            force_limit_fraction=f32(self.force_limit_fraction),
            force_max_n=f32(gripper.force_max_n),
            drive_stiffness_n_per_m=f32(gripper.drive_stiffness_n_per_mm * 1e3),
            kp=f32(self.kp_mm_s_per_n * 1e-3),
            v_close=f32(0.5 * self.closing_speed_mm_s * 1e-3),
            v_open=f32(0.5 * self.opening_speed_mm_s * 1e-3),
            reach_fraction=f32(self.reach_fraction),
            reach_settle_s=f32(self.reach_settle_s),
            dwell_s=f32(self.dwell_s),
            settle_s=f32(self.settle_s),
            close_timeout_s=f32(self.close_timeout_s),
            lift_height_m=f32(self.lift_height_mm * 1e-3),
            lift_speed_m_s=f32(self.lift_speed_mm_s * 1e-3),
            lift_accel_m_s2=f32(self.lift_accel_mm_s2 * 1e-3),
            hold_s=f32(self.hold_s),
            pad_contact_fraction=f32(self.pad_contact_fraction),
            table_contact_n=f32(self.table_contact_fraction * obj.mass_kg * G),
            success_height_fraction=f32(self.success_height_fraction),
            max_rotation_rad=f32(math.radians(self.max_rotation_deg)),
            divergence_speed=f32(self.divergence_speed),
            dt=f32(self.control_period_s),
        )


_DEFAULTS = {f.name: f.default for f in dataclasses.fields(GraspConfig)}


def fingertip_height_mm(obj: ObjectModel, gripper: GripperSpec, grasp: GraspConfig) -> float:
    """Height of the fingertips (the pads' lower edges) above the table at the grasp, mm.

    The object's own pick_height_mm wins; otherwise grasp.grasp_height's rule. With
    "mid_band" the pad centre is at half the object's height, except where the pad is
    taller than that allows: then the fingertips stop fingertip_clearance_mm (at most a
    quarter of the object's height) above the table, and the pads still cover the
    mid-height band (a lying cylinder's equator).
    """
    if obj.pick_height_mm is not None:
        return float(obj.pick_height_mm)
    half = 0.5 * obj.height_mm
    if grasp.grasp_height == "fingertip_mid":
        return half
    clearance = min(grasp.fingertip_clearance_mm, clearance_cap_mm(obj))
    return max(clearance, half - 0.5 * gripper.pad_height_mm)


def clearance_cap_mm(obj: ObjectModel) -> float:
    """The most the fingertips' clearance above the table may be, mm: a quarter of the
    object's height, so that the pads always cover a thin part's mid-height (a 3 mm
    plate is gripped from 0.75 mm up)."""
    return 0.25 * obj.height_mm


def check_clearance(obj: ObjectModel, grasp: GraspConfig) -> None:
    """Refuse a fingertip clearance that :func:`fingertip_height_mm` would lower without
    a word: one above a quarter of the object's height (the rule's cap) where the rule
    applies (grasp_height mid_band, no pick height of the object's own). The default
    is left to the rule, which lowers it for thin parts by design (docs/physics.md);
    a value the user chose is refused, naming what is allowed."""
    value = grasp.fingertip_clearance_mm
    if obj.pick_height_mm is not None or grasp.grasp_height != "mid_band":
        return
    cap = clearance_cap_mm(obj)
    if value > cap and value != _DEFAULTS["fingertip_clearance_mm"]:
        raise ConfigError(
            f"grasp.fingertip_clearance_mm = {value:g} is above a quarter of object "
            f"{obj.name!r}'s height ({obj.height_mm:g} mm): allowed at most {cap:g} mm, so "
            "that the pads still cover its mid-height; lower it, or give the fingertips' "
            "height itself (--pick-height-mm)"
        )


def pad_band_mm(obj: ObjectModel, gripper: GripperSpec, grasp: GraspConfig):
    """(bottom, top) heights of the pads above the table at the grasp, mm."""
    z = fingertip_height_mm(obj, gripper, grasp)
    return z, z + gripper.pad_height_mm


def min_grasp_force_n(obj: ObjectModel, pad_friction: float, safety_factor: float) -> float:
    """Eq. (1) of the paper: F_Gmin = m g S_f / (2 mu_s), N."""
    return obj.mass_kg * G * safety_factor / (2.0 * pad_friction)


def broadcast_params(p: kt.GraspParams, n: int, **per_pick) -> kt.GraspParams:
    """(N,) arrays of every parameter; per_pick names fields given per pick-point."""
    unknown = set(per_pick) - set(kt.GraspParams._fields)
    if unknown:
        raise ConfigError(f"unknown grasp parameter(s): {', '.join(sorted(unknown))}")
    fields = {}
    for name in kt.GraspParams._fields:
        value = per_pick.get(name, getattr(p, name))
        fields[name] = np.broadcast_to(np.asarray(value, np.float32), (n,)).copy()
    return kt.GraspParams(**fields)
