"""One pick-point's controller, phase machine and metric accumulation (pure JAX).

Details: docs/engine.md (kernels/grasp.py).
"""

from __future__ import annotations

import jax.numpy as jnp

# the kernels' data (kernels.types, defined without JAX), re-exported for their callers
from mjx_pick.kernels.types import (  # noqa: F401
    CLOSE,
    DONE,
    DWELL,
    FAILURES,
    HOLD,
    LIFT,
    OLD_SUCCESS_LABEL,
    PHASES,
    SETTLE,
    SUCCESS,
    TRACE_FIELDS,
    Accumulators,
    Addresses,
    ControlState,
    DriveMap,
    GraspParams,
    Measurement,
    Outcome,
)


def initial_state(finger_travel0, lift0=None) -> ControlState:
    """Start: settling, fingers at their starting travel (m), the lift where it starts
    (m; None: 0, the gripper's nominal height)."""
    z = jnp.zeros_like(finger_travel0)
    lift0 = z if lift0 is None else jnp.asarray(lift0, z.dtype)
    phase = jnp.int32(SETTLE) + jnp.zeros_like(finger_travel0, jnp.int32)
    return ControlState(phase, z, finger_travel0, lift0, z, z, lift0)


def initial_accumulators(like) -> Accumulators:
    z = jnp.zeros_like(like)
    f = jnp.zeros_like(like, dtype=bool)
    return Accumulators(
        contact_seen=f,
        reached=f,
        t_reached=z - 1.0,
        held=f,
        held_time=z,
        off_table_time=z,
        phi_max=z,
        yaw_max=z,
        tilt_max=z,
        force_left_max=z,
        force_right_max=z,
        lift_after_lift=z,
        table_after_lift=~f,
        slip_max=z,
        lift_final=z,
        table_final=~f,
        rot_final=z,
        finished=f,
        diverged=f,
        t=z,
        touch_left=f,
        touch_right=f,
        lost_left=f,
        lost_right=f,
        chatter=z,
    )


def control_step(p: GraspParams, s: ControlState, m: Measurement):
    """One control period: phase transitions and the P force controller.

    Returns:
      the next ControlState (its targets are the commands for this period).
    """
    force = 0.5 * (m.force_left + m.force_right)
    t = s.t_phase + p.dt
    ph = s.phase
    f_lim = jnp.minimum(p.force_limit_fraction * p.grip_force_n, p.force_max_n)
    # "reached" once the force has stayed between reach_fraction * F_d and the limit
    # for reach_settle_s: the impact of the approaching pads (a light part bounces
    # between them) must not start the lift (reach_settle_s = 0: the paper's rule)
    # the band reaches at least as far above F_d as below it: with F_d at the gripper's
    # limit (f_lim = F_d) a force held at F_d dithers across f_lim by float noise (an
    # MJCF drive, whose force limit is not exactly F_d at the pads, showed it)
    upper = jnp.maximum(f_lim, (2.0 - p.reach_fraction) * p.grip_force_n)
    steady = (ph == CLOSE) & (force >= p.reach_fraction * p.grip_force_n) & (force <= upper)
    t_steady = jnp.where(steady, s.t_steady + p.dt, 0.0)
    reached = steady & (t_steady >= p.reach_settle_s - 1e-6)
    nxt = jnp.select(
        [
            (ph == SETTLE) & (t >= p.settle_s),
            (ph == CLOSE) & reached & (p.dwell_s > 0),
            (ph == CLOSE) & reached,
            (ph == CLOSE) & (t >= p.close_timeout_s),
            (ph == DWELL) & (t >= p.dwell_s),
            # the same sum as the lift's top below (float32: lift_start + h - lift_start
            # may fall short of h)
            (ph == LIFT) & (s.lift_target >= s.lift_start + p.lift_height_m),
            (ph == HOLD) & (t >= p.hold_s),
        ],
        [CLOSE, DWELL, LIFT, DONE, LIFT, HOLD, DONE],
        ph,
    ).astype(jnp.int32)
    t_next = jnp.where(nxt == ph, t, 0.0)
    # P force controller: on from CLOSE on; a failed close (DONE without a lift) stops
    active = (
        (ph != SETTLE)
        & ~((ph == CLOSE) & (nxt == DONE))
        & ~((ph == DONE) & (s.lift_target <= s.lift_start))
    )
    v = jnp.clip(p.kp * (p.grip_force_n - force), -p.v_open, p.v_close)
    # until a pad touches, the fingers approach at the set closing speed, as the real
    # gripper does (the P law alone would creep in at kp * F_d: 1.6 mm/s for F_d = 0.8 N)
    touching = jnp.maximum(m.force_left, m.force_right) > p.pad_contact_fraction * p.grip_force_n
    v = jnp.where(touching, v, p.v_close)
    finger_target = s.finger_target + jnp.where(active, v * p.dt, 0.0)
    # anti-windup once engaged (touching, or holding: a pad bouncing off a sliding part
    # reads zero force for a tick): the servo pushes k_drive * (target - travel), at
    # most F_lim. In free approach the target leads by the drive's tracking lag only.
    engaged = touching | (ph == DWELL) | (ph == LIFT) | (ph == HOLD)
    k_drive = (
        p.drive_stiffness_n_per_m
        if m.drive_stiffness_n_per_m is None
        else m.drive_stiffness_n_per_m
    )
    capped = jnp.minimum(m.finger_left, m.finger_right) + f_lim / k_drive
    finger_target = jnp.where(engaged, jnp.minimum(finger_target, capped), finger_target)
    # the lift runs in LIFT only: trapezoidal profile, the speed rises by a*dt, never
    # above the cruise speed, and never above what still allows a stop at the top
    lifting = nxt == LIFT
    top = s.lift_start + p.lift_height_m
    remaining = jnp.maximum(top - s.lift_target, 0.0)
    v_stop = jnp.sqrt(2.0 * p.lift_accel_m_s2 * remaining)
    v_lift = jnp.minimum(s.lift_velocity + p.lift_accel_m_s2 * p.dt, p.lift_speed_m_s)
    v_lift = jnp.where(lifting, jnp.clip(v_lift, 0.0, v_stop), 0.0)
    lift_target = s.lift_target + v_lift * p.dt
    # within a micrometre of the top counts as arrived (the stopping speed tends to 0)
    lift_target = jnp.where(top - lift_target < 1e-6, top, lift_target)
    lift_target = jnp.where(lifting, jnp.minimum(lift_target, top), s.lift_target)
    return ControlState(nxt, t_next, finger_target, lift_target, v_lift, t_steady, s.lift_start)


def lift_duration(p: GraspParams):
    """Time of the trapezoidal lift (triangular when the cruise speed is not reached), s."""
    v, a, h = p.lift_speed_m_s, p.lift_accel_m_s2, p.lift_height_m
    trapezoid = h / v + v / a
    triangle = 2.0 * jnp.sqrt(h / a)
    return jnp.where(v * v / a < h, trapezoid, triangle)


def _quat_angle(q, q0):
    """Rotation angle between unit quaternions (rad, 0..pi)."""
    c = jnp.abs(jnp.sum(q * q0))
    return 2.0 * jnp.arccos(jnp.clip(c, 0.0, 1.0))


def _yaw(q):
    w, x, y, z = q[0], q[1], q[2], q[3]
    return jnp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _tilt(q):
    """Angle between the object's z axis and the world's (rad)."""
    x, y = q[1], q[2]
    r22 = 1.0 - 2.0 * (x * x + y * y)
    return jnp.arccos(jnp.clip(r22, -1.0, 1.0))


def accumulate(
    p: GraspParams,
    a: Accumulators,
    s: ControlState,
    s_next: ControlState,
    m: Measurement,
    pos0,
    quat0,
) -> Accumulators:
    """Fold one tick's measurement into the per-pick metrics.

    s is the state the tick ran in, s_next the one the controller chose; pos0, quat0
    the object's initial pose.
    """
    running = s.phase != DONE
    bad = (~m.finite | (m.speed_max > p.divergence_speed)) & running
    diverged = a.diverged | bad
    # nothing accumulates once DONE (a backend may stop stepping a finished pick) or
    # diverged (NaNs must not leak into maxima)
    live = ~diverged & running
    fl = jnp.where(live, m.force_left, 0.0)
    fr = jnp.where(live, m.force_right, 0.0)
    ft = jnp.where(live, m.force_table, 0.0)
    quat = jnp.where(live, m.object_quat, quat0)
    pos = jnp.where(live, m.object_pos, pos0)

    pad_contact_n = p.pad_contact_fraction * p.grip_force_n
    contact = jnp.maximum(fl, fr) > pad_contact_n
    gripping = jnp.minimum(fl, fr) > pad_contact_n
    on_table = ft > p.table_contact_n
    just_reached = (s.phase == CLOSE) & ((s_next.phase == LIFT) | (s_next.phase == DWELL))
    reached = a.reached | (live & just_reached)
    in_window = live & a.reached & (s.phase != DONE)
    held = jnp.where(live & just_reached, True, a.held & (~in_window | gripping))
    rot = _quat_angle(quat, quat0)
    d = _yaw(quat) - _yaw(quat0)
    dyaw = jnp.abs(jnp.arctan2(jnp.sin(d), jnp.cos(d)))
    obj_lift = pos[2] - pos0[2]
    # chatter: in the window, a pad that touched, let go, and touches again
    touch_l, touch_r = fl > pad_contact_n, fr > pad_contact_n
    back_l = in_window & a.lost_left & touch_l
    back_r = in_window & a.lost_right & touch_r
    lost_l = jnp.where(in_window, (a.lost_left | (a.touch_left & ~touch_l)) & ~touch_l, False)
    lost_r = jnp.where(in_window, (a.lost_right | (a.touch_right & ~touch_r)) & ~touch_r, False)
    lift_end = (s.phase == LIFT) & (s_next.phase == HOLD) & live
    hold_end = (s.phase == HOLD) & (s_next.phase == DONE) & live
    return Accumulators(
        contact_seen=a.contact_seen | (live & contact),
        reached=reached,
        t_reached=jnp.where(live & just_reached, a.t + p.dt, a.t_reached),
        held=held,
        held_time=a.held_time + jnp.where(in_window & held & gripping, p.dt, 0.0),
        off_table_time=a.off_table_time + jnp.where(in_window & ~on_table, p.dt, 0.0),
        phi_max=jnp.maximum(a.phi_max, jnp.where(live, rot, 0.0)),
        yaw_max=jnp.maximum(a.yaw_max, jnp.where(live, dyaw, 0.0)),
        tilt_max=jnp.maximum(a.tilt_max, jnp.where(live, _tilt(quat), 0.0)),
        force_left_max=jnp.maximum(a.force_left_max, fl),
        force_right_max=jnp.maximum(a.force_right_max, fr),
        lift_after_lift=jnp.where(lift_end, obj_lift, a.lift_after_lift),
        table_after_lift=jnp.where(lift_end, on_table, a.table_after_lift),
        slip_max=jnp.maximum(
            a.slip_max, jnp.where(in_window, m.lift - s.lift_start - obj_lift, 0.0)
        ),
        lift_final=jnp.where(hold_end, obj_lift, a.lift_final),
        table_final=jnp.where(hold_end, on_table, a.table_final),
        rot_final=jnp.where(hold_end, rot, a.rot_final),
        finished=a.finished | hold_end,
        diverged=diverged,
        t=a.t + p.dt,
        touch_left=in_window & touch_l,
        touch_right=in_window & touch_r,
        lost_left=lost_l,
        lost_right=lost_r,
        chatter=a.chatter + back_l.astype(a.chatter.dtype) + back_r.astype(a.chatter.dtype),
    )


def finalize(p: GraspParams, a: Accumulators) -> dict:
    """Per-pick results: eq. (2) score with documented normalisation, success, reason.

    Normalisation: t_grasp and t_grasp_nc are fractions of the planned grasp window
    (dwell + lift + hold), so each term of S lies in [0, 1]; weights are 1/3 each (the
    paper's 0.33), so S lies in [0, 1].
    """
    window = p.dwell_s + lift_duration(p) + p.hold_s
    t_grasp = jnp.clip(a.held_time / window, 0.0, 1.0)
    t_nc = jnp.clip(a.off_table_time / window, 0.0, 1.0)
    phi_deg = jnp.rad2deg(a.phi_max)
    score = (t_grasp + (180.0 - phi_deg) / 180.0 + t_nc) / 3.0
    high = p.success_height_fraction * p.lift_height_m
    lifted_after_lift = (a.lift_after_lift >= high) & ~a.table_after_lift
    held_to_end = a.finished & (a.lift_final >= high) & ~a.table_final
    upright = a.rot_final <= p.max_rotation_rad
    success = a.reached & held_to_end & upright & ~a.diverged
    # how far the deciding quantities lie from their thresholds, each as a fraction of
    # its tolerance (1: no slip / no turn; 0: on the threshold; < 0: past it), so that a
    # label decided by a hair can be told from a clear one; a part still touching the
    # table at the end counts as not lifted. Where judged, success <=> margin >= 0.
    judged = a.reached & a.finished & ~a.diverged
    lift_end = jnp.where(a.table_final, 0.0, a.lift_final)
    height_margin = (lift_end - high) / jnp.maximum(p.lift_height_m - high, 1e-9)
    rotation_margin = (p.max_rotation_rad - a.rot_final) / p.max_rotation_rad
    margin = jnp.minimum(height_margin, rotation_margin)
    # each outcome's condition, the first that holds decides (a reason only for picks
    # that failed: a held pick whose part lagged below the success height at the lift's
    # end, or still touched the table there, is a success)
    conditions = {
        Outcome.OK: success,
        Outcome.DIVERGED: a.diverged,
        Outcome.NO_CONTACT: ~a.reached & ~a.contact_seen,
        Outcome.FORCE_NOT_REACHED: ~a.reached,
        Outcome.SLIPPED_IN_LIFT: ~lifted_after_lift,
        Outcome.DROPPED_IN_HOLD: ~held_to_end,
        Outcome.ROTATED: ~upright,
    }
    failure = jnp.select(list(conditions.values()), list(conditions), Outcome.OK)
    nan = jnp.full_like(score, jnp.nan)
    return {
        "success": success,
        "failure": failure.astype(jnp.int32),
        "diverged": a.diverged,
        "score": jnp.where(a.diverged, nan, score),
        "t_grasp": jnp.where(a.diverged, nan, t_grasp),
        "phi_max_deg": jnp.where(a.diverged, nan, phi_deg),
        "t_grasp_nc": jnp.where(a.diverged, nan, t_nc),
        "yaw_max_deg": jnp.rad2deg(a.yaw_max),
        "tilt_max_deg": jnp.rad2deg(a.tilt_max),
        "t_reached_s": a.t_reached,
        "max_force_left_n": a.force_left_max,
        "max_force_right_n": a.force_right_max,
        "lift_height_mm": 1e3 * a.lift_final,
        "slip_mm": 1e3 * a.slip_max,
        "chatter": a.chatter.astype(jnp.int32),
        "rotation_final_deg": jnp.where(a.finished & ~a.diverged, jnp.rad2deg(a.rot_final), nan),
        "label_margin": jnp.where(judged, margin, nan),
    }


def _interp(x, xs: tuple, ys: tuple):
    """Piecewise-linear table lookup, clamped at the ends (jnp.interp on constants)."""
    return jnp.interp(x, jnp.asarray(xs, x.dtype), jnp.asarray(ys, x.dtype))


def finger_travel(ad: Addresses, qpos):
    """(left, right) pads' closing travel, m, from qpos (nq,)."""
    ql, qr = qpos[ad.finger_left_qpos], qpos[ad.finger_right_qpos]
    if ad.drive is None:
        return ql, qr
    d = ad.drive
    return _interp(ql, d.q_left, d.travel_left), _interp(qr, d.q_right, d.travel_right)


def measure(p: GraspParams, ad: Addresses, qpos, qvel, cfrc_ext) -> Measurement:
    """Measurement from one simulation's qpos (nq,), qvel (nv,), cfrc_ext (nbody, 6).

    cfrc_ext rows are (torque, force) in world axes. The object pushes the left pad
    against the closing axis (p's closing_axis_*) and the right pad along it; the table
    force on the object is the object's external force minus what the pads apply to it
    (Newton's third law).
    """
    f_obj = cfrc_ext[ad.object_body, 3:]
    f_left = cfrc_ext[ad.finger_left_body, 3:]
    f_right = cfrc_ext[ad.finger_right_body, 3:]
    o = ad.object_qpos
    travel_left, travel_right = finger_travel(ad, qpos)
    stiffness = None
    if ad.drive is not None:
        slower = jnp.minimum(travel_left, travel_right)
        stiffness = _interp(slower, ad.drive.travel, ad.drive.stiffness_n_per_m)
    axis = (p.closing_axis_x, p.closing_axis_y, p.closing_axis_z)
    return Measurement(
        force_left=-(f_left[0] * axis[0] + f_left[1] * axis[1] + f_left[2] * axis[2]),
        force_right=f_right[0] * axis[0] + f_right[1] * axis[1] + f_right[2] * axis[2],
        force_table=f_obj[2] + f_left[2] + f_right[2],
        finger_left=travel_left,
        finger_right=travel_right,
        object_pos=qpos[o : o + 3],
        object_quat=qpos[o + 3 : o + 7],
        lift=qpos[ad.lift_qpos],
        speed_max=jnp.max(jnp.abs(qvel)),
        finite=jnp.all(jnp.isfinite(qpos)) & jnp.all(jnp.isfinite(qvel)),
        drive_stiffness_n_per_m=stiffness,
    )


def command(ad: Addresses, s: ControlState, like):
    """Actuator controls (nu,) for the state's targets.

    An MJCF gripper's actuator is a position servo on its drive (a tendon or a joint):
    the travel target becomes the drive length that gives it (the table), then the
    control that sets that length as the servo's reference.
    """
    ctrl = jnp.zeros(ad.nu, like.dtype)
    ctrl = ctrl.at[ad.lift_actuator].set(s.lift_target)
    finger = s.finger_target
    if ad.drive is not None:
        d = ad.drive
        length = _interp(finger, d.travel, d.length)
        finger = d.ctrl_at_zero_length + d.ctrl_per_length * length
    ctrl = ctrl.at[ad.finger_left_actuator].set(finger)
    return ctrl.at[ad.finger_right_actuator].set(finger)


def tick(p: GraspParams, ad: Addresses, s, a, qpos, qvel, cfrc_ext, pos0, quat0):
    """Measure, control, accumulate: everything one pick does once per control period.

    Returns:
      (next ControlState, next Accumulators, ctrl (nu,), trace row (TRACE_FIELDS,)).
    """
    m = measure(p, ad, qpos, qvel, cfrc_ext)
    s_next = control_step(p, s, m)
    a_next = accumulate(p, a, s, s_next, m, pos0, quat0)
    row = jnp.stack(
        [
            a.t,
            m.force_left,
            m.force_right,
            m.force_table,
            m.object_pos[0],
            m.object_pos[1],
            m.object_pos[2],
            _yaw(m.object_quat),
            m.object_quat[0],
            m.object_quat[1],
            m.object_quat[2],
            m.object_quat[3],
            m.finger_left,
            m.finger_right,
            m.lift,
            s.phase.astype(m.lift.dtype),
        ]
    )
    return s_next, a_next, command(ad, s_next, qpos), row


def initial(ad: Addresses, qpos0) -> tuple[ControlState, Accumulators]:
    """One pick's starting control state and accumulators from its initial qpos (nq,):
    the fingers' travel (through the DriveMap of an MJCF gripper) and the lift where it
    starts (raised by an MJCF linkage's height compensation)."""
    travel0, _ = finger_travel(ad, qpos0)
    return initial_state(travel0, qpos0[ad.lift_qpos]), initial_accumulators(travel0)
