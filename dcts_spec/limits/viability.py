"""Acceleration bounds that keep a coordinate within its position and velocity bounds.

Implements the discrete-time method of A. Del Prete, "Joint Position and Velocity Bounds in
Discrete-Time Acceleration/Torque Control of Robot Manipulators", IEEE RA-L 3(1), 2018:
over one control period dt, with the acceleration a held constant,
  - position: the parabola x + dt ẋ + ½ dt² a stays inside [x_min, x_max] during the step
    (its apex too, when it falls inside the step);
  - velocity: |ẋ + dt a| ≤ v_max;
  - viability: from the next state the coordinate can still stop before its position bound
    braking at `braking` (x⁺ + ẋ⁺²/(2 braking) ≤ x_max), a quadratic inequality in a.
In a state that is no longer viable (too close to the bound for its speed, after a disturbance),
the apex term would ask for an unbounded deceleration; it is limited to stopping within the step
and heading back at the braking acceleration, so the joint stops at its bound instead of
bouncing off it. Beyond the bound, the end-of-step term brings it back. The position bounds are
then clamped into the velocity bounds (the velocity limit takes precedence: a joint beyond its
position bound heads back no faster than its velocity limit), and the result into ±`accel_limit`,
which gives way only to bring a state beyond its compiled envelope back (by up to the acceleration
that removes the excess in one period; the torque limits, through the QP's relaxation, decide how
much of it is met). Should lower and upper still cross (the position terms themselves conflict),
both become their midpoint so the QP stays feasible.
"""

from __future__ import annotations

import casadi as ca

from .base import STATE_TOLERANCE

# The state is symbolic in the controller and numeric in the tests; the bounds are then SX or DM.
# A limit is a number (±inf: none) or a run-time parameter (SX, always finite: it narrows a finite
# compiled limit), so which terms exist is decided when the controller is compiled.
Scalar = ca.SX | float
Bound = ca.SX | ca.DM


def _limited(value: Scalar) -> bool:
    return isinstance(value, ca.SX) or abs(value) != float("inf")

_TINY = 1e-12
# The velocity bound aims this fraction below the velocity limit. The bounds hold the acceleration
# over a period; a robot (and the simulator's rk4) holds the torque, and over the period M(q),
# ν(q, q̇) and g(q) move the acceleration: a joint coasting at its limit ends the period up to
# ~3e-5 of the limit beyond it with an acceleration limit of 10–25 rad/s² (Panda, iiwa14, UR5 with
# payloads, measured), ~6e-4 with none (a Panda commanding 2000 rad/s² in a step). The measured
# τ_ext takes that up one step late, not at once. 1e-3 of the limit is below what any user notices.
VELOCITY_MARGIN = 1e-3
# Beyond a bound, the position terms ask for absurd accelerations (~1/dt²); this keeps the QP
# data well scaled while still asking for far more than any robot can do.
_HUGE = 1e6


def _upper_from_position(x: Scalar, v: Scalar, x_max: Scalar, braking: Scalar, dt: float) -> Bound:
    """Largest a keeping x ≤ x_max during the step, apex of the parabola included."""
    end_of_step = 2.0 * (x_max - x - dt * v) / dt**2
    stop = -v / dt
    # Moving toward x_max (v > 0) and braking: the maximum is at t* = −v/a; inside the step
    # (a < −v/dt) it is x − v²/(2a), which must stay ≤ x_max. Too close for its speed (a state
    # that is no longer viable, after a disturbance or from the integration) this asks for
    # ~v²/(2·gap) → ∞: ask instead to stop within the step and head back at the braking
    # acceleration, so the coordinate stops at its bound rather than bouncing off it. Already
    # beyond x_max there is no apex to keep inside: the end of the step brings it back.
    apex = ca.fmax(-(v**2) / (2.0 * ca.fmax(x_max - x, _TINY)), stop - braking)
    inside_apex = ca.logic_and(ca.logic_and(v > 0, end_of_step < stop), x < x_max)
    return ca.if_else(inside_apex, apex, end_of_step)


def _upper_from_viability(x: Scalar, v: Scalar, x_max: Scalar, braking: Scalar, dt: float) -> Bound:
    """Largest a with which the next state x⁺ = x + dt v + ½dt² a, v⁺ = v + dt a can still stop
    before x_max braking at b *in steps of dt*: v⁺² + b dt v⁺ ≤ 2 b (x_max − x⁺), i.e.
    dt² a² + (2 dt v + 2 b dt²) a + v² + b dt v − 2 b (x_max − x − dt v) ≤ 0.

    The term b dt v⁺ is what braking in whole periods covers beyond the continuous v⁺²/(2b).
    Without it the coordinate reached its bound with a speed it could not shed in the last
    period without crossing mid-step, the apex term then braked at b and it bounced off: at an
    active limit the torque jumped 12 Nm every few tens of steps. With it the last braking step
    ends at rest, inside the bound."""
    qa = dt**2
    qb = 2.0 * dt * v + 2.0 * braking * dt**2
    qc = v**2 + braking * dt * v - 2.0 * braking * (x_max - x - dt * v)
    delta = qb**2 - 4.0 * qa * qc
    root = (-qb + ca.sqrt(ca.fmax(delta, 0.0))) / (2.0 * qa)
    stop = -v / dt
    # No real root: the state is not viable any more; the best is to stop within the step.
    return ca.fmax(ca.if_else(delta >= 0, root, stop), stop)


def _upper(x: Scalar, v: Scalar, x_max: Scalar, braking: Scalar, dt: float) -> Bound:
    return ca.fmin(_upper_from_position(x, v, x_max, braking, dt), _upper_from_viability(x, v, x_max, braking, dt))


def _overshoot(x: Scalar, v: Scalar, a: Bound, x_max: Scalar, dt: float) -> Bound:
    """How far x + v t + ½ a t² goes beyond x_max over t ∈ [0, dt] (negative: short of it)."""
    braking = ca.fmin(a, -_TINY)  # (a safe denominator; used only where a < 0)
    apex_inside = ca.logic_and(ca.logic_and(a < 0, v > 0), v < -a * dt)
    peak = ca.if_else(apex_inside, x - v**2 / (2.0 * braking), ca.fmax(x, x + dt * v + 0.5 * dt**2 * a))
    return peak - x_max


def state_excess(x: Scalar, v: Scalar, x_min: Scalar, x_max: Scalar, v_max: Scalar, lower: Bound, upper: Bound,
                 dt: float) -> Bound:
    """How far the state is beyond [x_min, x_max] or |v| ≤ v_max, in the coordinate's own units
    (the larger of the two; 0 within, and for a side without a limit), or may go beyond the
    position bounds during this period with an acceleration its bounds [lower, upper] allow. In a
    state that is no longer viable (too close to a bound for its speed, after a disturbance) the
    bounds take a weaker form: stopping within the step, or braking at the acceleration limit,
    which still crosses. A viable state's bounds keep the whole step within (the end-of-step and
    apex terms), so this is 0 in a closed loop that holds its bounds; without it such a step was
    "ok" and the bound crossed during it (a Panda's joint 7 0.1 mrad from its limit at 2.4 rad/s:
    1.2 mrad beyond it one step later; an iiwa14's joint 3 0.6 mrad from its limit at 0.8 rad/s
    under a 10 rad/s² acceleration limit)."""
    excess = ca.SX(0.0)
    for beyond, limited in ((_overshoot(x, v, upper, x_max, dt), _limited(x_max)),
                            (_overshoot(-x, -v, -lower, -x_min, dt), _limited(x_min)),
                            (ca.fabs(v) - v_max, _limited(v_max))):
        if limited:
            excess = ca.fmax(excess, beyond)
    return excess


def acceleration_bounds(
    x: Scalar, v: Scalar, x_min: Scalar, x_max: Scalar, v_max: Scalar, accel_limit: Scalar,
    braking: Scalar | tuple[Scalar, Scalar], dt: float, envelope: tuple[float, float, float] | None = None,
) -> tuple[Bound, Bound]:
    """(lower, upper) bounds on the acceleration of a coordinate for the next control period.

    x and v are the state (CasADi expressions or numbers); the limits are numbers, ±inf where
    there is none, or run-time parameters. `braking`: the deceleration the coordinate can count on
    (> 0), one value or (toward x_max, toward x_min), when it differs with the direction (a joint
    that gravity pulls one way). `envelope`: the compiled (x_min, x_max, v_max) that run-time
    parameters narrow (default: the limits themselves). The bounds are clipped to ±_HUGE, so they
    are finite even without any limit.
    """
    inf = float("inf")
    braking_down, braking_up = braking if isinstance(braking, tuple) else (braking, braking)
    upper = ca.SX(inf)
    lower = ca.SX(-inf)
    if _limited(x_max):
        upper = _upper(x, v, x_max, braking_down, dt)
    if _limited(x_min):
        lower = -_upper(-x, -v, -x_min, braking_up, dt)  # the mirror image x → −x
    if _limited(v_max):
        # The velocity bound comes first: the position terms are clamped into it, so a joint
        # beyond its position bound heads back at the velocity limit, not faster (as min/max
        # with a midpoint on conflict did: 3.6 × the velocity limit after a push). It aims
        # VELOCITY_MARGIN below the limit: see there.
        cap = (1.0 - VELOCITY_MARGIN) * v_max
        slowest, fastest = (-cap - v) / dt, (cap - v) / dt
        upper = ca.fmin(ca.fmax(upper, slowest), fastest)
        lower = ca.fmin(ca.fmax(lower, slowest), fastest)
    # Braking allowed beyond what the limits ask, by how far the state is beyond its compiled
    # envelope (of upper, of lower) by more than STATE_TOLERANCE: by up to Δv/dt + 2Δx/dt², the
    # acceleration that removes the excess in one period; 0 up to the tolerance, growing
    # continuously beyond it. Not within the tolerance, where the state counts as within its
    # limits (status "ok"): from 0 there, a Z1's wrist 3–7e-6 rad beyond its position limit was
    # commanded 28–39 rad/s² against a 25 rad/s² acceleration limit with status "ok" (2Δx/dt² is
    # 20 rad/s² at 1e-5 rad and 1 kHz; found from outside).
    low_env, high_env, v_env = envelope if envelope is not None else (x_min, x_max, v_max)
    give_down, give_up = ca.SX(0.0), ca.SX(0.0)
    if _limited(v_env):
        give_down += ca.fmax(v - v_env - STATE_TOLERANCE, 0.0) / dt
        give_up += ca.fmax(-v - v_env - STATE_TOLERANCE, 0.0) / dt
    if _limited(high_env):
        give_down += 2.0 * ca.fmax(x - high_env - STATE_TOLERANCE, 0.0) / dt**2
    if _limited(low_env):
        give_up += 2.0 * ca.fmax(low_env - x - STATE_TOLERANCE, 0.0) / dt**2
    if _limited(accel_limit):
        # The acceleration limit bounds the command, but gives way to the braking that takes the
        # state back within its compiled envelope (as little as the position and velocity terms
        # need; the torque limits decide the rest, through the relaxation). Capped at the limit,
        # the braking lost to any unmodelled acceleration beyond it: a 0.01 Nm bias in the
        # measured external torque of a light wrist (xArm7, 73 rad/s² against a 20 rad/s² limit)
        # ran it to 73 × its velocity limit, and a UR5's elbow stayed 3 rad beyond its position
        # limit 1.3 s after a push, braking at 15 of the 150 Nm it had. Within the envelope the
        # limit holds: a limit lowered at run time below the state is reached braking at it (given
        # way to, its one-period demand kicked an xArm7's torque by 1.4 × its limit, at a
        # parameter change the ramp is there to smooth).
        upper = ca.fmin(ca.fmax(upper, -accel_limit - give_down), accel_limit)
        lower = ca.fmax(ca.fmin(lower, accel_limit + give_up), -accel_limit)
        lower = ca.if_else(upper < -accel_limit, ca.fmin(lower, upper), lower)
        upper = ca.if_else(lower > accel_limit, ca.fmax(upper, lower), upper)
    elif envelope is not None and any(isinstance(limit, ca.SX) for limit in (x_min, x_max, v_max)):
        # No acceleration limit, but joint limits the firmware may narrow (a Cartesian bound has no
        # envelope here, and is as before): a state beyond a narrowed limit (within the envelope)
        # is brought back braking at `braking`, as under an
        # acceleration limit, not in one period: a position limit lowered 0.05 rad below an
        # iiwa14's joint 6 asked -3142 rad/s² (back at the velocity limit within the step) and
        # the torque jumped 123 Nm when the ramp landed. Within its limits a state brakes as hard
        # as the limits ask (a joint pushed toward its limit still stops at it).
        beyond_high, beyond_low = ca.SX(0.0), ca.SX(0.0)
        for high, low, value in ((x_max, x_min, x), (v_max, -v_max, v)):
            if _limited(high):
                beyond_high = ca.logic_or(beyond_high, value > high)
            if _limited(low):
                beyond_low = ca.logic_or(beyond_low, value < low)
        upper = ca.if_else(beyond_high, ca.fmax(upper, -braking_down - give_down), upper)
        lower = ca.if_else(beyond_low, ca.fmin(lower, braking_up + give_up), lower)
    upper = ca.fmin(ca.fmax(upper, -_HUGE), _HUGE)
    lower = ca.fmin(ca.fmax(lower, -_HUGE), _HUGE)
    middle = 0.5 * (lower + upper)
    conflict = lower > upper
    return ca.if_else(conflict, middle, lower), ca.if_else(conflict, middle, upper)
