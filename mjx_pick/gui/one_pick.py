"""The gripper tab's test of one pick-point (no web framework; runs in a worker thread).

Clearance and coverage first, with the pick-point's picture in the gripper frame, then
-- if it is feasible -- one recorded simulation through :func:`mjx_pick.evaluate` and
its force plot.
"""

from __future__ import annotations

import numpy as np

from mjx_pick.engine.registry import AUTO
from mjx_pick.gui import views
from mjx_pick.gui.formatting import compensation_text, fmt, outcome_words
from mjx_pick.gui.forms import Settings, backend_problems


def check_one_pick(obj, settings: Settings, x: float, y: float, yaw: float) -> dict:
    """The paper's checks of one pick-point (x, y in mm, yaw in degrees, gripper frame),
    without simulating it.

    Returns:
      {"lines": markdown lines for the page (the check, the initial speed, the fingertip
      height and, when feasible, the height compensation), "batch": the feasible
      GraspBatch of one or None, "pose": PNG bytes of the pick-point in the gripper
      frame (the part at its pose, the fingers at its opening or fully open)}.
    """
    from mjx_pick.core import pickpoints as pp
    from mjx_pick.core.procedure import fingertip_height_mm
    from mjx_pick.core.scene import height_compensation_mm

    checker = pp.FeasibilityChecker(obj, settings.gripper, settings.picks, settings.grasp)
    res = checker(np.array([x]), np.array([y]), np.array([yaw]))
    reason = pp.REASONS[int(res["reason"][0])]
    tip = fingertip_height_mm(obj, settings.gripper, settings.grasp)
    opening, coverage = float(res["opening_mm"][0]), float(res["coverage"][0])
    measured = ", ".join(
        text
        for value, text in (
            (opening, f"opening {opening:.1f} mm"),
            (coverage, f"coverage {coverage:.2f}"),
        )
        if np.isfinite(value)  # a pose that misses the object has neither
    )
    lines = [
        f"- clearance and coverage check: **{pp.REASON_WORDS[reason]}**"
        + (f" ({measured})" if measured else ""),
        f"- initial (closing) speed: {settings.grasp.closing_speed_mm_s:g} mm/s",
        f"- fingertip height above the table: {tip:.1f} mm (the pads' lower edges at the grasp)",
    ]
    batch = None
    if reason == "feasible":
        batch = checker.batch(np.array([0]), np.array([x]), np.array([y]), np.array([yaw]), "user")
        lines.append(
            "- " + compensation_text(float(height_compensation_mm(settings.gripper, batch)[0]))
        )
    shown = opening if np.isfinite(opening) else settings.gripper.stroke_mm
    pose = views.pose_png(obj, settings.gripper, x, y, yaw, shown)
    return {"lines": lines, "batch": batch, "pose": pose}


def simulate_one_pick(obj, settings: Settings, x: float, y: float, yaw: float, backend) -> dict:
    """The check and simulation of the pick-point (x, y in mm, yaw in degrees).

    Returns:
      {"text": markdown lines for the page, "pose": the pick-point's picture
      (:func:`check_one_pick`), "plot": force plot PNG bytes, or None when the
      pick-point is infeasible and was not simulated}.
    """
    from mjx_pick.studies.evaluation import evaluate

    checked = check_one_pick(obj, settings, x, y, yaw)
    head, batch = checked["lines"], checked["batch"]
    if batch is None:
        return {
            "text": "\n".join(head)
            + "\n- not simulated: the pick-point is infeasible. A feasible one: generate "
            "pick-points in tab 3 and click one on its map.",
            "plot": None,
            "pose": checked["pose"],
        }
    ev = evaluate(
        obj,
        settings.gripper,
        picks=batch,
        contact=settings.contact,
        grasp=settings.grasp,
        pick_config=settings.picks,
        backend=backend,
        n_traces=1,
    )
    r = {k: ev.table[k][0].as_py() for k in ev.table.column_names}
    trace = {name: np.asarray(ev.traces[name]) for name in ev.traces.column_names}
    head += [
        f"- score (eq. 2): **{fmt(r['score'])}**, success: **{r['success']}**, outcome: "
        f"{outcome_words(r['failure'])}",
        f"- `t_grasp` {fmt(r['t_grasp'])}, `phi_max` {fmt(r['phi_max_deg'], 1)} deg, "
        f"`t_grasp_nc` {fmt(r['t_grasp_nc'])}",
        f"- `F_Gmin`, eq. (1): {fmt(ev.summary['f_gmin_n'])} N at `F_d` = "
        f"{settings.grasp.grip_force_n:g} N",
    ]
    plot = views.force_png(trace, settings.grasp.grip_force_n, f"test pick ({x:g}, {y:g}, {yaw:g})")
    return {"text": "\n".join(head), "plot": plot, "pose": checked["pose"]}


def simulate_untraced(run, obj, pick_id: int) -> tuple[dict, dict, str]:
    """A pick-point of an evaluate run that the run did not trace, simulated now with
    its trace recorded, for tab 4's force plot and replay.

    The run's own settings (its config.json: gripper, contact, solver, procedure,
    pick-point checks and backend) and the pick's own pose; obj must be the run's object
    (ConfigError naming the difference otherwise: the run folder records the object's
    outline, not the object itself). Same settings, same backend: the same simulation
    as the run's, up to the float rounding of another batch size.

    A run made on a backend this machine cannot run (a GPU run opened on a CPU
    machine) is simulated on 'auto' here, and the note says so.

    Returns:
      (trace: {column: array} as ``Run.trace`` gives, row: the new simulation's
      results row, note: '' or what differs from the run's own simulation).
    """
    from mjx_pick.core import pickpoints as pp
    from mjx_pick.core.objects import check_same_object
    from mjx_pick.studies.calibration.trials.runs import settings_of
    from mjx_pick.studies.evaluation import evaluate

    config = run.config
    check_same_object(config.get("object") or {}, obj, f"run {run.path.name}")
    settings, pick_config = settings_of(config, f"{run.path.name}/config.json")
    row = run.row(pick_id)
    backend, note = config.get("backend") or AUTO, ""
    problem = backend_problems().get(backend)
    if problem:  # said, never the run's refusal with its install advice
        backend, note = AUTO, f"on {AUTO}: the run's backend {backend} cannot run here ({problem})"
    pose = row.get("grasp_pose")
    if pose is not None:  # a grasp given as a pose: the pose, tilt and height as the run's
        batch = _posed(obj, settings, pick_config, pick_id, np.asarray(pose, float))
    else:
        checker = pp.FeasibilityChecker(obj, settings.gripper, pick_config, settings.grasp)
        batch = checker.batch(
            np.array([pick_id]),
            np.array([row["x_mm"]]),
            np.array([row["y_mm"]]),
            np.array([row["yaw_deg"]]),
            "user",
        )
    ev = evaluate(
        obj,
        settings.gripper,
        picks=batch,
        contact=settings.contact,
        solver=settings.solver,
        grasp=settings.grasp,
        pick_config=pick_config,
        backend=backend,
        n_traces=1,
    )
    again = {k: ev.table[k][0].as_py() for k in ev.table.column_names}
    trace = {name: np.asarray(ev.traces[name]) for name in ev.traces.column_names}
    if pose is not None:  # as Run.trace gives a traced grasp's: the replay turns the gripper
        from mjx_pick.core.grasps import decompose

        trace["gripper_tilt_wxyz"] = decompose(np.reshape(pose, (1, 4, 4)))["tilt_quat"][0]
    return trace, again, note


def _posed(obj, settings, pick_config, pick_id: int, pose: np.ndarray):
    """The one grasp of a run given as a pose (its results' ``grasp_pose``: the grasp
    frame in the object frame), checked by the 6-DoF checks as the run checked it (the
    start opening by the same rule): a GraspBatch of one, or ConfigError saying why the
    grasp cannot be simulated here."""
    from mjx_pick.core.config import ConfigError
    from mjx_pick.core.grasp_checks import REASON_WORDS, GraspChecker
    from mjx_pick.engine.inputs import scene_of

    checker = GraspChecker(scene_of(obj, settings), pick_config.safety_zone_mm)
    batch = checker.batch(np.array([pick_id]), pose.reshape(1, 4, 4), "user")
    if len(batch) == 0:
        why = ", ".join(REASON_WORDS.get(k, k) for k, v in batch.rejected.items() if v)
        raise ConfigError(f"grasp {pick_id} is not feasible with the page's object: {why}")
    return batch
