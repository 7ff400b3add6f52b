"""Which OpenGL back end MuJoCo's offscreen renderer (the report's animations) uses.

MuJoCo picks its back end once, when ``mujoco`` is first imported, from the environment
variable ``MUJOCO_GL``. Without a display the default (GLFW) cannot open a context, so a
headless machine needs EGL. Importing mjx_pick never sets it; the command line calls
:func:`use_offscreen_rendering` before anything imports MuJoCo, and a notebook or script
that renders on a headless machine calls it first too.
"""

from __future__ import annotations

import ctypes.util
import os
import sys
import warnings

__all__ = ["display_problem", "has_display", "use_offscreen_rendering"]


def use_offscreen_rendering() -> str | None:
    """Set ``MUJOCO_GL=egl`` on a Linux machine without a display, where libEGL exists.

    Never overrides a value the user set, and leaves a machine with a display alone.
    Without libEGL it sets nothing: ``MUJOCO_GL=egl`` with no libEGL makes ``import
    mujoco`` itself fail. Returns the value in force afterwards (None: MuJoCo's default).
    Call it before MuJoCo is imported; afterwards it can no longer take effect (a
    warning says so).
    """
    if "MUJOCO_GL" in os.environ:
        return os.environ["MUJOCO_GL"]
    if has_display():
        return None
    if not ctypes.util.find_library("EGL"):
        return None
    if "mujoco" in sys.modules:
        warnings.warn(
            "use_offscreen_rendering() after `import mujoco`: MuJoCo has already chosen its "
            "OpenGL back end; set MUJOCO_GL=egl before Python starts instead",
            RuntimeWarning,
            stacklevel=2,
        )
        return None
    os.environ["MUJOCO_GL"] = "egl"
    return "egl"


def has_display() -> bool:
    """Whether windows can open here: always off Linux; on Linux, an X11 (DISPLAY) or
    Wayland (WAYLAND_DISPLAY) session."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def display_problem() -> str | None:
    """Why no window can open here, in one phrase naming what is needed (None: fine)."""
    if has_display():
        return None
    return (
        "no display: neither DISPLAY nor WAYLAND_DISPLAY is set; run it in a desktop "
        "session (X11 or Wayland) or over ssh -X"
    )
