"""The resolved robot: a Pinocchio model with the spec's frames, and the merged joint limits."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin


@dataclass(frozen=True)
class JointLimits:
    """Joint bounds in SI units, one entry per joint; ±inf where there is none."""

    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    tau_max: np.ndarray
    a_max: np.ndarray  # inf unless the spec gives joint accelerations
    # the position bounds assume braking at a_max (limits.joint_braking: "acceleration_limit"), or
    # less where the torque limit gives less ("torque_limited")
    torque_limited_braking: bool = False

    def unbounded(self, j: int) -> bool:
        """Has joint j no position limit on either side (a URDF continuous joint: robot/urdf.py)?"""
        return bool(np.isinf(self.q_min[j]) and np.isinf(self.q_max[j]))

    @staticmethod
    def of_model(model: pin.Model) -> "JointLimits":
        """The limits a URDF declares (Pinocchio stores 0 or a huge number where none is given).
        A joint whose lower and upper position limits are equal has none (`no_position_range`)."""
        n = model.nv
        none = no_position_range(model)

        def clean(values: np.ndarray, missing_if_zero: bool) -> np.ndarray:
            out = np.array(values, dtype=float)
            huge = np.abs(out) >= 1e10
            out[huge] = np.copysign(np.inf, out[huge])
            if missing_if_zero:
                out[out <= 0] = np.inf
            return out

        return JointLimits(
            q_min=np.where(none, -np.inf, clean(model.lowerPositionLimit, False)),
            q_max=np.where(none, np.inf, clean(model.upperPositionLimit, False)),
            v_max=clean(model.velocityLimit, True),
            tau_max=clean(model.effortLimit, True),
            a_max=np.full(n, np.inf),
        )


def no_position_range(model: pin.Model) -> np.ndarray:
    """Per joint: are its URDF position limits equal (a revolute joint whose <limit> gives only
    zeros, as example-robot-data's double pendulum)? Such a joint is meant to turn freely, as an
    effort or velocity of 0 means no limit; MuJoCo ignores such a range too. Read as [0, 0], it
    would be held still by its own position bound."""
    return np.asarray(model.lowerPositionLimit == model.upperPositionLimit, dtype=bool)


@dataclass(frozen=True)
class CartesianBound:
    """c_min ≤ dᵀ p_frame ≤ c_max: the frame origin between two planes of world normal d (a unit
    vector; a world axis for the paper's limited space, any direction for a tilted table)."""

    frame: str
    direction: tuple[float, float, float]
    label: str  # x, y, z, or plane<i> (the index in limits.cartesian)
    c_min: float  # -inf if none
    c_max: float  # +inf if none
    v_max: float  # inf if none
    a_max: float  # braking acceleration used by the viability bound

    @property
    def axis(self) -> int | None:
        """0, 1, 2 if the normal is the world x, y, z axis, else None."""
        return "xyz".index(self.label) if self.label in ("x", "y", "z") else None

    def coordinate(self, position: np.ndarray) -> np.ndarray:
        """dᵀp of positions (…, 3)."""
        return np.asarray(position) @ np.asarray(self.direction)


# Joints of several degrees of freedom by Pinocchio's name (validation asks to lock them)
_MULTI_DOF_KINDS = {"JointModelFreeFlyer": "floating", "JointModelPlanar": "planar", "JointModelSpherical": "spherical",
                    "JointModelSphericalZYX": "spherical"}


def multi_dof_kind(joint: pin.JointModel) -> str:
    """'floating', 'planar', 'spherical' (or Pinocchio's name) for a joint of several DOF."""
    return _MULTI_DOF_KINDS.get(joint.shortname(), joint.shortname())


def is_prismatic(joint: pin.JointModel) -> bool:
    """Does the joint translate (m, m/s, N) rather than rotate? From Pinocchio's joint model name
    (JointModelPZ, JointModelPrismaticUnaligned, … against JointModelRZ, …)."""
    return joint.shortname().removeprefix("JointModel").startswith("P")


def unit_of_kind(unit: str, prismatic: bool) -> str:
    """A revolute joint's unit (rad, rad/s, rad/s², Nm) as the joint's kind has it: m, m/s, m/s² and
    N for a prismatic joint."""
    if not prismatic:
        return unit
    return "N" if unit == "Nm" else unit.replace("rad", "m")


def prismatic_joints(model: pin.Model) -> np.ndarray:
    """Per joint of `model` (the order of q): does it translate?"""
    return np.array([is_prismatic(model.joints[j]) for j in range(1, model.njoints)], dtype=bool)


@dataclass
class Robot:
    """A fixed-base robot ready for the compiler: model, joint names, limits."""

    name: str
    model: pin.Model
    urdf_path: Path
    limits: JointLimits
    urdf_limits: JointLimits
    cartesian_bounds: tuple[CartesianBound, ...] = ()

    @property
    def nv(self) -> int:
        return self.model.nv

    @property
    def joint_names(self) -> list[str]:
        """Names of the (1-DOF) joints, in the order of q."""
        return [self.model.names[i] for i in range(1, self.model.njoints)]

    @property
    def prismatic(self) -> np.ndarray:
        """Per joint (the order of q): does it translate?"""
        return prismatic_joints(self.model)

    def has_frame(self, name: str) -> bool:
        return self.model.existFrame(name)

    def fixed_to_world(self, frame: str) -> bool:
        """Does no joint move `frame` (a frame of the base: a push or payload there acts on nothing)?"""
        return self.model.frames[self.model.getFrameId(frame)].parentJoint == 0

    def neutral_configuration(self) -> np.ndarray:
        """Middle of the joint range where it is finite, zero otherwise."""
        lo, hi = self.limits.q_min, self.limits.q_max
        finite = np.isfinite(lo) & np.isfinite(hi)
        return np.where(finite, 0.5 * (np.where(finite, lo, 0.0) + np.where(finite, hi, 0.0)), 0.0)
