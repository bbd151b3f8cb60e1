"""Run-time parameters: the controller's `param` input vector, its layout, and what each entry replaces.

The spec's `parameters` section names the values the firmware may change; each becomes a slice of
`param` (SI units, the compiled value as default, an allowed range). Limits only narrow: a limit's
range is the compiled envelope, and a limit the compiled controller does not have (infinite) has
no entry, so the structure of the bounds (which rows exist, which sides are finite) is the
compiled one. A set of values is checked as a whole (`ParameterLayout.check`): every entry finite
and in range, and each interval's min below its max.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..limits.naming import joint_unit
from ..robot.model import JointLimits, Robot
from ..spec import Spec
from ..spec.parameters import ParametersSpec
from ..tasks import Task
from ..tasks.base import TaskParameters, unit_text

GAIN_RANGES = {"kp": (0.0, 1e8, "1/s²"), "kd": (0.0, 1e5, "1/s")}
MAX_VELOCITY_RANGE = (0.0, 1e3)
REFERENCE_RANGE = {"position": 1e3, "rpy": 1e4, "q": 1e4}  # as the spec's LENGTH and JOINT_VALUE
# A one-sided Cartesian bound's offset may move this far (m) on its open side.
FAR = 1e3


class ParameterError(ValueError):
    """A parameter set that is refused: `field` names the entry (as in the layout)."""

    def __init__(self, field: str, message: str):
        super().__init__(f"{field}: {message}")
        self.field = field


def exact(value: float) -> str:
    """`value` short (%g) where that is the number, else in full: a refused 100.0000001 is not
    shown as the bound 100 it exceeds."""
    short = f"{value:g}"
    return short if float(short) == value else repr(float(value))


@dataclass(frozen=True)
class ParameterInput:
    """A slice of the run-time parameter vector `param`."""

    name: str  # task.kp, joint_torque.max, cartesian.tool.z.min, ...
    c_name: str  # the C struct's field
    offset: int
    size: int
    unit: str
    components: tuple[str, ...]
    default: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    lower_open: bool = False  # the value must exceed `lower` (a velocity limit)
    periodic: bool = False  # angles of period 2π (roll, pitch, yaw): a ramp takes the short way round

    def to_dict(self) -> dict:
        return {"name": self.name, "c_name": self.c_name, "offset": self.offset, "size": self.size, "unit": self.unit,
                "components": list(self.components), "default": list(self.default), "lower": list(self.lower),
                "upper": list(self.upper), "lower_open": self.lower_open, "periodic": self.periodic}

    @staticmethod
    def from_dict(d: dict) -> "ParameterInput":
        return ParameterInput(d["name"], d["c_name"], d["offset"], d["size"], d["unit"], tuple(d["components"]),
                              tuple(d["default"]), tuple(d["lower"]), tuple(d["upper"]), bool(d["lower_open"]),
                              bool(d.get("periodic", False)))

    @property
    def slice(self) -> slice:
        return slice(self.offset, self.offset + self.size)


@dataclass(frozen=True)
class ParameterLayout:
    """The entries of `param`, the intervals whose min must stay below their max (flat indices),
    the ramp time, and which entry holds each joint's torque limit (-1: the compiled one)."""

    entries: tuple[ParameterInput, ...] = ()
    order: tuple[tuple[int, int], ...] = ()
    ramp_time: float = 0.0
    torque_index: tuple[int, ...] = ()

    @property
    def size(self) -> int:
        return sum(e.size for e in self.entries)

    @property
    def defaults(self) -> np.ndarray:
        return np.array([v for e in self.entries for v in e.default], dtype=float)

    @property
    def periodic(self) -> np.ndarray:
        """Per value: is it an angle of period 2π (see ParameterInput.periodic)?"""
        return np.array([e.periodic for e in self.entries for _ in range(e.size)], dtype=bool)

    def entry(self, name: str) -> ParameterInput:
        for e in self.entries:
            if e.name == name:
                return e
        known = ", ".join(e.name for e in self.entries) or "none"
        raise ParameterError(name, f"no such run-time parameter; this controller has: {known}")

    def check(self, values: np.ndarray) -> None:
        """Raise ParameterError naming the first entry that is not finite, out of its range, or
        (an interval's max) not above its min."""
        values = np.asarray(values, dtype=float).reshape(-1)
        if values.size != self.size:
            raise ParameterError("param", f"{values.size} values for {self.size} parameters")
        for e in self.entries:
            for k in range(e.size):
                v, lo, hi = values[e.offset + k], e.lower[k], e.upper[k]
                where = f" ({e.components[k]})" if e.size > 1 else ""
                if not np.isfinite(v):
                    raise ParameterError(e.name, f"{v}{where} is not finite")
                if v < lo or (e.lower_open and v == lo) or v > hi:
                    side = "(" if e.lower_open else "["
                    value = f"{exact(v)} {e.unit}" if e.unit else exact(v)
                    raise ParameterError(e.name, f"{value}{where} is outside {side}{exact(lo)}, {exact(hi)}]"
                                         + (" (the compiled envelope)" if _is_limit(e) else ""))
        for i, j in self.order:
            if not values[i] < values[j]:
                upper = self._owner(j)
                raise ParameterError(upper.name, f"{exact(values[j])} must be above the matching min {exact(values[i])}")

    def vector(self, values: dict | np.ndarray, base: np.ndarray | None = None) -> np.ndarray:
        """A full parameter vector: `values` as a vector, or a dict {name: value(s)} applied over
        `base` (default: the compiled values). Not checked (see `check`)."""
        if not isinstance(values, dict):
            out = np.asarray(values, dtype=float).reshape(-1).copy()
            if out.size != self.size:
                raise ParameterError("param", f"{out.size} values for {self.size} parameters")
            return out
        out = (self.defaults if base is None else np.asarray(base, dtype=float)).copy()
        for name, value in values.items():
            e = self.entry(name)
            if any(isinstance(x, (bool, np.bool_)) for x in np.ravel(np.asarray(value, dtype=object))):
                raise ParameterError(name, f"{value!r} is not a number (as in a spec, true/false are not 1/0)")
            v = np.asarray(value, dtype=float).reshape(-1)
            if v.size not in (1, e.size):
                raise ParameterError(name, f"{v.size} values; it takes {e.size} ({', '.join(e.components)}) or one for all")
            out[e.slice] = v
        return out

    def as_dict(self, values: np.ndarray) -> dict[str, list[float]]:
        return {e.name: [float(v) for v in values[e.slice]] for e in self.entries}

    def _owner(self, index: int) -> ParameterInput:
        return next(e for e in self.entries if e.offset <= index < e.offset + e.size)

    def to_dict(self) -> dict:
        return {"entries": [e.to_dict() for e in self.entries], "order": [list(p) for p in self.order],
                "ramp_time": self.ramp_time, "torque_index": list(self.torque_index)}

    @staticmethod
    def from_dict(d: dict | None, n: int) -> "ParameterLayout":
        if not d:
            return ParameterLayout(torque_index=(-1,) * n)
        return ParameterLayout(tuple(ParameterInput.from_dict(e) for e in d["entries"]),
                               tuple((int(i), int(j)) for i, j in d["order"]), float(d["ramp_time"]),
                               tuple(int(i) for i in d["torque_index"]))


def _is_limit(e: ParameterInput) -> bool:
    return e.name.startswith(("joint_", "cartesian."))


# The joint limit each run-time limit entry replaces (a JointLimits field).
_JOINT_LIMIT_ENTRIES = {"joint_position.min": "q_min", "joint_position.max": "q_max",
                        "joint_velocity.max": "v_max", "joint_acceleration.max": "a_max",
                        "joint_torque.max": "tau_max"}


def cartesian_labels(robot: Robot) -> list[str]:
    """The run-time parameter label of each Cartesian bound, `frame.axis` (an index appended to a
    repeated one)."""
    labels: list[str] = []
    for i, bound in enumerate(robot.cartesian_bounds):
        label = f"{bound.frame}.{bound.label}"
        labels.append(label if label not in labels else f"{label}{i}")
    return labels


@dataclass(frozen=True)
class LimitsInForce:
    """The limits each sample of a run was held to: the compiled ones where no run-time parameter
    narrowed them. `joint`'s arrays are (samples, joints); `c_min`, `c_max` (samples, Cartesian
    bounds)."""

    joint: JointLimits
    c_min: np.ndarray
    c_max: np.ndarray


def limits_in_force(layout: ParameterLayout, values: np.ndarray, robot: Robot) -> LimitsInForce:
    """The limits at each sample of `values` (samples, layout.size): the run-time parameters as the
    controller applied them (ramps included)."""
    samples = len(values)
    compiled = robot.limits
    joint = {key: np.tile(getattr(compiled, key), (samples, 1)) for key in _JOINT_LIMIT_ENTRIES.values()}
    bounds = robot.cartesian_bounds
    c_min = np.tile(np.array([b.c_min for b in bounds], dtype=float), (samples, 1))
    c_max = np.tile(np.array([b.c_max for b in bounds], dtype=float), (samples, 1))
    joints = {name: j for j, name in enumerate(robot.joint_names)}
    labels = {label: i for i, label in enumerate(cartesian_labels(robot))}
    for e in layout.entries:
        if e.name in _JOINT_LIMIT_ENTRIES:
            target = joint[_JOINT_LIMIT_ENTRIES[e.name]]
            for k, name in enumerate(e.components):
                target[:, joints[name]] = values[:, e.offset + k]
        elif e.name.startswith("cartesian."):
            target = c_min if e.name.endswith(".min") else c_max
            target[:, labels[e.components[0]]] = values[:, e.offset]
    return LimitsInForce(JointLimits(**joint), c_min, c_max)


@dataclass
class ParameterSymbols:
    """The `param` input, its layout, and the symbolic values that replace compiled ones."""

    param: ca.SX
    layout: ParameterLayout
    tasks: dict[str, TaskParameters] = field(default_factory=dict)
    activation: dict[str, ca.SX] = field(default_factory=dict)  # task name -> a in [0, 1]
    joint: dict[str, list] = field(default_factory=dict)  # q_min, q_max, v_max, a_max, tau_max -> per joint
    cartesian: list[tuple] = field(default_factory=list)  # per bound: (c_min, c_max)


def c_identifier(text: str) -> str:
    return re.sub(r"\W", "_", text)


class _Builder:
    """Collects entries; `take` returns the symbols of the entry it adds."""

    def __init__(self):
        self.entries: list[ParameterInput] = []
        self.order: list[tuple[int, int]] = []
        self.size = 0
        self._symbols: list[ca.SX] = []

    def take(self, name: str, unit: str, components, default, lower, upper, lower_open: bool = False,
             periodic: bool = False) -> ca.SX:
        size = len(default)
        symbol = ca.SX.sym(c_identifier(name), size)
        self.entries.append(ParameterInput(name, c_identifier(name), self.size, size, unit, tuple(components),
                                           tuple(float(v) for v in default), tuple(float(v) for v in lower),
                                           tuple(float(v) for v in upper), lower_open, periodic))
        self._symbols.append(symbol)
        self.size += size
        return symbol

    def vector(self) -> ca.SX:
        return ca.vertcat(*self._symbols) if self._symbols else ca.SX(0, 1)


def _task_parameters(b: _Builder, task: Task, fields: tuple[str, ...]) -> tuple[TaskParameters, ca.SX | None]:
    m, axes = task.dim, tuple(r.split(".")[-1] for r in task.row_names)
    values = TaskParameters()
    for gain in ("kp", "kd"):
        if gain in fields:
            lo, hi, unit = GAIN_RANGES[gain]
            default = getattr(task, gain)
            setattr(values, gain, b.take(f"{task.name}.{gain}", unit, axes, default, [lo] * m, [hi] * m))
    if "max_velocity" in fields:
        lo, hi = MAX_VELOCITY_RANGE
        values.max_velocity = b.take(f"{task.name}.max_velocity", unit_text(task.row_units, "/s"), ("norm",),
                                     [task.max_velocity], [lo], [hi], True)
    if "reference" in fields:
        for key, value in task.constant_reference().items():
            unit, components = next((u, c) for f, _, u, c in task.reference_fields() if f == key)
            r = REFERENCE_RANGE[key]
            values.reference[key] = b.take(f"{task.name}.{key}", unit, components, value, [-r] * len(value),
                                           [r] * len(value), periodic=key == "rpy")
    activation = None
    if "activation" in fields:
        activation = b.take(f"{task.name}.activation", "", ("a",), [1.0], [0.0], [1.0])
    return values, activation


def build_parameters(spec: Spec, robot: Robot, tasks: list[Task]) -> ParameterSymbols:
    """The `param` vector of a validated spec (empty without a `parameters` section)."""
    settings = spec.parameters or ParametersSpec()
    n, lim, names = robot.nv, robot.limits, robot.joint_names
    b = _Builder()
    out = ParameterSymbols(ca.SX(0, 1), ParameterLayout())
    for task in tasks:
        fields = settings.task_fields(task.name)
        if fields:
            out.tasks[task.name], activation = _task_parameters(b, task, fields)
            if activation is not None:
                out.activation[task.name] = activation
    units = [joint_unit(robot, j) for j in range(n)]
    groups = settings.limit_groups()
    torque_index = [-1] * n
    if "joint_position" in groups:
        q_min, q_max = list(lim.q_min), list(lim.q_max)
        low = np.where(np.isfinite(lim.q_min), lim.q_min, -REFERENCE_RANGE["q"])
        high = np.where(np.isfinite(lim.q_max), lim.q_max, REFERENCE_RANGE["q"])
        starts = {}
        for side, compiled, target in (("min", lim.q_min, q_min), ("max", lim.q_max, q_max)):
            kept = [j for j in range(n) if np.isfinite(compiled[j])]
            if not kept:
                continue
            symbol = b.take(f"joint_position.{side}", unit_text(tuple(units[j] for j in kept)),
                            [names[j] for j in kept], compiled[kept], low[kept], high[kept])
            starts[side] = {j: b.size - len(kept) + k for k, j in enumerate(kept)}
            for k, j in enumerate(kept):
                target[j] = symbol[k]
        for j in set(starts.get("min", {})) & set(starts.get("max", {})):
            b.order.append((starts["min"][j], starts["max"][j]))
        out.joint.update(q_min=q_min, q_max=q_max)
    for group, key, suffix in (("joint_velocity", "v_max", "/s"), ("joint_acceleration", "a_max", "/s²"),
                               ("joint_torque", "tau_max", "")):
        if group not in groups:
            continue
        compiled = getattr(lim, key)
        joint_units = [("Nm" if u == "rad" else "N") if group == "joint_torque" else u + suffix for u in units]
        kept = [j for j in range(n) if np.isfinite(compiled[j])]
        # (0, compiled]: narrowing only
        symbol = b.take(f"{group}.max", unit_text(tuple(joint_units[j] for j in kept)), [names[j] for j in kept],
                        compiled[kept], [0.0] * len(kept), compiled[kept], True)
        values = list(compiled)
        for k, j in enumerate(kept):
            values[j] = symbol[k]
            if group == "joint_torque":
                torque_index[j] = b.size - len(kept) + k
        out.joint[key] = values
    if "cartesian" in groups:
        for bound, label in zip(robot.cartesian_bounds, cartesian_labels(robot), strict=True):
            low = bound.c_min if np.isfinite(bound.c_min) else -FAR
            high = bound.c_max if np.isfinite(bound.c_max) else FAR
            sides, index = [], {}
            for side, value in (("min", bound.c_min), ("max", bound.c_max)):
                if not np.isfinite(value):
                    sides.append(value)
                    continue
                sides.append(b.take(f"cartesian.{label}.{side}", "m", (label,), [value], [low], [high])[0])
                index[side] = b.size - 1
            if len(index) == 2:
                b.order.append((index["min"], index["max"]))
            out.cartesian.append(tuple(sides))
    out.param = b.vector()
    out.layout = ParameterLayout(tuple(b.entries), tuple(b.order), settings.ramp(spec.controller.period),
                                 tuple(torque_index))
    return out


def torque_limit(symbols: ParameterSymbols, compiled: np.ndarray) -> ca.SX:
    """|τ| ≤ this: the run-time torque limits where there are, the compiled ones elsewhere."""
    values = symbols.joint.get("tau_max")
    if values is None:
        return ca.SX(ca.DM(compiled))
    return ca.vertcat(*[v if isinstance(v, ca.SX) else ca.SX(float(v)) for v in values])
