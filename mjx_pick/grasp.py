"""The simulated pick procedure: force-controlled close, lift, hold (user settings).

:class:`GraspConfig` holds the user-facing settings (units in the names); ``params``
turns them into the kernels' per-pick SI arrays (``mjx_pick.kernels.grasp``), which
both backends share. Defaults follow the paper: F_d = 50 N (its UR5e test), a 5 ms
control period (its Simulink rate), lifting as soon as F_d is reached, a 100 mm lift.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mjx_pick.config import ConfigError, check_choice, check_range
from mjx_pick.gripper import GripperSpec
from mjx_pick.kernels import grasp as gk
from mjx_pick.objects import ObjectModel
from mjx_pick.physics import SolverParams

G = 9.81


@dataclasses.dataclass(frozen=True)
class GraspConfig:
    """Controller and phase settings of one simulated pick."""

    grip_force_n: float = 50.0  # F_d, the desired pad force
    kp_mm_s_per_n: float = 2.0  # P gain: each finger's speed (mm/s) per N of force error
    # largest rate of closing of the opening; Robotiq 2F-85 range 20-150 mm/s
    closing_speed_mm_s: float = 100.0
    opening_speed_mm_s: float = 10.0  # largest rate of opening (force overshoot)
    control_period_s: float = 0.005  # the paper's Simulink sample time
    reach_fraction: float = 0.95  # F >= 0.95 F_d counts as "force reached"...
    # ...once it has stayed between that and the drive's limit this long (the pads'
    # impact on a light part is a spike, not a grasp); 0 is the paper's literal rule
    reach_settle_s: float = 0.02
    dwell_s: float = 0.0  # wait between reaching F_d and lifting (paper: none)
    settle_s: float = 0.02  # the object settles on the table before closing
    close_timeout_s: float = 1.5  # a symmetric gripper may travel its half stroke
    lift_height_mm: float = 100.0  # the paper's test lifted 10 cm
    lift_speed_mm_s: float = 200.0
    lift_accel_mm_s2: float = 2000.0  # the arm's acceleration (trapezoidal profile)
    hold_s: float = 0.5
    success_height_fraction: float = 0.9  # success: object lifted >= 90 % of the lift
    max_rotation_deg: float = 45.0  # ...and turned at most this much in the grip
    pad_contact_fraction: float = 0.02  # a pad touches above this fraction of F_d
    table_contact_fraction: float = 0.1  # table contact above this fraction of m g
    safety_factor: float = 1.1  # S_f of eq. (1), the paper's "gripper safety margin"
    # |qvel| above this (m/s, rad/s) is a blow-up; a light block squeezed out of a
    # corner pinch legitimately spins at ~60 rad/s, a blow-up reaches 1e3+ or NaN
    divergence_speed: float = 200.0
    # where the pads grip (the paper: "picked at half the object depth"): "mid_band"
    # centres the pads on the object's mid-height, the fingertips no lower than
    # fingertip_clearance_mm above the table; "fingertip_mid" puts the fingertips at
    # half height (the paper's literal rule: the pads then cover the upper half only).
    # An object's own pick_height_mm (the CLI's --pick-height-mm) overrides both.
    grasp_height: str = "mid_band"
    fingertip_clearance_mm: float = 2.0
    # the drive's force limit relative to F_d while the force loop runs: the real
    # gripper's current limit. The integrated speed command cannot wind the finger
    # servo up beyond it when the object slips or turns in the grasp.
    force_limit_fraction: float = 1.15

    def __post_init__(self):
        o = "grasp"
        check_range(o, "grip_force_n", self.grip_force_n, 0, lo_open=True)
        check_range(o, "kp_mm_s_per_n", self.kp_mm_s_per_n, 0, 1e4, lo_open=True)
        check_range(o, "closing_speed_mm_s", self.closing_speed_mm_s, 0, 2000, lo_open=True)
        check_range(o, "opening_speed_mm_s", self.opening_speed_mm_s, 0, 2000)
        check_range(o, "control_period_s", self.control_period_s, 1e-4, 0.05)
        check_range(o, "reach_fraction", self.reach_fraction, 0.5, 1.0)
        check_range(o, "reach_settle_s", self.reach_settle_s, 0, 1)
        check_range(o, "dwell_s", self.dwell_s, 0, 10)
        check_range(o, "settle_s", self.settle_s, 0, 10)
        check_range(o, "close_timeout_s", self.close_timeout_s, 0, 60, lo_open=True)
        check_range(o, "lift_height_mm", self.lift_height_mm, 0, 2000, lo_open=True)
        check_range(o, "lift_speed_mm_s", self.lift_speed_mm_s, 0, 5000, lo_open=True)
        check_range(o, "lift_accel_mm_s2", self.lift_accel_mm_s2, 0, 1e5, lo_open=True)
        check_range(o, "hold_s", self.hold_s, 0, 60)
        check_range(o, "success_height_fraction", self.success_height_fraction, 0, 1, lo_open=True)
        check_range(o, "max_rotation_deg", self.max_rotation_deg, 0, 180, lo_open=True)
        check_range(o, "pad_contact_fraction", self.pad_contact_fraction, 0, 0.5, lo_open=True)
        check_range(o, "table_contact_fraction", self.table_contact_fraction, 0, 1, lo_open=True)
        check_range(o, "safety_factor", self.safety_factor, 1.0)
        check_range(o, "divergence_speed", self.divergence_speed, 0.1, lo_open=False)
        check_choice(o, "grasp_height", self.grasp_height, ("mid_band", "fingertip_mid"))
        check_range(o, "fingertip_clearance_mm", self.fingertip_clearance_mm, 0, 100)
        check_range(o, "force_limit_fraction", self.force_limit_fraction, 1.0, 3.0)

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

    def params(self, obj: ObjectModel, gripper: GripperSpec) -> gk.GraspParams:
        """The kernels' parameters (float32 scalars, SI)."""
        f32 = np.float32
        return gk.GraspParams(
            force_n=f32(self.grip_force_n),
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
    # the clearance never exceeds a quarter of the height, so that the pads always
    # cover a thin part's mid-height (a 3 mm plate is gripped from 0.75 mm up)
    clearance = min(grasp.fingertip_clearance_mm, 0.25 * obj.height_mm)
    return max(clearance, half - 0.5 * gripper.pad_height_mm)


def pad_band_mm(obj: ObjectModel, gripper: GripperSpec, grasp: GraspConfig):
    """(bottom, top) heights of the pads above the table at the grasp, mm."""
    z = fingertip_height_mm(obj, gripper, grasp)
    return z, z + gripper.pad_height_mm


def min_grasp_force_n(obj: ObjectModel, pad_friction: float, safety_factor: float) -> float:
    """Eq. (1) of the paper: F_Gmin = m g S_f / (2 mu_s), N."""
    return obj.mass_kg * G * safety_factor / (2.0 * pad_friction)


def broadcast_params(p: gk.GraspParams, n: int, **per_pick) -> gk.GraspParams:
    """(N,) arrays of every parameter; per_pick names fields given per pick-point."""
    unknown = set(per_pick) - set(gk.GraspParams._fields)
    if unknown:
        raise ConfigError(f"unknown grasp parameter(s): {', '.join(sorted(unknown))}")
    fields = {}
    for name in gk.GraspParams._fields:
        value = per_pick.get(name, getattr(p, name))
        fields[name] = np.broadcast_to(np.asarray(value, np.float32), (n,)).copy()
    return gk.GraspParams(**fields)
