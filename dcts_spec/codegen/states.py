"""Realistic controller inputs for golden vectors, agreement tests and benchmarks.

A state is (q, dq, tau_ext, ref): q inside the joint limits, moderate velocities, some external
torque, and references near what the task currently sees (its frame's pose or the posture), so
the QP is the one a running controller solves. A few kinds of states put limits in play
(joints near a bound moving toward it, large external torques), and `with_nonfinite` adds
NaN/Inf inputs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..controller import STATUS_LIMITS_RELAXED, STATUS_OK, Controller
from ..robot.model import prismatic_joints
from ..robot.resolve import PLACEHOLDER_SPEED
from ..tasks.cartesian import CartesianTask
from ..tasks.joint import JointTask

# Where a joint has no finite bound, sample q within ±π.
UNBOUNDED_RANGE = np.pi
CARTESIAN_TRIES = 200  # draws of q for one inside the Cartesian bounds, after which the last stands
# The golden vectors compare both paths of a step with bound rows: at least this many of their
# states end "ok" and this many "limits relaxed". Drawn alike for every robot, they did not: a
# URDF's placeholder velocity limits (iCub's 100 rad/s) made all 122 finite states relaxed, and
# the iiwa14's made 2 of 122 relaxed.
GOLDEN_PER_STATUS = 10
# The regular states' speeds, as a fraction of what StateSampler draws, tried in turn until
# GOLDEN_PER_STATUS of them are "ok"; after the first, their Cartesian bounds' frames inside them
# (a random q had an ANYmal's arm beyond its bound in every state). At rest, the last, only
# gravity and the tasks' errors remain.
GOLDEN_SPEEDS = (1.0, 0.25, 0.0625, 0.0)


@dataclass
class State:
    q: np.ndarray
    dq: np.ndarray
    tau_ext: np.ndarray
    ref: np.ndarray
    kind: str = "random"
    params: np.ndarray | None = None  # a run-time parameter set taken just before this state's step

    def as_tuple(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.q, self.dq, self.tau_ext, self.ref


class StateSampler:
    """Draws realistic states for one controller."""

    def __init__(self, controller: Controller, seed: int = 0, speed: float = 1.0, inside: bool = False):
        self.controller = controller
        self.rng = np.random.default_rng(seed)
        self.speed = speed  # scales the regular velocities (random_dq), not the limit cases' own
        self.inside = inside  # random states with the Cartesian bounds' frames inside them (`start`)
        robot = controller.robot
        lim = robot.limits
        n = controller.n
        self.n = n
        lo = np.where(np.isfinite(lim.q_min), lim.q_min, -UNBOUNDED_RANGE)
        hi = np.where(np.isfinite(lim.q_max), lim.q_max, UNBOUNDED_RANGE)
        self.q_lo, self.q_hi = lo, hi
        self.v_max = np.where(np.isfinite(lim.v_max), lim.v_max, 2.0)
        # the regular states' speeds: a placeholder limit (robot.resolve.PLACEHOLDER_SPEED) is no
        # joint's speed (Bolt's 1000 rad/s gave random states at 360 rad/s, whose 1e5 rad/s² terms
        # cancel into 60 Nm torques, where the runtimes part by their solvers' tolerance)
        plausible = np.where(prismatic_joints(robot.model), PLACEHOLDER_SPEED[True], PLACEHOLDER_SPEED[False])
        self.v_regular = np.minimum(self.v_max, plausible)
        self.tau_max = np.where(np.isfinite(lim.tau_max), lim.tau_max, 100.0)
        self.model = robot.model
        self.data = robot.model.createData()
        self.tasks = {t.name: t for level in controller.problem.levels for t in level.tasks}

    # -- pieces ----------------------------------------------------------------------------------

    def random_q(self, margin: float = 0.05) -> np.ndarray:
        span = self.q_hi - self.q_lo
        return self.rng.uniform(self.q_lo + margin * span, self.q_hi - margin * span)

    def random_dq(self, fraction: float = 0.25) -> np.ndarray:
        dq = self.rng.normal(0.0, fraction * self.v_regular) * self.speed
        return np.clip(dq, -0.8 * self.v_regular, 0.8 * self.v_regular)

    def random_tau_ext(self, scale: float = 2.0) -> np.ndarray:
        if self.rng.random() < 0.4:
            return np.zeros(self.n)
        return self.rng.normal(0.0, scale, self.n)

    def reference(self, q: np.ndarray) -> np.ndarray:
        """References near the tasks' current values at q (what a trajectory generator sends)."""
        ref = np.zeros(self.controller.ref_size)
        if not ref.size:
            return ref
        pin.framesForwardKinematics(self.model, self.data, q)
        for r in self.controller.ref_layout:
            task = self.tasks[r.task]
            sl = slice(r.offset, r.offset + r.size)
            if r.field == "position" and isinstance(task, CartesianTask):
                placement = self.data.oMf[self.model.getFrameId(task.frame)]
                ref[sl] = placement.translation + self.rng.normal(0.0, 0.03, 3)
            elif r.field == "rpy" and isinstance(task, CartesianTask):
                placement = self.data.oMf[self.model.getFrameId(task.frame)]
                ref[sl] = pin.rpy.matrixToRpy(placement.rotation) + self.rng.normal(0.0, 0.05, 3)
            elif r.field == "q" and isinstance(task, JointTask):
                ref[sl] = q[task.joint_indices] + self.rng.normal(0.0, 0.1, r.size)
            elif r.field == "acceleration":
                ref[sl] = self.rng.normal(0.0, 0.5, r.size)
            else:  # velocity feed-forward
                ref[sl] = self.rng.normal(0.0, 0.05, r.size)
        return ref

    # -- states ----------------------------------------------------------------------------------

    def random(self) -> State:
        q = self.random_q()
        for _ in range(CARTESIAN_TRIES if self.inside else 0):
            if self.inside_cartesian_bounds(q):
                break
            q = self.random_q()
        return State(q, self.random_dq(), self.random_tau_ext(), self.reference(q), "random")

    def inside_cartesian_bounds(self, q: np.ndarray) -> bool:
        """Are the frames of every Cartesian bound within it at q?"""
        bounds = self.controller.robot.cartesian_bounds
        if not bounds:
            return True
        pin.framesForwardKinematics(self.model, self.data, q)
        return all(b.c_min <= b.coordinate(self.data.oMf[self.model.getFrameId(b.frame)].translation) <= b.c_max
                   for b in bounds)

    def start(self) -> State:
        """A random state with the Cartesian bounds' frames inside them, where a motion starts (from
        outside, every step until the robot is back inside is a relaxed one); after CARTESIAN_TRIES
        draws, the last."""
        for _ in range(CARTESIAN_TRIES):
            state = self.random()
            if self.inside_cartesian_bounds(state.q):
                break
        return state

    def near_limit(self) -> State:
        """A joint close to a position bound and moving toward it: the limit rows bind."""
        q = self.random_q()
        dq = self.random_dq(0.1)
        j = int(self.rng.integers(self.n))
        span = self.q_hi[j] - self.q_lo[j]
        if self.rng.random() < 0.5:
            q[j] = self.q_hi[j] - self.rng.uniform(0.0, 0.03) * span
            dq[j] = self.rng.uniform(0.3, 0.9) * self.v_max[j]
        else:
            q[j] = self.q_lo[j] + self.rng.uniform(0.0, 0.03) * span
            dq[j] = -self.rng.uniform(0.3, 0.9) * self.v_max[j]
        return State(q, dq, self.random_tau_ext(), self.reference(q), "near_limit")

    def beyond_limit(self) -> State | None:
        """A joint already beyond its velocity limit, or its position limit, as after a push: the
        step cannot hold that bound, and the relaxed solve brings the joint back (None if no joint
        has a finite limit)."""
        lim = self.controller.robot.limits
        q, dq = self.random_q(), self.random_dq(0.1)
        velocity = np.flatnonzero(np.isfinite(lim.v_max))
        position = np.flatnonzero(np.isfinite(lim.q_min) & np.isfinite(lim.q_max))
        if not velocity.size and not position.size:
            return None
        side = self.rng.choice([-1.0, 1.0])
        if position.size and (not velocity.size or self.rng.random() < 0.5):
            j = int(self.rng.choice(position))
            span = self.q_hi[j] - self.q_lo[j]
            q[j] = (self.q_hi[j] if side > 0 else self.q_lo[j]) + side * self.rng.uniform(0.002, 0.02) * span
        else:
            j = int(self.rng.choice(velocity))
            dq[j] = side * self.rng.uniform(1.02, 1.3) * lim.v_max[j]
        return State(q, dq, self.random_tau_ext(), self.reference(q), "beyond_limit")

    def fast(self) -> State:
        """High joint velocities (velocity-limit rows bind)."""
        q = self.random_q()
        dq = self.rng.uniform(0.7, 0.98, self.n) * self.v_max * self.rng.choice([-1.0, 1.0], self.n)
        return State(q, dq, self.random_tau_ext(), self.reference(q), "fast")

    def heavy_load(self) -> State:
        """Large external torques (torque-limit rows bind)."""
        q = self.random_q()
        tau_ext = self.rng.uniform(0.3, 0.8, self.n) * self.tau_max * self.rng.choice([-1.0, 1.0], self.n)
        return State(q, self.random_dq(), tau_ext, self.reference(q), "heavy_load")

    def parameters(self) -> np.ndarray:
        """A valid run-time parameter set away from the compiled one: gains ×0.6–1.4, references
        moved by a few cm or hundredths of a rad, activations 0 or 0.5, every limit narrowed."""
        layout = self.controller.param_layout
        values = layout.defaults
        for e in layout.entries:
            kind = e.name.rsplit(".", 1)[-1]
            for k in range(e.size):
                d, lo, hi = e.default[k], e.lower[k], e.upper[k]
                if kind == "min":
                    v = d + self.rng.uniform(0.0, 0.2) * min(hi - d, 0.5)
                elif kind == "max" and e.lower_open:  # a magnitude: |dq|, |ddq|, |tau| ≤ it
                    v = d * self.rng.uniform(0.7, 1.0)
                elif kind == "max":
                    v = d - self.rng.uniform(0.0, 0.2) * min(d - lo, 0.5)
                elif kind == "activation":
                    v = float(self.rng.choice([0.0, 0.5]))
                elif kind in ("kp", "kd", "max_velocity"):
                    v = d * self.rng.uniform(0.6, 1.4)
                else:  # a reference
                    v = d + self.rng.normal(0.0, 0.03)
                values[e.offset + k] = np.clip(v, lo, hi)
        layout.check(values)
        return values

    def mixed(self, count: int, limit_fraction: float = 0.15) -> list[State]:
        """Mostly random states, a share of them with limits in play."""
        out = []
        for _ in range(count):
            u = self.rng.random()
            if u < limit_fraction / 3:
                out.append(self.near_limit())
            elif u < 2 * limit_fraction / 3:
                out.append(self.fast())
            elif u < limit_fraction:
                out.append(self.heavy_load())
            else:
                out.append(self.random())
        return out

    def nonfinite(self, base: State, which: int) -> State:
        """A copy of `base` with a NaN/Inf in one input (the kind cycles through q, dq, tau_ext, ref)."""
        q, dq, tau_ext, ref = (v.copy() for v in base.as_tuple())
        j = int(self.rng.integers(self.n))
        kind = which % 4
        if kind == 0:
            q[j] = np.nan
        elif kind == 1:
            dq[j] = np.inf
        elif kind == 2:
            tau_ext[j] = -np.inf
        elif ref.size:
            ref[int(self.rng.integers(ref.size))] = np.nan
        else:
            q[j] = -np.inf
            dq[(j + 1) % self.n] = np.nan
        return State(q, dq, tau_ext, ref, "nonfinite")


def statuses(controller: Controller, states: list[State]) -> np.ndarray:
    """The status of each state's step, each from a fresh controller with the compiled parameters."""
    out = np.zeros(len(states), dtype=int)
    for k, s in enumerate(states):
        controller.reset()
        controller.reset_params()
        out[k] = controller.step(s.q, s.dq, s.tau_ext, s.ref if controller.ref_size else None).status
    controller.reset()
    return out


def golden_states(controller: Controller, count: int = 120, seed: int = 0) -> list[State]:
    """The golden-vector inputs: regular and limit-active states, with a few non-finite ones;
    for a law with bound rows, GOLDEN_PER_STATUS of them "ok" and as many "limits relaxed" where
    the robot allows (the regular states slowed down, states beyond a limit added)."""
    for speed in GOLDEN_SPEEDS:
        sampler = StateSampler(controller, seed, speed, inside=speed < GOLDEN_SPEEDS[0])
        states = sampler.mixed(count - 10, limit_fraction=0.2)
        status = statuses(controller, states)
        if (status == STATUS_OK).sum() >= GOLDEN_PER_STATUS:
            break
    if controller.bound_names:
        missing = GOLDEN_PER_STATUS - int((status == STATUS_LIMITS_RELAXED).sum())
        beyond: list[State] = []
        for _ in range(3 * max(missing, 0)):  # (a bound may not be a row of this spec: try a few)
            if len(beyond) == missing:
                break
            state = sampler.beyond_limit()
            if state is None:
                break
            if statuses(controller, [state])[0] == STATUS_LIMITS_RELAXED:
                beyond.append(state)
        for k, state in enumerate(beyond):  # (spread over the sequence)
            states.insert((k + 1) * len(states) // (len(beyond) + 1), state)
    # Deterministic extras: limit cases, and non-finite inputs spread over the sequence (one
    # before any finite q was seen, so the fallback has no last gravity to use).
    extras = [sampler.near_limit(), sampler.near_limit(), sampler.fast(), sampler.heavy_load()]
    states[10:10] = extras
    for i, position in enumerate((0, 25, 60, 95)):
        base = states[min(position, len(states) - 1)]
        states.insert(position, sampler.nonfinite(base, i))
    if controller.param_size:
        # run-time parameter sets taken along the way (each ramped in over the next steps, one of
        # them across a non-finite input), and the compiled set again near the end
        for position in (20, 45, 58, 80):
            states[min(position, len(states) - 1)].params = sampler.parameters()
        states[min(105, len(states) - 1)].params = controller.param_layout.defaults
    return states


def trajectory_states(controller: Controller, count: int, seed: int = 0, episode: int = 1000,
                      step=None) -> list[State]:
    """States along closed-loop motions: the robot's forward dynamics under the controller's torque
    and the external torque, integrated over `controller.spec.controller.period` (semi-implicit
    Euler) from random starts inside the Cartesian bounds, with external torque pulses and, for
    run-time references, jumps. `step(q, dq, tau_ext, ref)` returns the StepResult (default: the
    Python runtime, which is slow; pass a compiled controller's step).
    """
    sampler = StateSampler(controller, seed)
    rng = sampler.rng
    dt = controller.spec.controller.period
    step = step or controller.step
    states: list[State] = []
    while len(states) < count:
        start = sampler.start()
        q, dq, ref = start.q, start.dq * 0.2, start.ref
        tau_ext = np.zeros(sampler.n)
        pulse_end = -1
        for k in range(min(episode, count - len(states))):
            if k == pulse_end:
                tau_ext = np.zeros(sampler.n)
            if rng.random() < 0.004:  # a push of 50–300 ms every quarter second on average
                tau_ext = rng.normal(0.0, 0.15, sampler.n) * sampler.tau_max
                pulse_end = k + int(rng.integers(50, 300))
            if ref.size and rng.random() < 0.002:
                ref = sampler.reference(q)
            states.append(State(q.copy(), dq.copy(), tau_ext.copy(), ref.copy(), "trajectory"))
            result = step(q, dq, tau_ext, ref if ref.size else None)
            ddq = pin.aba(sampler.model, sampler.data, q, dq, result.tau + tau_ext)  # the robot's response
            dq = np.clip(dq + dt * ddq, -sampler.v_max, sampler.v_max)
            q = np.clip(q + dt * dq, sampler.q_lo, sampler.q_hi)
    return states[:count]
