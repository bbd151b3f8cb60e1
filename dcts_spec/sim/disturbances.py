"""External forces on the simulated robot: pushes at a point of a body and joint-torque profiles."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin

from .scenario import Scenario


@dataclass(frozen=True)
class _Push:
    body: int  # MuJoCo body; 0 (the world) for frames that do not move
    point: np.ndarray  # in the body frame (= the Pinocchio joint frame)
    force: np.ndarray
    torque: np.ndarray
    active: np.ndarray  # per substep

    def world_point(self, data: mujoco.MjData) -> np.ndarray:
        """Where the force acts, in world coordinates, at the current kinematics."""
        return data.xpos[self.body] + data.xmat[self.body].reshape(3, 3) @ self.point


class Disturbances:
    """Applies the scenario's disturbances before each MuJoCo substep.

    Joint torques go to `qfrc_applied` (precomputed per substep). Pushes go to `xfrc_applied`,
    which MuJoCo applies at the body's centre of mass: a force f at the point p needs the
    moment (p − c) × f added, with p and c from the current kinematics.
    """

    def __init__(self, scenario: Scenario, model: pin.Model, mj_model: mujoco.MjModel):
        times = np.arange(scenario.steps * scenario.substeps) * scenario.timestep
        self._joint_torque = None
        if scenario.torque_profiles:
            self._joint_torque = sum(np.outer(p.amplitude(times), p.torque) for p in scenario.torque_profiles)
        self._pushes = []
        for push in scenario.pushes:
            frame = model.frames[model.getFrameId(push.frame)]
            joint = frame.parentJoint
            body = 0 if joint == 0 else int(mj_model.jnt_bodyid[mj_model.joint(model.names[joint]).id])
            if body == 0:
                continue  # a frame fixed to the world: the robot does not feel the push
            active = (times >= push.start) & (times < push.end)
            self._pushes.append(_Push(body, frame.placement.act(push.point), push.force, push.torque, active))
        self._any_push = (np.any([p.active for p in self._pushes], axis=0) if self._pushes
                          else np.zeros(times.size, dtype=bool))
        self._pushing = False

    def apply(self, mj_model: mujoco.MjModel, data: mujoco.MjData, substep: int) -> None:
        """Set MuJoCo's applied forces for the substep about to run (needs the current qpos)."""
        if self._joint_torque is not None:
            data.qfrc_applied[:] = self._joint_torque[substep]
        if self._pushing:
            data.xfrc_applied[:] = 0.0
        self._pushing = bool(self._any_push[substep])
        if not self._pushing:
            return
        # After mj_step, xpos/xipos are those of the previous state: update them first.
        mujoco.mj_kinematics(mj_model, data)
        mujoco.mj_comPos(mj_model, data)
        for push in self._pushes:
            if push.active[substep]:
                lever = push.world_point(data) - data.xipos[push.body]
                data.xfrc_applied[push.body, :3] += push.force
                data.xfrc_applied[push.body, 3:] += push.torque + np.cross(lever, push.force)

    def generalized(self, mj_model: mujoco.MjModel, data: mujoco.MjData, substep: int, out: np.ndarray) -> None:
        """The joint torques the disturbances of `apply` exert (the true τ_ext), into `out`."""
        out[:] = data.qfrc_applied if self._joint_torque is not None else 0.0
        if not self._any_push[substep]:
            return
        for push in self._pushes:
            if push.active[substep]:
                mujoco.mj_applyFT(mj_model, data, push.force, push.torque, push.world_point(data), push.body, out)
