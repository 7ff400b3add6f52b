"""One pick-point's controller, phase machine and metrics as Warp functions.

The same arithmetic as :mod:`mjx_pick.kernels.grasp` (the reference: every function
here mirrors the one of the same name there, in float32, and a test compares them on
random states), written for the MuJoCo Warp backend, whose whole rollout runs as Warp
kernels on the GPU. The structs mirror the NamedTuples field for field, so that numpy
converts between them (``numpy_dtype()`` of each struct).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from mjx_pick.kernels import types as kt

SETTLE = wp.constant(kt.SETTLE)
CLOSE = wp.constant(kt.CLOSE)
DWELL = wp.constant(kt.DWELL)
LIFT = wp.constant(kt.LIFT)
HOLD = wp.constant(kt.HOLD)
DONE = wp.constant(kt.DONE)
OK = wp.constant(int(kt.Outcome.OK))
NO_CONTACT = wp.constant(int(kt.Outcome.NO_CONTACT))
FORCE_NOT_REACHED = wp.constant(int(kt.Outcome.FORCE_NOT_REACHED))
SLIPPED_IN_LIFT = wp.constant(int(kt.Outcome.SLIPPED_IN_LIFT))
DROPPED_IN_HOLD = wp.constant(int(kt.Outcome.DROPPED_IN_HOLD))
ROTATED = wp.constant(int(kt.Outcome.ROTATED))
DIVERGED = wp.constant(int(kt.Outcome.DIVERGED))
NTRACE = wp.constant(len(kt.TRACE_FIELDS))
# MuJoCo Warp's pair_friction and pair_solimp rows
vec5 = wp.types.vector(length=5, dtype=wp.float32)


def _mirror(name: str, fields: tuple[str, ...], types: dict | None = None):
    """A Warp struct with a NamedTuple's fields, in its order (float unless types says
    otherwise), so that numpy converts between the two field by field."""
    types = types or {}
    cls = type(name, (), {"__annotations__": {f: types.get(f, float) for f in fields}})
    cls.__doc__ = f"kernels.types' {name} fields, for Warp kernels."
    cls.__module__ = __name__
    return wp.struct(cls)


_ACC_BOOLS = (
    "contact_seen",
    "reached",
    "held",
    "table_after_lift",
    "table_final",
    "finished",
    "diverged",
    "touch_left",
    "touch_right",
    "lost_left",
    "lost_right",
)
Params = _mirror("Params", kt.GraspParams._fields)
Control = _mirror("Control", kt.ControlState._fields, {"phase": int})
Acc = _mirror("Acc", kt.Accumulators._fields, dict.fromkeys(_ACC_BOOLS, wp.bool))


@wp.struct
class Measurement:
    """kt.Measurement (drive_stiffness_n_per_m < 0: GraspParams' constant)."""

    force_left: float
    force_right: float
    force_table: float
    finger_left: float
    finger_right: float
    object_pos: wp.vec3
    object_quat: wp.vec4  # w, x, y, z
    lift: float
    speed_max: float
    finite: wp.bool
    drive_stiffness_n_per_m: float


Result = _mirror(
    "Result",
    kt.RESULT_FIELDS,
    {**dict.fromkeys(kt.RESULT_FLAGS, wp.bool), **dict.fromkeys(kt.RESULT_COUNTS, int)},
)


# kt.Addresses' integer fields (nu: the ctrl row's length), and whether finger travel goes
# through a DriveMap (its tables in Drive)
Addresses = _mirror(
    "Addresses",
    (*(f for f in kt.Addresses._fields if f not in ("nu", "drive")), "has_drive"),
    {**dict.fromkeys(kt.Addresses._fields, int), "has_drive": wp.bool},
)


@wp.struct
class Drive:
    """kt.DriveMap's tables, (K,) each (empty without a drive)."""

    q_left: wp.array(dtype=float)
    travel_left: wp.array(dtype=float)
    q_right: wp.array(dtype=float)
    travel_right: wp.array(dtype=float)
    travel: wp.array(dtype=float)
    length: wp.array(dtype=float)
    stiffness_n_per_m: wp.array(dtype=float)
    ctrl_per_length: float
    ctrl_at_zero_length: float


def addresses(ad: kt.Addresses) -> Addresses:
    """The Warp struct of kt.Addresses."""
    out = Addresses()
    for name in Addresses.vars:
        if name != "has_drive":
            setattr(out, name, int(getattr(ad, name)))
    out.has_drive = ad.drive is not None
    return out


def drive(ad: kt.Addresses, device) -> Drive:
    """The Warp struct of a DriveMap's tables on device (empty tables without one)."""
    out = Drive()
    dm = ad.drive
    for name in ("q_left", "travel_left", "q_right", "travel_right", "travel", "length"):
        values = getattr(dm, name) if dm is not None else ()
        setattr(out, name, wp.array(np.asarray(values, np.float32), dtype=float, device=device))
    values = dm.stiffness_n_per_m if dm is not None else ()
    out.stiffness_n_per_m = wp.array(np.asarray(values, np.float32), dtype=float, device=device)
    out.ctrl_per_length = float(dm.ctrl_per_length) if dm is not None else 0.0
    out.ctrl_at_zero_length = float(dm.ctrl_at_zero_length) if dm is not None else 0.0
    return out


def to_struct_array(values: tuple, struct, device) -> wp.array:
    """(N,) Warp array of struct from a NamedTuple of (N,) arrays with the same fields."""
    dtype = np.dtype(struct.numpy_dtype())
    n = len(np.asarray(values[0]).reshape(-1))
    host = np.zeros(n, dtype)
    for name in dtype.names:
        host[name] = np.asarray(getattr(values, name)).reshape(-1)
    return wp.array(host, dtype=struct, device=device)


def from_struct_array(arr: wp.array) -> dict:
    """{field: (N,) numpy} of a Warp struct array."""
    host = arr.numpy()
    return {name: np.array(host[name]) for name in host.dtype.names}


# ----------------------------------------------------------------------------- helpers
@wp.func
def interp(x: float, xs: wp.array(dtype=float), ys: wp.array(dtype=float)):
    """Piecewise-linear lookup in ascending xs, clamped at the ends (jnp.interp)."""
    n = xs.shape[0]
    if x <= xs[0]:
        return ys[0]
    if x >= xs[n - 1]:
        return ys[n - 1]
    lo = int(0)  # noqa: UP018 (Warp: a loop-carried local needs its type)
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    t = (x - xs[lo]) / (xs[hi] - xs[lo])
    return ys[lo] + t * (ys[hi] - ys[lo])


@wp.func
def quat_angle(q: wp.vec4, q0: wp.vec4):
    c = wp.abs(wp.dot(q, q0))
    return 2.0 * wp.acos(wp.clamp(c, 0.0, 1.0))


@wp.func
def yaw(q: wp.vec4):
    w = q[0]
    x = q[1]
    y = q[2]
    z = q[3]
    return wp.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


@wp.func
def tilt(q: wp.vec4):
    x = q[1]
    y = q[2]
    r22 = 1.0 - 2.0 * (x * x + y * y)
    return wp.acos(wp.clamp(r22, -1.0, 1.0))


@wp.func
def lift_duration(p: Params):
    v = p.lift_speed_m_s
    a = p.lift_accel_m_s2
    h = p.lift_height_m
    if v * v / a < h:
        return h / v + v / a
    return 2.0 * wp.sqrt(h / a)


# ------------------------------------------------------------------------ the kernels
@wp.func
def finger_travel_left(ad: Addresses, dr: Drive, q: float):
    if ad.has_drive:
        return interp(q, dr.q_left, dr.travel_left)
    return q


@wp.func
def finger_travel_right(ad: Addresses, dr: Drive, q: float):
    if ad.has_drive:
        return interp(q, dr.q_right, dr.travel_right)
    return q


@wp.func
def measure(
    p: Params,
    ad: Addresses,
    dr: Drive,
    qpos: wp.array(dtype=float),
    qvel: wp.array(dtype=float),
    cfrc_ext: wp.array(dtype=wp.spatial_vector),
):
    """kernels.grasp.measure for one simulation: qpos (nq,), qvel (nv,), cfrc_ext (nbody,) rows
    of (torque, force) in world axes."""
    f_obj = cfrc_ext[ad.object_body]
    f_left = cfrc_ext[ad.finger_left_body]
    f_right = cfrc_ext[ad.finger_right_body]
    o = ad.object_qpos
    m = Measurement()
    # along the closing axis (kernels.grasp.measure)
    ax, ay, az = p.closing_axis_x, p.closing_axis_y, p.closing_axis_z
    m.force_left = -(f_left[3] * ax + f_left[4] * ay + f_left[5] * az)
    m.force_right = f_right[3] * ax + f_right[4] * ay + f_right[5] * az
    m.force_table = f_obj[5] + f_left[5] + f_right[5]
    m.finger_left = finger_travel_left(ad, dr, qpos[ad.finger_left_qpos])
    m.finger_right = finger_travel_right(ad, dr, qpos[ad.finger_right_qpos])
    m.object_pos = wp.vec3(qpos[o], qpos[o + 1], qpos[o + 2])
    m.object_quat = wp.vec4(qpos[o + 3], qpos[o + 4], qpos[o + 5], qpos[o + 6])
    m.lift = qpos[ad.lift_qpos]
    speed = float(0.0)  # noqa: UP018 (Warp: a loop-carried local needs its type)
    finite = bool(True)  # noqa: UP018
    for i in range(qvel.shape[0]):
        speed = wp.max(speed, wp.abs(qvel[i]))
        finite = finite and wp.isfinite(qvel[i])
    for i in range(qpos.shape[0]):
        finite = finite and wp.isfinite(qpos[i])
    m.speed_max = speed
    m.finite = finite
    m.drive_stiffness_n_per_m = -1.0
    if ad.has_drive:
        slower = wp.min(m.finger_left, m.finger_right)
        m.drive_stiffness_n_per_m = interp(slower, dr.travel, dr.stiffness_n_per_m)
    return m


@wp.func
def control_step(p: Params, s: Control, m: Measurement):
    """kernels.grasp.control_step: the next Control (its targets are this period's commands)."""
    force = 0.5 * (m.force_left + m.force_right)
    t = s.t_phase + p.dt
    ph = s.phase
    f_lim = wp.min(p.force_limit_fraction * p.grip_force_n, p.force_max_n)
    upper = wp.max(f_lim, (2.0 - p.reach_fraction) * p.grip_force_n)
    steady = (ph == CLOSE) and (force >= p.reach_fraction * p.grip_force_n) and (force <= upper)
    t_steady = 0.0
    if steady:
        t_steady = s.t_steady + p.dt
    reached = steady and (t_steady >= p.reach_settle_s - 1.0e-6)
    nxt = ph
    if ph == SETTLE and t >= p.settle_s:
        nxt = CLOSE
    elif ph == CLOSE and reached and p.dwell_s > 0.0:
        nxt = DWELL
    elif ph == CLOSE and reached:
        nxt = LIFT
    elif ph == CLOSE and t >= p.close_timeout_s:
        nxt = DONE
    elif ph == DWELL and t >= p.dwell_s:
        nxt = LIFT
    elif ph == LIFT and s.lift_target >= s.lift_start + p.lift_height_m:
        nxt = HOLD
    elif ph == HOLD and t >= p.hold_s:
        nxt = DONE
    t_next = t
    if nxt != ph:
        t_next = 0.0
    active = (
        (ph != SETTLE)
        and not (ph == CLOSE and nxt == DONE)
        and not (ph == DONE and s.lift_target <= s.lift_start)
    )
    v = wp.clamp(p.kp * (p.grip_force_n - force), -p.v_open, p.v_close)
    touching = wp.max(m.force_left, m.force_right) > p.pad_contact_fraction * p.grip_force_n
    if not touching:
        v = p.v_close
    finger_target = s.finger_target
    if active:
        finger_target = s.finger_target + v * p.dt
    engaged = touching or ph == DWELL or ph == LIFT or ph == HOLD
    k_drive = p.drive_stiffness_n_per_m
    if m.drive_stiffness_n_per_m >= 0.0:
        k_drive = m.drive_stiffness_n_per_m
    capped = wp.min(m.finger_left, m.finger_right) + f_lim / k_drive
    if engaged:
        finger_target = wp.min(finger_target, capped)
    lifting = nxt == LIFT
    top = s.lift_start + p.lift_height_m
    remaining = wp.max(top - s.lift_target, 0.0)
    v_stop = wp.sqrt(2.0 * p.lift_accel_m_s2 * remaining)
    v_lift = wp.min(s.lift_velocity + p.lift_accel_m_s2 * p.dt, p.lift_speed_m_s)
    if lifting:
        v_lift = wp.clamp(v_lift, 0.0, v_stop)
    else:
        v_lift = 0.0
    lift_target = s.lift_target + v_lift * p.dt
    if top - lift_target < 1.0e-6:
        lift_target = top
    if lifting:
        lift_target = wp.min(lift_target, top)
    else:
        lift_target = s.lift_target
    out = Control()
    out.phase = nxt
    out.t_phase = t_next
    out.finger_target = finger_target
    out.lift_target = lift_target
    out.lift_velocity = v_lift
    out.t_steady = t_steady
    out.lift_start = s.lift_start
    return out


@wp.func
def accumulate(
    p: Params, a: Acc, s: Control, s_next: Control, m: Measurement, pos0: wp.vec3, quat0: wp.vec4
):
    """kernels.grasp.accumulate: one tick's measurement folded into the metrics."""
    running = s.phase != DONE
    bad = (not m.finite or m.speed_max > p.divergence_speed) and running
    diverged = a.diverged or bad
    live = (not diverged) and running
    fl = 0.0
    fr = 0.0
    ft = 0.0
    quat = quat0
    pos = pos0
    if live:
        fl = m.force_left
        fr = m.force_right
        ft = m.force_table
        quat = m.object_quat
        pos = m.object_pos
    pad_contact_n = p.pad_contact_fraction * p.grip_force_n
    contact = wp.max(fl, fr) > pad_contact_n
    gripping = wp.min(fl, fr) > pad_contact_n
    on_table = ft > p.table_contact_n
    just_reached = (s.phase == CLOSE) and (s_next.phase == LIFT or s_next.phase == DWELL)
    reached = a.reached or (live and just_reached)
    in_window = live and a.reached and (s.phase != DONE)
    held = a.held and ((not in_window) or gripping)
    if live and just_reached:
        held = True
    rot = quat_angle(quat, quat0)
    d = yaw(quat) - yaw(quat0)
    dyaw = wp.abs(wp.atan2(wp.sin(d), wp.cos(d)))
    obj_lift = pos[2] - pos0[2]
    touch_l = fl > pad_contact_n
    touch_r = fr > pad_contact_n
    back_l = in_window and a.lost_left and touch_l
    back_r = in_window and a.lost_right and touch_r
    lost_l = False
    lost_r = False
    if in_window:
        lost_l = (a.lost_left or (a.touch_left and not touch_l)) and not touch_l
        lost_r = (a.lost_right or (a.touch_right and not touch_r)) and not touch_r
    lift_end = (s.phase == LIFT) and (s_next.phase == HOLD) and live
    hold_end = (s.phase == HOLD) and (s_next.phase == DONE) and live
    out = Acc()
    out.contact_seen = a.contact_seen or (live and contact)
    out.reached = reached
    out.t_reached = a.t_reached
    if live and just_reached:
        out.t_reached = a.t + p.dt
    out.held = held
    out.held_time = a.held_time
    if in_window and held and gripping:
        out.held_time = a.held_time + p.dt
    out.off_table_time = a.off_table_time
    if in_window and not on_table:
        out.off_table_time = a.off_table_time + p.dt
    rot_live = 0.0
    dyaw_live = 0.0
    tilt_live = 0.0
    if live:
        rot_live = rot
        dyaw_live = dyaw
        tilt_live = tilt(quat)
    out.phi_max = wp.max(a.phi_max, rot_live)
    out.yaw_max = wp.max(a.yaw_max, dyaw_live)
    out.tilt_max = wp.max(a.tilt_max, tilt_live)
    out.force_left_max = wp.max(a.force_left_max, fl)
    out.force_right_max = wp.max(a.force_right_max, fr)
    out.lift_after_lift = a.lift_after_lift
    out.table_after_lift = a.table_after_lift
    if lift_end:
        out.lift_after_lift = obj_lift
        out.table_after_lift = on_table
    slip = 0.0
    if in_window:
        slip = m.lift - s.lift_start - obj_lift
    out.slip_max = wp.max(a.slip_max, slip)
    out.lift_final = a.lift_final
    out.table_final = a.table_final
    out.rot_final = a.rot_final
    if hold_end:
        out.lift_final = obj_lift
        out.table_final = on_table
        out.rot_final = rot
    out.finished = a.finished or hold_end
    out.diverged = diverged
    out.t = a.t + p.dt
    out.touch_left = in_window and touch_l
    out.touch_right = in_window and touch_r
    out.lost_left = lost_l
    out.lost_right = lost_r
    chatter = a.chatter
    if back_l:
        chatter = chatter + 1.0
    if back_r:
        chatter = chatter + 1.0
    out.chatter = chatter
    return out


@wp.func
def finalize(p: Params, a: Acc):
    """kernels.grasp.finalize: eq. (2) score, success, failure reason and margins of one pick."""
    window = p.dwell_s + lift_duration(p) + p.hold_s
    t_grasp = wp.clamp(a.held_time / window, 0.0, 1.0)
    t_nc = wp.clamp(a.off_table_time / window, 0.0, 1.0)
    phi_deg = wp.degrees(a.phi_max)
    score = (t_grasp + (180.0 - phi_deg) / 180.0 + t_nc) / 3.0
    high = p.success_height_fraction * p.lift_height_m
    lifted_after_lift = (a.lift_after_lift >= high) and not a.table_after_lift
    held_to_end = a.finished and (a.lift_final >= high) and not a.table_final
    upright = a.rot_final <= p.max_rotation_rad
    success = a.reached and held_to_end and upright and not a.diverged
    judged = a.reached and a.finished and not a.diverged
    lift_end = a.lift_final
    if a.table_final:
        lift_end = 0.0
    height_margin = (lift_end - high) / wp.max(p.lift_height_m - high, 1.0e-9)
    rotation_margin = (p.max_rotation_rad - a.rot_final) / p.max_rotation_rad
    margin = wp.min(height_margin, rotation_margin)
    failure = OK
    if success:
        failure = OK
    elif a.diverged:
        failure = DIVERGED
    elif (not a.reached) and (not a.contact_seen):
        failure = NO_CONTACT
    elif not a.reached:
        failure = FORCE_NOT_REACHED
    elif not lifted_after_lift:
        failure = SLIPPED_IN_LIFT
    elif not held_to_end:
        failure = DROPPED_IN_HOLD
    elif not upright:
        failure = ROTATED
    nan = wp.nan
    r = Result()
    r.success = success
    r.failure = failure
    r.diverged = a.diverged
    r.score = score
    r.t_grasp = t_grasp
    r.phi_max_deg = phi_deg
    r.t_grasp_nc = t_nc
    if a.diverged:
        r.score = nan
        r.t_grasp = nan
        r.phi_max_deg = nan
        r.t_grasp_nc = nan
    r.yaw_max_deg = wp.degrees(a.yaw_max)
    r.tilt_max_deg = wp.degrees(a.tilt_max)
    r.t_reached_s = a.t_reached
    r.max_force_left_n = a.force_left_max
    r.max_force_right_n = a.force_right_max
    r.lift_height_mm = 1.0e3 * a.lift_final
    r.slip_mm = 1.0e3 * a.slip_max
    r.chatter = int(a.chatter)
    r.rotation_final_deg = nan
    if a.finished and not a.diverged:
        r.rotation_final_deg = wp.degrees(a.rot_final)
    r.label_margin = nan
    if judged:
        r.label_margin = margin
    return r


@wp.func
def finger_command(ad: Addresses, dr: Drive, finger_target: float):
    """The finger actuators' control for a closing-travel target (kernels.grasp.command)."""
    if ad.has_drive:
        length = interp(finger_target, dr.travel, dr.length)
        return dr.ctrl_at_zero_length + dr.ctrl_per_length * length
    return finger_target


@wp.func
def write_command(ad: Addresses, dr: Drive, s: Control, ctrl: wp.array(dtype=float)):
    """kernels.grasp.command into ctrl (nu,): zeros but for the lift and the finger actuators."""
    for i in range(ctrl.shape[0]):
        ctrl[i] = 0.0
    ctrl[ad.lift_actuator] = s.lift_target
    finger = finger_command(ad, dr, s.finger_target)
    ctrl[ad.finger_left_actuator] = finger
    ctrl[ad.finger_right_actuator] = finger


@wp.func
def initial_control(ad: Addresses, dr: Drive, qpos0: wp.array(dtype=float)):
    """kernels.grasp.initial's ControlState from a pick's initial qpos (nq,)."""
    s = Control()
    s.phase = SETTLE
    s.t_phase = 0.0
    s.finger_target = finger_travel_left(ad, dr, qpos0[ad.finger_left_qpos])
    s.lift_target = qpos0[ad.lift_qpos]
    s.lift_velocity = 0.0
    s.t_steady = 0.0
    s.lift_start = qpos0[ad.lift_qpos]
    return s


@wp.func
def initial_acc():
    """kernels.grasp.initial_accumulators."""
    a = Acc()
    a.contact_seen = False
    a.reached = False
    a.t_reached = -1.0
    a.held = False
    a.held_time = 0.0
    a.off_table_time = 0.0
    a.phi_max = 0.0
    a.yaw_max = 0.0
    a.tilt_max = 0.0
    a.force_left_max = 0.0
    a.force_right_max = 0.0
    a.lift_after_lift = 0.0
    a.table_after_lift = True
    a.slip_max = 0.0
    a.lift_final = 0.0
    a.table_final = True
    a.rot_final = 0.0
    a.finished = False
    a.diverged = False
    a.t = 0.0
    a.touch_left = False
    a.touch_right = False
    a.lost_left = False
    a.lost_right = False
    a.chatter = 0.0
    return a


@wp.func
def trace_row(a: Acc, s: Control, m: Measurement, row: wp.array(dtype=float)):
    """kernels.grasp.tick's trace row (kt.TRACE_FIELDS order) into row (NTRACE,)."""
    row[0] = a.t
    row[1] = m.force_left
    row[2] = m.force_right
    row[3] = m.force_table
    row[4] = m.object_pos[0]
    row[5] = m.object_pos[1]
    row[6] = m.object_pos[2]
    row[7] = yaw(m.object_quat)
    row[8] = m.object_quat[0]
    row[9] = m.object_quat[1]
    row[10] = m.object_quat[2]
    row[11] = m.object_quat[3]
    row[12] = m.finger_left
    row[13] = m.finger_right
    row[14] = m.lift
    row[15] = float(s.phase)


@wp.func
def finished(s: Control, a: Acc, k: int, n_ticks: int):
    """Whether a pick has ended: DONE, diverged, or n_ticks control periods run."""
    return s.phase == DONE or a.diverged or k >= n_ticks
