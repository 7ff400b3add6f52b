"""The grasp kernels' data without JAX: parameters, states, phases, outcomes, trace fields."""

from __future__ import annotations

import enum
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    import jax

SETTLE, CLOSE, DWELL, LIFT, HOLD, DONE = range(6)
PHASES = ("settle", "close", "dwell", "lift", "hold", "done")


class Outcome(enum.IntEnum):
    """How a pick ended: its code (stable: results and benchmarks store it), its
    ``label`` (the results table's ``failure`` column) and what it ``means``.

    A new reason: a member here and its condition in ``kernels.grasp.finalize``
    (docs/architecture.md).
    """

    def __new__(cls, code: int, means: str):
        member = int.__new__(cls, code)
        member._value_ = code
        member.means = means
        return member

    OK = 0, "held: at the hold's end lifted to the success height, off the table, upright"
    NO_CONTACT = 1, "the pads never touched the part"
    FORCE_NOT_REACHED = 2, "the pads touched the part but never reached F_d"
    SLIPPED_IN_LIFT = 3, "the part lagged below the success height at the lift's end"
    DROPPED_IN_HOLD = 4, "the part fell below the success height during the hold"
    ROTATED = 5, "the part turned more than max_rotation_deg"
    DIVERGED = 6, "the simulation blew up (NaN/Inf, a MuJoCo reset, an absurd speed): unscored"

    @property
    def label(self) -> str:
        """The results table's word for it ("success" for OK)."""
        return "success" if self is Outcome.OK else self.name.lower()


FAILURES = tuple(o.label for o in Outcome)  # labels by code
SUCCESS = Outcome.OK.label
# the label of OK before it read "success" (results written by mjx-pick <= 0.1.0)
OLD_SUCCESS_LABEL = "none"


class GraspParams(NamedTuple):
    """Per-pick controller and phase settings, SI units (each a traced scalar)."""

    grip_force_n: jax.Array  # F_d, desired pad force
    force_limit_fraction: jax.Array  # drive force limit / F_d while the force loop runs
    force_max_n: jax.Array  # the gripper's largest force
    drive_stiffness_n_per_m: jax.Array  # finger servo stiffness (force per m of lag)
    kp: jax.Array  # (m/s)/N, finger speed per newton of force error
    v_close: jax.Array  # m/s, each finger's largest closing speed
    v_open: jax.Array  # m/s, each finger's largest opening speed
    reach_fraction: jax.Array  # F >= reach_fraction * F_d counts as reached
    reach_settle_s: jax.Array  # ...once F has stayed in [reach, limit] this long
    dwell_s: jax.Array
    settle_s: jax.Array
    close_timeout_s: jax.Array
    lift_height_m: jax.Array
    lift_speed_m_s: jax.Array
    lift_accel_m_s2: jax.Array  # trapezoidal lift: accelerate, cruise, decelerate
    hold_s: jax.Array
    # a pad touches when its force exceeds this fraction of F_d (a fraction, so that a
    # per-pick F_d override moves the threshold with it)
    pad_contact_fraction: jax.Array
    table_contact_n: jax.Array  # the object touches the table when its force exceeds this
    success_height_fraction: jax.Array
    max_rotation_rad: jax.Array
    divergence_speed: jax.Array  # |qvel| above this (m/s or rad/s) is a blow-up
    dt: jax.Array  # control period, s
    # the gripper's closing axis in world axes (a unit vector; its left pad moves along
    # +axis): the pads' forces are measured along it. (1, 0, 0): a vertical grasp
    closing_axis_x: jax.Array = 1.0
    closing_axis_y: jax.Array = 0.0
    closing_axis_z: jax.Array = 0.0


class ControlState(NamedTuple):
    phase: jax.Array  # int32
    t_phase: jax.Array  # s in the current phase
    finger_target: jax.Array  # m, each finger's closing-travel target
    lift_target: jax.Array  # m, gripper lift target
    lift_velocity: jax.Array  # m/s, of the lift target
    t_steady: jax.Array  # s the force has stayed between reach and limit while closing
    lift_start: jax.Array  # m, the gripper's starting lift (height compensation)


class Measurement(NamedTuple):
    """What the controller and metrics see at a control tick."""

    force_left: jax.Array  # N, normal force on the left pad (its x component)
    force_right: jax.Array  # N
    force_table: jax.Array  # N, vertical table force on the object
    finger_left: jax.Array  # m, the left finger's closing travel
    finger_right: jax.Array  # m
    object_pos: jax.Array  # (3,) m, object frame origin
    object_quat: jax.Array  # (4,) w, x, y, z
    lift: jax.Array  # m, gripper lift joint position
    speed_max: jax.Array  # largest |qvel|
    finite: jax.Array  # bool, state is finite
    # N per m of target lead, the drive's stiffness at the pads at this travel (an MJCF
    # linkage's lever changes along its stroke); None: GraspParams' constant
    drive_stiffness_n_per_m: jax.Array | None = None


class Accumulators(NamedTuple):
    contact_seen: jax.Array  # bool
    reached: jax.Array  # bool, F_d reached
    t_reached: jax.Array  # s since start when reached
    held: jax.Array  # bool, grip held uninterrupted since reaching F_d
    held_time: jax.Array  # s
    off_table_time: jax.Array  # s in the grasp window without table contact
    phi_max: jax.Array  # rad, largest rotation from the initial orientation
    yaw_max: jax.Array  # rad, largest |yaw change| (about the vertical)
    tilt_max: jax.Array  # rad, largest tilt of the object's vertical axis
    force_left_max: jax.Array
    force_right_max: jax.Array
    lift_after_lift: jax.Array  # m, object lift when the LIFT phase ended
    table_after_lift: jax.Array  # bool, touching the table then
    slip_max: jax.Array  # m, largest gripper lift minus object lift in the window
    lift_final: jax.Array  # m, object lift at the end of the hold
    table_final: jax.Array  # bool
    rot_final: jax.Array  # rad
    finished: jax.Array  # bool, the hold ended (success is only possible then)
    diverged: jax.Array  # bool
    t: jax.Array  # s since start
    # chatter: a pad's force falling below the contact threshold and coming back
    # while the part is held (the grasp window); per pad, whether it touched at the
    # last tick and whether it has let go since it last touched
    touch_left: jax.Array  # bool
    touch_right: jax.Array  # bool
    lost_left: jax.Array  # bool
    lost_right: jax.Array  # bool
    chatter: jax.Array  # count of returns


class DriveMap(NamedTuple):
    """How an MJCF gripper's joints and actuator relate to its pads' closing travel.

    Static under jit (tuples of floats, hashable): tables sampled along the stroke by a
    quasi-static close of the MuJoCo C model (``mjx_pick.core.mjcf_gripper``), each ascending
    in its first column, interpolated linearly. Travel is each pad's closing distance
    from fully open, m, in the free (parallel) mode of the linkage.
    """

    q_left: tuple[float, ...]  # (K,) left finger joint position (rad or m)
    travel_left: tuple[float, ...]  # (K,) left pad travel there, m
    q_right: tuple[float, ...]  # (K,) right finger joint position
    travel_right: tuple[float, ...]  # (K,) m
    travel: tuple[float, ...]  # (K,) mean pad travel, m
    length: tuple[float, ...]  # (K,) actuator length there (tendon or joint units)
    stiffness_n_per_m: tuple[float, ...]  # (K,) pad force per m of travel lead
    ctrl_per_length: float  # ctrl = ctrl_at_zero_length + ctrl_per_length * length
    ctrl_at_zero_length: float


class Addresses(NamedTuple):
    """Where the kernels read and write in MuJoCo's arrays (ints: static under jit).

    finger_*_qpos: the finger's slide joint (parallel jaw) or the joint whose angle
    ``drive`` maps to the pad's travel (MJCF gripper); finger_*_body: the body holding
    the pad; finger_*_actuator: the same actuator twice when one drives both fingers.
    """

    object_qpos: int
    lift_qpos: int
    finger_left_qpos: int
    finger_right_qpos: int
    object_body: int
    finger_left_body: int
    finger_right_body: int
    lift_actuator: int
    finger_left_actuator: int
    finger_right_actuator: int
    nu: int
    drive: DriveMap | None = None  # None: the joints' coordinates are the travel


# one row per control tick of a recorded pick, SI units, in tick()'s order; with the
# object's quaternion, a row holds every joint of a parallel-jaw scene, so a trace can be
# replayed (rendered) without simulating again. finger_*_m is each pad's closing travel
# (for an MJCF gripper, through its DriveMap)
TRACE_FIELDS = (
    "t_s",
    "force_left_n",
    "force_right_n",
    "force_table_n",
    "object_x_m",
    "object_y_m",
    "object_z_m",
    "object_yaw_rad",
    "object_qw",
    "object_qx",
    "object_qy",
    "object_qz",
    "finger_left_m",
    "finger_right_m",
    "lift_m",
    "phase",
)


# a pick's results (``kernels.grasp.finalize``'s keys, in its order); the flags and counts
# among them, the rest float32
RESULT_FIELDS = (
    "success",
    "failure",
    "diverged",
    "score",
    "t_grasp",
    "phi_max_deg",
    "t_grasp_nc",
    "yaw_max_deg",
    "tilt_max_deg",
    "t_reached_s",
    "max_force_left_n",
    "max_force_right_n",
    "lift_height_mm",
    "slip_mm",
    "chatter",
    "rotation_final_deg",
    "label_margin",
)
RESULT_FLAGS = ("success", "diverged")
RESULT_COUNTS = ("failure", "chatter")
