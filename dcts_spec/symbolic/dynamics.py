"""Rigid-body kinematics and dynamics of fixed-base arms as CasADi SX expressions.

Conventions follow Pinocchio: λ(i) is the parent of joint i and λMi = (R, p) places frame i in frame
λ(i) (x_λ = R x_i + p). A spatial motion is (ω, v) and a spatial force is (n, f), both taken at the
origin of the frame they are expressed in. Velocities, accelerations, inertias and forces of the
dynamics live in body frames, where the body inertias are numeric constants (M by the CRBA, ν, g and
τ by the RNEA); kinematic outputs are world-aligned.

The graph is kept lean for generated code: each λMi(q) is split into its numeric placement M0 and a
joint motion MJ(q) (rotation about / translation along a fixed axis), and both are applied one after
the other, so products with the numeric part fold into constants and CasADi drops every term with an
exact 0 or 1 factor.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Self

import casadi as ca
import numpy as np
import pinocchio as pin

# Geometry entries this close to 0 are round-off of a right angle (cos(π/2) = 6e-17, or 5e-12 for
# UR5's rpy 1.57079632679) and are made exact so that SX drops the terms: that saves 20-45 % of the
# operations and moves a placement by less than 1e-10 times a link length.
_ROUND_OFF = 1e-10

_ALIGNED_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}
_REVOLUTE = {f"JointModelR{k}": a for k, a in _ALIGNED_AXES.items()}
_PRISMATIC = {f"JointModelP{k}": a for k, a in _ALIGNED_AXES.items()}
_REVOLUTE_UNALIGNED = "JointModelRevoluteUnaligned"
_PRISMATIC_UNALIGNED = "JointModelPrismaticUnaligned"
_ALIGNED = {**_REVOLUTE, **_PRISMATIC}
_SUPPORTED = (*_REVOLUTE, _REVOLUTE_UNALIGNED, *_PRISMATIC, _PRISMATIC_UNALIGNED)


def _exact(a: np.ndarray) -> np.ndarray:
    """Numeric geometry with its round-off zeros made exact."""
    a = np.array(a, dtype=float)
    a[np.abs(a) < _ROUND_OFF] = 0.0
    return a


@dataclass(frozen=True)
class JointGeometry:
    """The numbers of a 1-dof joint i: its parent λ(i), its placement λMi at q = 0 (R0, p0), its
    axis in its own frame and whether it turns (else slides) about it; round-off zeros exact."""

    name: str
    parent: int
    idx_q: int
    idx_v: int
    rotation: np.ndarray  # R0 (3, 3)
    translation: np.ndarray  # p0 (3,)
    axis: np.ndarray  # (3,)
    revolute: bool

    @classmethod
    def of(cls, model: pin.Model, index: int) -> Self:
        jmodel = model.joints[index]
        kind = jmodel.shortname()
        name = model.names[index]
        if kind not in _SUPPORTED or jmodel.nq != 1 or jmodel.nv != 1:
            raise ValueError(
                f"joint {name!r} has unsupported type {kind} (nq={jmodel.nq}, nv={jmodel.nv}); "
                f"supported are 1-dof revolute and prismatic joints: {', '.join(_SUPPORTED)}"
            )
        if kind in (_REVOLUTE_UNALIGNED, _PRISMATIC_UNALIGNED):
            axis = np.asarray(jmodel.extract().axis, dtype=float)
        else:
            axis = np.array(_ALIGNED[kind])
        placement = model.jointPlacements[index]
        return cls(name, int(model.parents[index]), int(jmodel.idx_q), int(jmodel.idx_v),
                   _exact(placement.rotation), _exact(placement.translation), _exact(axis),
                   kind in _REVOLUTE or kind == _REVOLUTE_UNALIGNED)


def _zeros3() -> ca.SX:
    return ca.SX.zeros(3, 1)


def _axis_rotation(axis: np.ndarray, c: ca.SX, s: ca.SX) -> ca.SX:
    """exp([a]× θ) from c = cos θ, s = sin θ; explicit for ±e_k so its 0/1 entries stay exact."""
    nonzero = np.flatnonzero(axis)
    if nonzero.size == 1:
        k = int(nonzero[0])
        s = s if axis[k] > 0 else -s
        i, j = (k + 1) % 3, (k + 2) % 3
        rot = ca.SX.eye(3)
        rot[i, i] = c
        rot[j, j] = c
        rot[j, i] = s
        rot[i, j] = -s
        return rot
    # Rodrigues: R = c I + s [a]× + (1 - c) a aᵀ
    a = ca.SX(axis)
    return c * ca.SX.eye(3) + s * ca.skew(a) + (1 - c) * ca.mtimes(a, a.T)


def _rotate_symmetric(rot: ca.SX, sym: ca.SX) -> ca.SX:
    """R S Rᵀ for a symmetric S, built from its lower triangle so the result is exactly symmetric."""
    rs = ca.mtimes(rot, sym)
    out = ca.SX(3, 3)
    for i in range(3):
        for j in range(i + 1):
            out[i, j] = ca.dot(rs[i, :], rot[j, :])
            if j != i:
                out[j, i] = out[i, j]
    return out


@dataclass(frozen=True, slots=True)
class _Spatial:
    """A spatial motion (ω, v) or force (n, f) at the origin of its frame: `ang`, `lin` are (3, 1)."""

    ang: ca.SX
    lin: ca.SX

    @classmethod
    def zero(cls) -> Self:
        return cls(_zeros3(), _zeros3())

    def __add__(self, other: _Spatial) -> _Spatial:
        return _Spatial(self.ang + other.ang, self.lin + other.lin)

    def cross_motion(self, m: _Spatial) -> _Spatial:
        """Motion cross product self × m = (ω × ω', ω × v' + v × ω')."""
        return _Spatial(ca.cross(self.ang, m.ang), ca.cross(self.ang, m.lin) + ca.cross(self.lin, m.ang))


@dataclass(frozen=True, slots=True)
class _Inertia:
    """Spatial inertia about a frame origin: mass m, first moment h = m c, rotational inertia Ī (3x3).

    The form in which (symbolic) composite inertias of the CRBA add up and move between frames.
    """

    mass: float
    h: ca.SX
    rot: ca.SX

    @classmethod
    def from_pin(cls, inertia: pin.Inertia) -> Self:
        m, c = float(inertia.mass), np.asarray(inertia.lever)
        # parallel-axis theorem: Ī = I_c + m [c]×ᵀ[c]×
        rot = inertia.inertia + m * (c @ c * np.eye(3) - np.outer(c, c))
        return cls(m, ca.SX(m * c), ca.SX(rot))

    def __add__(self, other: _Inertia) -> _Inertia:
        return _Inertia(self.mass + other.mass, self.h + other.h, self.rot + other.rot)

    def momentum(self, m: _Spatial) -> _Spatial:
        """I m = (Ī ω + h × v, m v − h × ω)."""
        return _Spatial(
            ca.mtimes(self.rot, m.ang) + ca.cross(self.h, m.lin),
            self.mass * m.lin - ca.cross(self.h, m.ang),
        )

    def transformed(self, rot: ca.SX, p: ca.SX) -> _Inertia:
        """The same body seen from a frame in which this frame has rotation `rot` and origin `p`."""
        h = ca.mtimes(rot, self.h)
        h_new = h + self.mass * p
        ibar = _rotate_symmetric(rot, self.rot)
        # shift of the reference point by p: Ī' = Ī − [h]×[p]× − [p]×[h]× − m [p]×[p]×, i.e.
        # Ī'_ij = Ī_ij − h_i p_j − p_i h'_j off the diagonal, Ī'_ii = Ī_ii + Σ_k≠i p_k (h_k + h'_k)
        shift = [p[k] * (h[k] + h_new[k]) for k in range(3)]
        out = ca.SX(3, 3)
        for i in range(3):
            out[i, i] = ibar[i, i] + sum((shift[k] for k in range(3) if k != i), ca.SX(0))
            for j in range(i):
                out[i, j] = ibar[i, j] - h[i] * p[j] - p[i] * h_new[j]
                out[j, i] = out[i, j]
        return _Inertia(self.mass, h_new, out)


@dataclass(frozen=True, slots=True)
class _Body:
    """A body's inertia about its centre of mass c, in body axes: mass m and I_c, all numeric."""

    mass: float
    com: ca.SX
    inertia: ca.SX

    @classmethod
    def from_pin(cls, inertia: pin.Inertia) -> Self:
        return cls(float(inertia.mass), ca.SX(inertia.lever), ca.SX(inertia.inertia))

    def force(self, a: _Spatial, v: _Spatial | None = None) -> _Spatial:
        """I a + v ×* I v (I a when v is None), by Newton-Euler about the centre of mass: cheaper
        than the spatial form, as I_c is often diagonal and every product with c is numeric."""
        alpha = a.ang
        acc_com = a.lin + ca.cross(alpha, self.com)
        torque = ca.mtimes(self.inertia, alpha)
        if v is not None:
            omega = v.ang
            acc_com = acc_com + ca.cross(omega, v.lin + ca.cross(omega, self.com))
            torque = torque + ca.cross(omega, ca.mtimes(self.inertia, omega))
        force = self.mass * acc_com
        return _Spatial(torque + ca.cross(self.com, force), force)


class _Joint:
    """A 1-dof joint, λMi(q) = M0 · MJ(q): M0 = (R0, p0) numeric, MJ = (RJ, pJ) a rotation about or a
    translation along the joint axis (in frame i)."""

    def __init__(self, model: pin.Model, index: int, q: ca.SX) -> None:
        geometry = JointGeometry.of(model, index)
        self.name: str = geometry.name
        self.parent: int = geometry.parent
        self.idx_v: int = geometry.idx_v
        self.revolute: bool = geometry.revolute
        axis = geometry.axis
        self.axis: ca.SX = ca.SX(axis)
        self.r0: ca.SX = ca.SX(geometry.rotation)
        self.p0: ca.SX = ca.SX(geometry.translation)
        qi = q[geometry.idx_q]
        if self.revolute:
            self.rj: ca.SX = _axis_rotation(axis, ca.cos(qi), ca.sin(qi))
            self.pj: ca.SX = _zeros3()
        else:
            self.rj = ca.SX.eye(3)
            self.pj = self.axis * qi
        # λXi S = X0 S: the joint's own screw motion leaves its axis invariant
        axis_parent = ca.mtimes(self.r0, self.axis)
        self.subspace_in_parent: _Spatial = (
            _Spatial(axis_parent, ca.cross(self.p0, axis_parent))
            if self.revolute
            else _Spatial(_zeros3(), axis_parent)
        )

    def subspace(self, x: ca.SX | float) -> _Spatial:
        """S x: the joint's motion subspace in frame i, scaled by a joint rate x."""
        ax = self.axis * x
        return _Spatial(ax, _zeros3()) if self.revolute else _Spatial(_zeros3(), ax)

    def project(self, f: _Spatial) -> ca.SX:
        """Sᵀ f: the generalized force of a spatial force in frame i."""
        return ca.dot(self.axis, f.ang if self.revolute else f.lin)

    def motion_to_child(self, m: _Spatial) -> _Spatial:
        """iXλ m, through M0 then MJ: ω' = Rᵀ ω, v' = Rᵀ (v − p × ω)."""
        for rot, p in ((self.r0, self.p0), (self.rj, self.pj)):
            m = _Spatial(ca.mtimes(rot.T, m.ang), ca.mtimes(rot.T, m.lin - ca.cross(p, m.ang)))
        return m

    def force_to_parent(self, f: _Spatial) -> _Spatial:
        """λXi* f, through MJ then M0: f' = R f, n' = R n + p × f'."""
        for rot, p in ((self.rj, self.pj), (self.r0, self.p0)):
            lin = ca.mtimes(rot, f.lin)
            f = _Spatial(ca.mtimes(rot, f.ang) + ca.cross(p, lin), lin)
        return f

    def inertia_to_parent(self, inertia: _Inertia) -> _Inertia:
        """λXi* I iXλ: a (composite) body inertia seen from frame λ(i)."""
        return inertia.transformed(self.rj, self.pj).transformed(self.r0, self.p0)


class SymbolicRobot:
    """Rigid-body dynamics of a fixed-base pinocchio.Model as CasADi SX expressions of q and dq.

    Each quantity is built once, on first use, on top of shared passes (world placements, body
    velocities), so asking again or for several frames reuses the same graph; the returned
    expressions are therefore shared and must not be modified in place.
    """

    def __init__(self, model: pin.Model, q: ca.SX | None = None, dq: ca.SX | None = None) -> None:
        self.model = model
        self.nv: int = model.nv
        self.q: ca.SX = ca.SX.sym("q", model.nq) if q is None else q
        self.dq: ca.SX = ca.SX.sym("dq", model.nv) if dq is None else dq
        for name, x, n in (("q", self.q, model.nq), ("dq", self.dq, model.nv)):
            if x.shape != (n, 1):
                raise ValueError(f"{name} must be an SX of shape ({n}, 1), got {x.shape}")
        # keyed by Pinocchio joint index, in model order: parents come before their children
        self._joints: dict[int, _Joint] = {i: _Joint(model, i, self.q) for i in range(1, model.njoints)}
        self._bodies = [_Body.from_pin(model.inertias[i]) for i in range(model.njoints)]
        self._frame_placements: dict[int, tuple[ca.SX, ca.SX]] = {}
        self._jacobians: dict[int, ca.SX] = {}
        self._biases: dict[int, ca.SX] = {}

    # -- shared passes ---------------------------------------------------------------------------

    @cached_property
    def _world(self) -> list[tuple[ca.SX, ca.SX]]:
        """World placement (oRi, opi) of every joint frame, universe first: oMi = oMλ M0 MJ."""
        world = [(ca.SX.eye(3), _zeros3())]
        for joint in self._joints.values():
            r_parent, p_parent = world[joint.parent]
            r_pre = ca.mtimes(r_parent, joint.r0)
            world.append(
                (ca.mtimes(r_pre, joint.rj), p_parent + ca.mtimes(r_parent, joint.p0) + ca.mtimes(r_pre, joint.pj))
            )
        return world

    @cached_property
    def _motion(self) -> tuple[list[_Spatial], list[_Spatial]]:
        """Body velocities v_i and accelerations a_i at ddq = 0 without gravity, in body frames."""
        vel, acc = [_Spatial.zero()], [_Spatial.zero()]
        for joint in self._joints.values():
            s_dq = joint.subspace(self.dq[joint.idx_v])
            v = joint.motion_to_child(vel[joint.parent]) + s_dq
            vel.append(v)
            acc.append(joint.motion_to_child(acc[joint.parent]) + v.cross_motion(s_dq))
        return vel, acc

    def _backward(self, forces: list[_Spatial]) -> ca.SX:
        """Generalized forces of body forces, from the leaves: τ_i = Sᵢᵀ f_i, f_λ += λXi* f_i."""
        forces = list(forces)
        tau = ca.SX.zeros(self.nv, 1)
        for i, joint in reversed(self._joints.items()):
            tau[joint.idx_v] = joint.project(forces[i])
            if joint.parent > 0:
                forces[joint.parent] = forces[joint.parent] + joint.force_to_parent(forces[i])
        return tau

    def _static_rnea(self, ddq: ca.SX | None) -> ca.SX:
        """RNEA at dq = 0 with gravity: M ddq + g, or g alone when ddq is None."""
        gravity = self.model.gravity
        # the base accelerates upwards instead of gravity pulling every body down
        acc = [_Spatial(-ca.SX(gravity.angular), -ca.SX(gravity.linear))]
        for joint in self._joints.values():
            a = joint.motion_to_child(acc[joint.parent])
            acc.append(a if ddq is None else a + joint.subspace(ddq[joint.idx_v]))
        return self._backward([body.force(a) for body, a in zip(self._bodies, acc, strict=True)])

    def _frame_id(self, frame: str | int) -> int:
        fid = self.model.getFrameId(frame) if isinstance(frame, str) else int(frame)
        if not 0 <= fid < self.model.nframes:
            raise KeyError(f"model {self.model.name!r} has no frame {frame!r}")
        return fid

    # -- kinematics ------------------------------------------------------------------------------

    def frame_placement(self, frame: str | int) -> tuple[ca.SX, ca.SX]:
        """World position (3, 1) and rotation (3, 3) of a frame: oMf = oMi iMf."""
        fid = self._frame_id(frame)
        if fid not in self._frame_placements:
            f = self.model.frames[fid]
            r_joint, p_joint = self._world[f.parentJoint]
            self._frame_placements[fid] = (
                p_joint + ca.mtimes(r_joint, ca.SX(_exact(f.placement.translation))),
                ca.mtimes(r_joint, ca.SX(_exact(f.placement.rotation))),
            )
        return self._frame_placements[fid]

    def frame_jacobian(self, frame: str | int) -> ca.SX:
        """(6, nv) Jacobian of a frame, LOCAL_WORLD_ALIGNED: rows [velocity of its origin; ω], world axes."""
        fid = self._frame_id(frame)
        if fid not in self._jacobians:
            p_frame, _ = self.frame_placement(fid)
            jac = ca.SX(6, self.nv)
            i = self.model.frames[fid].parentJoint
            while i > 0:
                joint = self._joints[i]
                r_joint, p_joint = self._world[i]
                z = ca.mtimes(r_joint, joint.axis)  # joint axis in world axes
                if joint.revolute:
                    jac[:3, joint.idx_v] = ca.cross(z, p_frame - p_joint)
                    jac[3:, joint.idx_v] = z
                else:
                    jac[:3, joint.idx_v] = z
                i = joint.parent
            self._jacobians[fid] = jac
        return self._jacobians[fid]

    def frame_bias_acceleration(self, frame: str | int) -> ca.SX:
        """(6, 1) J̇ q̇ of frame_jacobian: classical acceleration of the frame origin (with ω × v) and
        angular acceleration at ddq = 0, in world axes."""
        fid = self._frame_id(frame)
        if fid not in self._biases:
            f = self.model.frames[fid]
            vel, acc = self._motion
            v, a = vel[f.parentJoint], acc[f.parentJoint]
            r_joint, _ = self._world[f.parentJoint]
            r = ca.SX(_exact(f.placement.translation))
            # spatial velocity and acceleration moved to the frame origin, then made classical
            v_lin = v.lin + ca.cross(v.ang, r)
            a_lin = a.lin + ca.cross(a.ang, r) + ca.cross(v.ang, v_lin)
            self._biases[fid] = ca.vertcat(ca.mtimes(r_joint, a_lin), ca.mtimes(r_joint, a.ang))
        return self._biases[fid]

    # -- dynamics --------------------------------------------------------------------------------

    @cached_property
    def _mass(self) -> ca.SX:
        mass = ca.SX(self.nv, self.nv)
        composite = [_Inertia.from_pin(inertia) for inertia in self.model.inertias]
        for i, joint in reversed(self._joints.items()):
            # the subtree of i is complete here: children have larger indices
            col = joint.idx_v
            mass[col, col] = joint.project(composite[i].momentum(joint.subspace(1.0)))
            if joint.parent == 0:
                continue
            moved = joint.inertia_to_parent(composite[i])
            composite[joint.parent] = composite[joint.parent] + moved
            # λXi* Ic_i S_i = (λXi* Ic_i iXλ)(λXi S_i), and λXi S_i is numeric
            force = moved.momentum(joint.subspace_in_parent)
            ancestor = self._joints[joint.parent]
            while True:
                mass[ancestor.idx_v, col] = ancestor.project(force)
                mass[col, ancestor.idx_v] = mass[ancestor.idx_v, col]
                if ancestor.parent == 0:
                    break
                force = ancestor.force_to_parent(force)
                ancestor = self._joints[ancestor.parent]
        return mass

    @cached_property
    def _nle(self) -> ca.SX:
        vel, acc = self._motion
        return self._backward([body.force(a, v) for body, v, a in zip(self._bodies, vel, acc, strict=True)])

    @cached_property
    def _gravity(self) -> ca.SX:
        return self._static_rnea(None)

    def mass_matrix(self) -> ca.SX:
        """Joint-space inertia matrix M(q), (nv, nv), exactly symmetric (CRBA in body frames)."""
        return self._mass

    def coriolis(self) -> ca.SX:
        """ν(q, dq) = C(q, dq) dq: nonlinear effects without gravity, (nv, 1) (RNEA at ddq = 0)."""
        return self._nle

    def gravity(self) -> ca.SX:
        """Generalized gravity g(q), (nv, 1), for model.gravity."""
        return self._gravity

    @cached_property
    def _gravity_rate(self) -> ca.SX:
        # first moments Σ m_b c_b of every subtree about the world origin, from the leaves
        mass = [float(inertia.mass) for inertia in self.model.inertias]
        moment = [_zeros3()] + [m * op + ca.mtimes(orot, ca.SX(m * np.asarray(self.model.inertias[i].lever)))
                                for i, (m, (orot, op)) in enumerate(zip(mass[1:], self._world[1:]), start=1)]
        for i, joint in reversed(self._joints.items()):
            if joint.parent > 0:
                moment[joint.parent] = moment[joint.parent] + moment[i]
                mass[joint.parent] += mass[i]
        rate = ca.SX.zeros(self.nv, 1)
        g = ca.SX(self.model.gravity.linear)
        for i, joint in self._joints.items():
            if joint.revolute:  # (a prismatic joint's own motion leaves its gravity force as it is)
                orot, op = self._world[i]
                axis = ca.mtimes(orot, joint.axis)
                arm = moment[i] - mass[i] * op  # the subtree's first moment about the joint's origin
                rate[joint.idx_v] = -ca.dot(axis, ca.cross(ca.cross(axis, arm), g))
        return rate

    @property
    def revolute(self) -> list[bool]:
        """Is joint j (in velocity order) revolute (else prismatic)?"""
        kinds = [False] * self.nv
        for joint in self._joints.values():
            kinds[joint.idx_v] = joint.revolute
        return kinds

    def gravity_rate(self) -> ca.SX:
        """∂g_j/∂q_j for each joint j, the other joints fixed, (nv, 1). Turning a revolute joint
        turns its subtree about the joint's axis, so its gravity torque is a sinusoid of zero mean:
        g_j(q_j + θ) = g_j cos θ + (∂g_j/∂q_j) sin θ; a prismatic joint's is constant (0 here)."""
        return self._gravity_rate

    def inverse_dynamics(self, ddq: ca.SX) -> ca.SX:
        """τ = M ddq + ν + g by RNEA; the velocity terms are those of coriolis(), since RNEA is
        affine in (ddq, gravity) once the velocities are fixed."""
        if ddq.shape != (self.nv, 1):
            raise ValueError(f"ddq must be an SX of shape ({self.nv}, 1), got {ddq.shape}")
        return self.coriolis() + self._static_rnea(ddq)
