"""Independent reference: the closed-form dynamically consistent hierarchy with Pinocchio and NumPy.

Nothing here uses dcts_spec's symbolic layer or formulations: task Jacobians, J̇q̇, errors and
dynamics come from Pinocchio's numeric algorithms, the hierarchy from NumPy pseudo-inverses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin


@dataclass
class NumericTask:
    """A task as the reference sees it: its own copy of the spec's meaning."""

    priority: int
    kind: str  # position | orientation | pose | joint
    kp: np.ndarray
    kd: np.ndarray
    frame: str | None = None
    rows: list[int] | None = None  # rows of [v; ω] (Cartesian)
    joints: list[int] | None = None  # joint indices (joint task)
    position: np.ndarray | None = None
    rotation: np.ndarray | None = None
    q: np.ndarray | None = None


def task_terms(model: pin.Model, data: pin.Data, task: NumericTask, q: np.ndarray, dq: np.ndarray):
    """J, J̇q̇ and the desired acceleration kp Δx − kd ẋ of one task."""
    n = model.nv
    if task.kind == "joint":
        J = np.zeros((len(task.joints), n))
        J[np.arange(len(task.joints)), task.joints] = 1.0
        error = np.zeros(len(task.joints)) if task.q is None else task.q - q[task.joints]
        bias = np.zeros(len(task.joints))
    else:
        fid = model.getFrameId(task.frame)
        J6 = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        bias6 = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector
        M = data.oMf[fid]
        error6 = np.zeros(6)
        if task.position is not None:
            error6[:3] = task.position - M.translation
        if task.rotation is not None:
            error6[3:] = pin.log3(task.rotation @ M.rotation.T)
        J, bias, error = J6[task.rows], bias6[task.rows], error6[task.rows]
    target = task.kp * error - task.kd * (J @ dq)
    return J, bias, target


def dynamics(model: pin.Model, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, ν (Coriolis/centrifugal) and g from Pinocchio."""
    data = model.createData()
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T  # crba fills the upper triangle only
    g = pin.computeGeneralizedGravity(model, data, q)
    nu = pin.rnea(model, data, q, dq, np.zeros(model.nv)) - g
    return M, nu, g


def closed_form_hierarchy(model: pin.Model, tasks: list[NumericTask], q, dq, tau_ext=None):
    """τ of the recursive dynamically consistent hierarchy (restricted Jacobians, pseudo-inverses).

    Returns (tau, actual acceleration a, levels) where levels = [(J, bias, target), ...] by priority.
    """
    n = model.nv
    tau_ext = np.zeros(n) if tau_ext is None else tau_ext
    data = model.createData()
    pin.forwardKinematics(model, data, q, dq, np.zeros(n))
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    M, nu, g = dynamics(model, q, dq)
    Minv = np.linalg.inv(M)
    levels = []
    for p in sorted({t.priority for t in tasks}):
        terms = [task_terms(model, data, t, q, dq) for t in tasks if t.priority == p]
        levels.append(tuple(np.concatenate(x) if x[0].ndim == 1 else np.vstack(x) for x in zip(*terms)))
    a = Minv @ (tau_ext - nu)
    N = np.eye(n)
    for J, bias, target in levels:
        Jr = J @ N
        Jbar = Minv @ Jr.T @ np.linalg.pinv(Jr @ Minv @ Jr.T, rcond=1e-10)
        a = a + Jbar @ (target - bias - J @ a)
        N = N - Jbar @ Jr
    tau = M @ a + nu + g - tau_ext
    return tau, a, levels
