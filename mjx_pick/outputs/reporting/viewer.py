"""``mjx-pick view RUN --pick ID``: one traced pick-point replayed in MuJoCo's
interactive viewer (``mujoco.viewer.launch_passive``), where a display exists.

Details: docs/outputs.md (outputs/reporting/viewer.py).
"""

from __future__ import annotations

import os
import sys
import time

from mjx_pick.core import numbers
from mjx_pick.core.config import ConfigError
from mjx_pick.outputs.display import display_problem
from mjx_pick.outputs.reporting.body_poses import TracePose
from mjx_pick.outputs.reporting.run import Run

__all__ = ["view"]


def check_view(run_dir: str | os.PathLike, pick_id: int | str, speed: float = 1.0):
    """The run, the pick-point's trace and the model file of a replay: a ConfigError
    naming the input when one is wrong (before anything opens a window). pick_id: a
    traced pick_id, or "best" / "worst": the best or worst traced pick-point."""
    run = Run.load(run_dir)
    numbers.check("speed", speed)
    ranked = run.traced()
    traced = [pid for pid, _ in ranked]
    if run.traces is None or not traced:
        raise ConfigError(
            f"{run.path}: no traced pick-points (traces.parquet); evaluate with --traces 1 or more"
        )
    if pick_id in ("best", "worst"):
        # traced() lists the best first (best at its top), the worst after (worst last)
        pick_id = traced[0] if pick_id == "best" else traced[-1]
    else:
        try:
            pick_id = int(pick_id)
        except ValueError:
            raise ConfigError(f"--pick {pick_id!r}: a traced pick_id, best or worst") from None
    if pick_id not in traced:
        raise ConfigError(
            f"--pick {pick_id}: not traced in {run.path}; traced pick-points: "
            + ", ".join(str(p) for p in traced)
        )
    scene = run.path / "scene.xml"
    if not scene.is_file():
        raise ConfigError(f"{run.path}: no scene.xml (the simulated model) to replay")
    return run, run.trace(pick_id), scene


def view(
    run_dir: str | os.PathLike, pick_id: int | str, *, speed: float = 1.0, loop: bool = False
) -> None:
    """Replay traced pick-point pick_id ("best", "worst" or a traced pick_id) of an
    evaluate folder in MuJoCo's viewer.

    speed: playback speed, a multiple of real time; loop: replay until the window is
    closed (else the last frame stays until it is closed). The time and phase show in
    the window's corner. Raises ConfigError for a bad input or where no display exists.
    """
    run, trace, scene = check_view(run_dir, pick_id, speed)
    problem = display_problem()
    if problem:
        raise ConfigError(f"view: {problem}; without one, `mjx-pick report` writes anim_*.mp4")
    import mujoco
    import mujoco.viewer

    model = mujoco.MjModel.from_xml_path(str(scene))
    data = mujoco.MjData(model)
    pose = TracePose(model, trace, run.gripper)
    try:
        handle = mujoco.viewer.launch_passive(model, data)
    except RuntimeError as err:  # macOS outside mjpython, or no GL context
        hint = " (on macOS run it with mjpython: mjpython -m mjx_pick.cli view ...)"
        raise ConfigError(
            f"view: MuJoCo's viewer could not start: {err}"
            + (hint if sys.platform == "darwin" else "")
        ) from err
    with handle:
        _replay(handle, model, data, pose, trace, speed, loop)


def _replay(handle, model, data, pose: TracePose, trace: dict, speed: float, loop: bool) -> None:
    import mujoco

    step_s = pose.dt / speed
    while handle.is_running():
        start = time.monotonic()
        for k in range(len(pose)):
            if not handle.is_running():
                return
            with handle.lock():
                pose.apply(data, k)
                mujoco.mj_forward(model, data)
            label = f"t = {trace['t_s'][k]:.2f} s  {trace['phase'][k]}"
            handle.set_texts((None, None, label, f"{speed:g} x real time"))
            handle.sync()
            lag = start + (k + 1) * step_s - time.monotonic()
            if lag > 0:
                time.sleep(lag)
        if not loop:
            break
    while handle.is_running():  # the last frame stays until the window is closed
        time.sleep(0.05)
