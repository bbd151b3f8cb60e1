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
    axes: tuple[str, ...] | None = None  # Cartesian: x, y, z (world), rx, ry, rz (see orientation_terms)
    joints: list[int] | None = None  # joint indices (joint task)
    position: np.ndarray | None = None
    rotation: np.ndarray | None = None
    q: np.ndarray | None = None
    # joint task: which of its joints have no position limit (a URDF continuous joint), whose error
    # takes the short way round, in (−π, π]
    wrapped: tuple[bool, ...] | None = None


LINEAR = ("x", "y", "z")
OWN = {"rx": 0, "ry": 1, "rz": 2}


def orientation_terms(R: np.ndarray, R_d: np.ndarray | None, axes: tuple[str, ...]):
    """(B, error) of an orientation task, from Pinocchio's quaternions: the task velocity is Bᵀω.

    All three axes: world axes, log3(R_d Rᵀ). Two of the frame's own axes: the rotation that turns
    the free own axis onto the target's (Quaternion.FromTwoVectors), as a rotation vector, along
    the two. One own axis k: the twist 2 atan2(q_k, q_w) of Rᵀ R_d's quaternion, wrapped to ±π
    (its task velocity is ψ's own rate: `twist_terms`; B = R e_k serves a pure damping task)."""
    if len(axes) == 3:
        B = np.eye(3)[:, [OWN[a] for a in axes]]
        return B, np.zeros(3) if R_d is None else B.T @ pin.log3(R_d @ R.T)
    B = R[:, [OWN[a] for a in axes]]
    if R_d is None:
        return B, np.zeros(len(axes))
    if len(axes) == 2:
        (free,) = set(OWN) - set(axes)
        k = OWN[free]
        swing = pin.log3(pin.Quaternion.FromTwoVectors(R[:, k], R_d[:, k]).matrix())
        return B, B.T @ swing
    q = pin.Quaternion(R.T @ R_d)
    twist = 2.0 * np.arctan2(q.vec()[OWN[axes[0]]], q.w)
    return B, np.array([(twist + np.pi) % (2 * np.pi) - np.pi])


def twist(model: pin.Model, fid: int, R_d: np.ndarray, axis: str, q: np.ndarray) -> float:
    """The twist error of `orientation_terms` at q."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return float(orientation_terms(data.oMf[fid].rotation, R_d, (axis,))[1][0])


def twist_terms(model: pin.Model, fid: int, R_d: np.ndarray, axis: str, q: np.ndarray, dq: np.ndarray,
                h: float = 1e-4, t: float = 2e-4):
    """(J, J̇q̇, ψ) of a twist task by central differences of ψ(q), Richardson-extrapolated (steps
    h and h/2: error O(h⁴)): the task acceleration is d²/dt² of −ψ, J = −∂ψ/∂q and J̇q̇ =
    −d²ψ(q + t q̇)/dt² at t = 0 (revolute joints: q adds). (A plain second difference at t = 1e-4
    was 3e-4 off a J̇q̇ of 193 rad/s² on a UR3 whose tool swung far from its target: a "miss" of
    4e-5 that was the reference's; found from outside.)"""
    psi = twist(model, fid, R_d, axis, q)

    def gradient(step: float) -> np.ndarray:
        return np.array([-(twist(model, fid, R_d, axis, q + step * e) - twist(model, fid, R_d, axis, q - step * e))
                         / (2 * step) for e in np.eye(model.nv)])

    def curvature(step: float) -> float:
        return -(twist(model, fid, R_d, axis, q + step * dq) - 2 * psi + twist(model, fid, R_d, axis, q - step * dq)) / step**2

    J = (4.0 * gradient(h / 2) - gradient(h)) / 3.0
    bias = (4.0 * curvature(t / 2) - curvature(t)) / 3.0
    return J, bias, psi


def task_terms(model: pin.Model, data: pin.Data, task: NumericTask, q: np.ndarray, dq: np.ndarray):
    """J, J̇q̇ and the desired acceleration kp Δx − kd ẋ of one task."""
    n = model.nv
    if task.kind == "joint":
        J = np.zeros((len(task.joints), n))
        J[np.arange(len(task.joints)), task.joints] = 1.0
        error = np.zeros(len(task.joints)) if task.q is None else task.q - q[task.joints]
        if task.wrapped is not None:
            error = np.where(task.wrapped, np.angle(np.exp(1j * error)), error)
        bias = np.zeros(len(task.joints))
    else:
        fid = model.getFrameId(task.frame)
        J6 = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        bias6 = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector
        M = data.oMf[fid]
        rows = []
        for axis in task.axes:
            if axis in LINEAR:
                k = LINEAR.index(axis)
                error = 0.0 if task.position is None else task.position[k] - M.translation[k]
                rows.append((J6[k], bias6[k], error))
        angular = tuple(a for a in task.axes if a not in LINEAR)
        if len(angular) == 1 and task.rotation is not None:
            rows.append(twist_terms(model, fid, task.rotation, angular[0], q, dq))
        elif angular:
            B, error = orientation_terms(M.rotation, task.rotation, angular)
            rows += [(b @ J6[3:], b @ bias6[3:], e) for b, e in zip(B.T, error)]
        order = [a for a in task.axes if a in LINEAR] + list(angular)
        rows = [rows[order.index(a)] for a in task.axes]
        J, bias, error = (np.array([r[i] for r in rows]) for i in range(3))
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
