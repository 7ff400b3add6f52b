"""Traced pick-points replayed in MuJoCo's offscreen renderer (GIF, top and side)."""

from __future__ import annotations

import io
import os

import numpy as np

from mjx_pick.config import write_atomic
from mjx_pick.gripper import GripperSpec
from mjx_pick.mjcf_gripper import PREFIX, characterise

__all__ = ["animate"]


def animate(
    scene_xml: str | os.PathLike,
    trace: dict,
    path: str | os.PathLike,
    every: int = 8,
    size: tuple[int, int] = (320, 240),
    gripper: GripperSpec | None = None,
) -> int:
    """Replay a trace in MuJoCo's offscreen renderer as a GIF; returns the frame count.

    An MJCF gripper (gripper.mjcf) is posed from the traced pad travel through its
    measured close (``mjx_pick.mjcf_gripper``).

    Each frame is the top camera beside the side camera (each ``size`` = (width,
    height) pixels), with the time and phase written on it; one frame every ``every``
    control ticks, played in real time.
    """
    import mujoco
    from PIL import Image, ImageDraw

    model = mujoco.MjModel.from_xml_path(str(scene_xml))
    data = mujoco.MjData(model)
    w, h = size
    try:
        renderer = mujoco.Renderer(model, h, w)
    except Exception as err:  # noqa: BLE001 - any GL failure gets the same advice
        raise RuntimeError(
            "MuJoCo's offscreen renderer could not start: set MUJOCO_GL=egl (or osmesa) "
            "before Python starts and install libegl1 (or libosmesa6)"
        ) from err
    linkage = None if gripper is None or gripper.mjcf is None else characterise(gripper.mjcf)
    fingers = () if linkage else ("finger_left", "finger_right")
    adr = {j: int(model.jnt_qposadr[model.joint(j).id]) for j in ("object", "lift", *fingers)}
    if linkage:
        links = [int(model.jnt_qposadr[model.joint(PREFIX + j).id]) for j in linkage.joint_names]
    cams = []
    for elevation, distance, lookat_z in ((-90.0, 0.25, 0.02), (-8.0, 0.38, 0.07)):
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = (0.0, 0.0, lookat_z)
        cam.distance, cam.azimuth, cam.elevation = distance, 90.0, elevation
        option = mujoco.MjvOption()
        if elevation < -45:  # from the top, the gripper's body would hide the object
            option.geomgroup[2] = 0
        cams.append((cam, option))
    frames = []
    dt = float(trace["t_s"][1] - trace["t_s"][0]) if len(trace["t_s"]) > 1 else 0.005
    try:
        for k in range(0, len(trace["t_s"]), every):
            o = adr["object"]
            data.qpos[o : o + 3] = [trace[f"object_{c}_m"][k] for c in "xyz"]
            data.qpos[o + 3 : o + 7] = [trace[f"object_q{c}"][k] for c in "wxyz"]
            data.qpos[adr["lift"]] = trace["lift_m"][k]
            if linkage:
                travel = 0.5 * (trace["finger_left_m"][k] + trace["finger_right_m"][k])
                data.qpos[links] = linkage.joint_positions(travel)[0]
            else:
                data.qpos[adr["finger_left"]] = trace["finger_left_m"][k]
                data.qpos[adr["finger_right"]] = trace["finger_right_m"][k]
            mujoco.mj_forward(model, data)
            views = []
            for cam, option in cams:
                renderer.update_scene(data, camera=cam, scene_option=option)
                views.append(renderer.render())
            img = Image.fromarray(np.concatenate(views, axis=1))
            draw = ImageDraw.Draw(img)
            draw.text(
                (6, 4), f"t = {trace['t_s'][k]:.2f} s  {trace['phase'][k]}", fill=(255, 255, 255)
            )
            draw.text((w + 6, 4), "side", fill=(255, 255, 255))
            frames.append(img.convert("P", palette=Image.Palette.ADAPTIVE))
    finally:
        renderer.close()
    buf = io.BytesIO()
    frames[0].save(
        buf,
        format="GIF",
        save_all=True,
        append_images=frames[1:],
        duration=max(20, int(round(1000 * dt * every))),
        loop=0,
    )
    write_atomic(path, buf.getvalue())
    return len(frames)
