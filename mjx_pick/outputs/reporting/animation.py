"""Traced pick-points replayed in MuJoCo's offscreen renderer (GIF and MP4, top and side).

Every trace row holds the whole joint state (``kernels.grasp.TRACE_FIELDS``), so a
replay simulates nothing: ``body_poses.TracePose`` sets the model's joints from one row.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from pathlib import Path

import numpy as np

from mjx_pick.core.config import write_atomic
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.outputs.reporting.body_poses import TracePose

__all__ = ["animate", "render_pool", "render_rows", "write_mp4"]


def _render_in_child() -> bool:
    """Whether this process cannot render offscreen but an EGL child can: no display,
    no MUJOCO_GL chosen (MuJoCo takes it once, at its import: a library never sets it
    for its caller), and libEGL present. The CLI chooses EGL for its own process
    (``display.use_offscreen_rendering``) and renders in it."""
    import ctypes.util

    from mjx_pick.outputs.display import has_display

    return (
        "MUJOCO_GL" not in os.environ
        and not has_display()
        and sys.platform.startswith("linux")
        and bool(ctypes.util.find_library("EGL"))
    )


def render_rows(
    scene_xml: str | os.PathLike,
    trace: dict,
    rows,
    size: tuple[int, int] = (320, 240),
    gripper: GripperSpec | None = None,
) -> list[np.ndarray]:
    """Trace rows rendered in MuJoCo's offscreen renderer: for each row k in rows, the
    top camera beside the side camera (each ``size`` = (width, height) pixels) with the
    time and phase written on it, an RGB array (height, 2 width, 3)."""
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
    pose = TracePose(model, trace, gripper)
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
    try:
        for k in rows:
            pose.apply(data, k)
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
            frames.append(np.asarray(img))
    finally:
        renderer.close()
    return frames


@contextlib.contextmanager
def render_pool():
    """Where animations render: None for this process, or (where it cannot render
    offscreen but an EGL child can, :func:`_render_in_child`) one child process that
    starts with EGL. A report opens it once for all its animations: a child costs the
    imports of MuJoCo and this package, a few seconds, each time one starts."""
    if not _render_in_child():
        yield None
        return
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    saved = os.environ.get("MUJOCO_GL")
    os.environ["MUJOCO_GL"] = "egl"  # inherited by the child at its start only
    try:
        with ctx.Pool(1) as pool:
            yield pool
    finally:
        if saved is None:
            os.environ.pop("MUJOCO_GL", None)
        else:
            os.environ["MUJOCO_GL"] = saved


def animate(
    scene_xml: str | os.PathLike,
    trace: dict,
    path: str | os.PathLike,
    every: int = 8,
    size: tuple[int, int] = (320, 240),
    gripper: GripperSpec | None = None,
    mp4: bool = True,
    pool=None,
) -> int:
    """Replay a trace in MuJoCo's offscreen renderer as a GIF, and beside it (mp4) the
    same frames as an H.264 MP4 (``path`` with the suffix .mp4); returns the frame count.

    Each frame is :func:`render_rows`' (top and side cameras, time and phase); one frame
    every ``every`` control ticks, played in real time. pool: a :func:`render_pool`
    that several animations share (default: one opened for this one).
    """
    args = (scene_xml, trace, path, every, size, gripper, mp4)
    if pool is not None:
        return pool.apply(animate, args)
    if _render_in_child():
        # this process chose its OpenGL back end when it imported MuJoCo, and that one
        # cannot open a context here: render in a child that starts with EGL
        with render_pool() as child:
            return child.apply(animate, args)
    from PIL import Image

    frames = render_rows(scene_xml, trace, range(0, len(trace["t_s"]), every), size, gripper)
    t = trace["t_s"]
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.005
    frame_s = dt * every
    palette = [Image.fromarray(f).convert("P", palette=Image.Palette.ADAPTIVE) for f in frames]
    buf = io.BytesIO()
    palette[0].save(
        buf,
        format="GIF",
        save_all=True,
        append_images=palette[1:],
        duration=max(20, int(round(1000 * frame_s))),
        loop=0,
    )
    write_atomic(path, buf.getvalue())
    if mp4:
        write_mp4(Path(path).with_suffix(".mp4"), frames, 1.0 / frame_s)
    return len(frames)


def write_mp4(path: str | os.PathLike, frames: list[np.ndarray], fps: float) -> Path:
    """RGB frames (H, W, 3 uint8) as an H.264 MP4 (yuv420p: plays in browsers and
    players), fps frames per second, written atomically. Odd sizes are padded by one
    black pixel (the codec needs even ones).

    The encoder is the ffmpeg binary the imageio-ffmpeg wheel ships, run here directly:
    imageio's own writer starts it with a ``preexec_fn``, i.e. a Python-level fork in a
    process whose JAX threads are running (JAX warns of a deadlock), and leaves its pipes
    open. In its own session, so that a Ctrl-C meant for mjx-pick reaches it only
    through us (the partial file is removed).
    """
    import subprocess
    import tempfile

    from imageio_ffmpeg import get_ffmpeg_exe

    path = Path(path)
    h, w = frames[0].shape[:2]
    pad = ((0, h % 2), (0, w % 2), (0, 0))
    raw = b"".join(
        np.ascontiguousarray(np.pad(f[..., :3], pad), np.uint8).tobytes() for f in frames
    )
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".mp4")
    os.close(fd)
    cmd = [get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24"]
    cmd += ["-s", f"{w + w % 2}x{h + h % 2}", "-r", f"{fps:.6g}", "-i", "-", "-an"]
    cmd += ["-c:v", "libx264", "-pix_fmt", "yuv420p", "-movflags", "+faststart", tmp]
    try:
        done = subprocess.run(cmd, input=raw, capture_output=True, start_new_session=True)
        if done.returncode != 0:
            why = done.stderr.decode(errors="replace").strip().splitlines()
            raise RuntimeError(
                f"ffmpeg could not write {path} (exit {done.returncode}): "
                + (why[-1] if why else "no message")
            )
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
