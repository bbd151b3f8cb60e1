"""A camera view that frames the robot (MuJoCo's default also frames the floor)."""

from __future__ import annotations

import mujoco
import numpy as np


def aim_at_robot(camera: mujoco.MjvCamera, model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Look at the robot's bodies in their current pose from the front-left, slightly above."""
    mujoco.mj_kinematics(model, data)
    points = np.vstack([data.xpos[1:], data.site_xpos]) if model.nsite else data.xpos[1:]
    low, high = points.min(axis=0), points.max(axis=0)
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = 0.5 * (low + high)
    camera.distance = max(1.0, 2.2 * float(np.linalg.norm(high - low)))
    camera.azimuth, camera.elevation = 135.0, -20.0
