"""Whether a window can be opened, and the OpenGL backend for offscreen rendering.

Nothing here imports MuJoCo: it reads MUJOCO_GL once, at its first import, so the backend
must be chosen before that.
"""

from __future__ import annotations

import os
import sys


def display_problem() -> str | None:
    """Why no window can be opened here, or None if one can."""
    if sys.platform == "darwin":
        return None
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return None
    return "no display (DISPLAY and WAYLAND_DISPLAY are not set)"


def choose_gl_backend() -> None:
    """Use EGL for offscreen rendering when there is no display and the user chose no backend."""
    if "MUJOCO_GL" not in os.environ and display_problem() is not None:
        os.environ["MUJOCO_GL"] = "egl"
