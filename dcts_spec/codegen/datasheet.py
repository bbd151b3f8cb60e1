"""The prose of a bundle's header and README: a datasheet of the compiled controller.

Sizes, units and sign conventions, the reference layout with each entry's unit, every compiled
task gain and limit with its unit, statuses, the robot model and where timing is measured. Each
function returns text for one template marker (header lines start with " *").
"""

from __future__ import annotations

import textwrap

import numpy as np

from ..controller import Controller
from ..formulations.parameters import ParameterInput
from ..parameter_ramp import ramp_steps
from ..limits.joint import DEFAULT_BRAKING
from ..limits.naming import interval_text, joint_force_unit, joint_unit
from ..limits.viability import VELOCITY_MARGIN
from ..robot.collision import resolve_collision
from ..robot.resolve import locked_joints
from ..tasks import JointTask, Task
from ..tasks.base import unit_text
from .model import describe_changes

DIGITS = 6  # significant digits of the numbers in the header


def number(value: float) -> str:
    return f"{value:.{DIGITS}g}"


def fmt_list(values) -> str:
    return "[" + ", ".join(number(v) for v in values) + "]"


def table(rows: list[tuple[str, str]], indent: str = " *   ") -> str:
    width = max(len(a) for a, _ in rows) + 2
    return "\n".join(f"{indent}{a:<{width}}{b}".rstrip() for a, b in rows)


def columns(rows: list[list[str]], indent: str = " *   ") -> str:
    """Rows of cells, each column as wide as its widest cell."""
    widths = [max(len(row[k]) for row in rows) + 2 for k in range(len(rows[0]))]
    return "\n".join((indent + "".join(f"{c:<{w}}" for c, w in zip(row, widths))).rstrip() for row in rows)


def wrap(text: str, indent: str = " * ", width: int = 100, first: str | None = None) -> list[str]:
    """Comment lines of at most `width` characters (words are not broken); `first`: the first
    line's indent (a label), if not `indent`."""
    return textwrap.wrap(text, width, initial_indent=indent if first is None else first, subsequent_indent=indent,
                         break_long_words=False, break_on_hyphens=False)


def joint_units(controller: Controller) -> list[str]:
    """"rad" or "m" per joint, in the order of q."""
    return [joint_unit(controller.robot, j) for j in range(controller.n)]


def _tasks(controller: Controller) -> dict[str, Task]:
    return {t.name: t for level in controller.problem.levels for t in level.tasks}


# -- inputs and conventions ------------------------------------------------------------------------


def _per_joint(units: list[str], revolute: str, prismatic: str) -> str:
    """One unit for the robot's joints: the revolute or the prismatic one, or both for a mix."""
    if "m" not in units:
        return revolute
    if "rad" not in units:
        return prismatic
    return f"{revolute}, {prismatic} for a prismatic joint"


def parameters_text(controller: Controller, big: str) -> str:
    """The arguments of <name>_step."""
    n, nref = controller.n, controller.ref_size
    units = joint_units(controller)
    torque = _per_joint(units, "Nm", "N")
    ignored = " (ignored: external_torque is 'ignored')" if controller.spec.controller.external_torque != "measured" else ""
    return table([
        (f"q[{n}]", f"joint positions ({_per_joint(units, 'rad', 'm')})"),
        (f"dq[{n}]", f"joint velocities ({_per_joint(units, 'rad/s', 'm/s')})"),
        (f"tau_ext[{n}]", f"external joint torques ({torque}), see Conventions; NULL means zero{ignored}"),
        (f"ref[{nref}]", f"run-time references, layout below; may be NULL when {big}_NREF is 0"),
        (f"tau[{n}]", f"output: joint torques to apply ({torque}, gravity included), always finite and"),
        ("", f"within |tau| <= tau_max = {fmt_list(controller.tau_max)} {torque if ',' not in torque else f'({torque})'}"),
        ("info", "optional (may be NULL): commanded acceleration, task scalings, QP solution"),
    ])


def conventions_text(controller: Controller) -> str:
    """Units, signs and frames of the inputs and the output."""
    units = joint_units(controller)
    kinds = ", ".join(f"{name} {u}" for name, u in zip(controller.robot.joint_names, units))
    measured = controller.spec.controller.external_torque == "measured"
    return "\n".join([
        " *   Units      SI. Joints in the order of q, each in its own unit (prismatic: m, m/s, N):",
        *wrap(kinds, " *              "),
        " *   Signs      q, dq, tau and tau_ext are positive along the joint's axis in the URDF.",
        " *   tau        the whole joint torque to command: gravity, Coriolis and the tasks included",
        " *              (add nothing to it).",
        " *   tau_ext    the torque the environment applies on the joints (a contact, a hand pushing):",
        " *              M(q) ddq + nu(q, dq) + g(q) = tau + tau_ext, so pushing a link along +q gives",
        " *              tau_ext > 0, and a force F (N) at a frame gives tau_ext = J(q)^T F. From joint",
        " *              torque sensors: tau_ext = M(q) ddq + nu + g - tau_sensed (model minus measured).",
        (" *              The tasks and limits use it: an estimate's error acts as a disturbance."
         if measured else
         " *              Not used: the spec's external_torque is 'ignored' (the controller assumes 0)."),
        " *   Cartesian  positions, plane normals and offsets in the world frame (the URDF's root),",
        " *              m; orientations as roll, pitch, yaw in rad, R = Rz(yaw) Ry(pitch) Rx(roll).",
        f" *   Period     {controller.spec.controller.period:g} s: the limits are shaped for it; call the step at this rate.",
        *locked_text(controller),
        *payload_text(controller),
    ])


def payload_text(controller: Controller) -> list[str]:
    """The Conventions lines on the payloads the model carries (robot.payloads)."""
    payloads = controller.spec.robot.payloads
    if not payloads:
        return []
    listed = ", ".join(f"{p.mass:g} kg at {p.frame} (centre of mass {fmt_list(p.com)} m in it)" for p in payloads)
    return wrap(f"in the model, and in g(q): {listed}. Without them, or with another load, the difference acts "
                "as tau_ext: recompile with the load the robot carries.", " *              ", first=" *   Payloads   ")


def locked_text(controller: Controller) -> list[str]:
    """The Conventions lines on the locked joints: not in q, and held by the firmware."""
    locked = locked_joints(controller.spec)
    if not locked:
        return []
    listed = ", ".join(f"{name} at {value:g}" for name, value in locked.items())
    return wrap(f"not in q: hold them there yourself (the model has them fixed; rad or m): {listed}.",
                " *              ", first=" *   Locked     ")


def sizes_text(controller: Controller, levels: int, nr: int, npls: int, workspace_bytes: int) -> str:
    return (f"NQ {controller.n}, NREF {controller.ref_size}, NX {controller.nx}, NA {controller.na}, NLEVELS {levels}, "
            f"NR {nr}, NP {npls}; workspace {workspace_bytes} bytes")


# -- references ------------------------------------------------------------------------------------


def component_units(task: Task, unit: str, size: int) -> list[str]:
    """The unit of each entry of a reference slice whose unit text is `unit` (tasks.base.unit_text):
    one unit for all, or, for a mix, per task row (m or rad) in the order unit_text lists them."""
    distinct = unit.split(", ")
    if len(distinct) == 1:
        return distinct * size
    order = list(dict.fromkeys(task.row_units))
    return [distinct[order.index(u)] for u in task.row_units]


def ref_layout_text(controller: Controller, big: str) -> tuple[str, str]:
    """The header's layout lines (each entry's unit) and the REF offset macros."""
    layout = controller.ref_layout
    if not layout:
        return " *   (empty: every reference is a constant of the spec)", "/* (none) */\n"
    tasks = _tasks(controller)
    lines, macros = [], []
    for r in layout:
        last = r.offset + r.size - 1
        span = f"ref[{r.offset}]" if r.size == 1 else f"ref[{r.offset}..{last}]"
        units = component_units(tasks[r.task], r.unit, r.size)
        if len(set(units)) == 1:
            what = f"{r.field} ({units[0]}): {', '.join(r.components)}"
        else:
            groups = {u: [c for c, cu in zip(r.components, units) if cu == u] for u in dict.fromkeys(units)}
            what = f"{r.field} ({'; '.join(f'{u}: ' + ', '.join(cs) for u, cs in groups.items())})"
        lines.append(f" *   {span:<14} task {r.task}, {what}")
        macro = "".join(c if c.isalnum() else "_" for c in f"{big}_REF_{r.task}_{r.field}").upper()
        macros.append(f"#define {macro} {r.offset} /* {r.size} values */")
    return "\n".join(lines), "\n".join(macros) + "\n"


# -- gains -----------------------------------------------------------------------------------------


def _values(values: np.ndarray) -> str:
    """One number when every axis has it, else one per axis."""
    values = np.asarray(values, dtype=float)
    return number(values[0]) if np.all(values == values[0]) else fmt_list(values)


def _task_subject(task: Task, kind: str) -> str:
    if isinstance(task, JointTask):
        return f"joint task on {', '.join(task.joint_names)}"
    rotation = [a for a in task.axes if a.startswith("r")]
    own = " (rotation axes: the frame's own)" if rotation and len(rotation) < 3 else ""
    return f"{kind} of frame {task.frame}, axes {', '.join(task.axes)}{own}"


def _task_reference(task: Task, controller: Controller) -> str:
    if task.reference_is_input:
        slices = [r for r in controller.ref_layout if r.task == task.name]
        first, last = slices[0].offset, slices[-1].offset + slices[-1].size - 1
        extra = ", with velocity and acceleration feed-forward" if task.feedforward else ""
        return f"run time, ref[{first}..{last}]{extra}"
    constant = task.constant_reference()
    if not constant:
        return "none (kp = 0: a pure damping task)"
    parts = []
    for key, values in constant.items():
        if key == "q":
            parts.append(f"q = {fmt_list(values)} {unit_text(task.row_units)}")
        elif key == "rpy":
            parts.append(f"rpy = {fmt_list(values)} rad (world)")
        else:
            parts.append(f"position = {fmt_list(values)} m (world)")
    return "compiled, " + ", ".join(parts)


def gains_text(controller: Controller) -> str:
    """Each task's compiled gains, saturation and reference."""
    tasks = _tasks(controller)
    lines = []
    for spec_task in controller.spec.tasks:
        task = tasks[spec_task.name]
        saturation, units = "none", unit_text(task.row_units, "/s")
        if task.max_velocity is not None and "," in units:
            saturation = f"{number(task.max_velocity)} (the norm of (kp/kd) dx over axes in {units.replace(', ', ' and ')})"
        elif task.max_velocity is not None:
            saturation = f"{number(task.max_velocity)} {units} (the norm of (kp/kd) dx)"
        lines += [
            f" *   {task.name}: priority {task.priority}, {_task_subject(task, spec_task.type)}",
            f" *     kp = {_values(task.kp)} 1/s², kd = {_values(task.kd)} 1/s, max_velocity = {saturation}",
            f" *     reference: {_task_reference(task, controller)}",
        ]
    return "\n".join(lines)


# -- limits ----------------------------------------------------------------------------------------

_ENFORCEMENT = {
    "osc": "osc does not keep them: it has no limits, its torque is only clipped to +-tau_max",
    "projector": "projector keeps the joint ones by saturation in the null space, not the Cartesian ones; "
                 "its torque is clipped to +-tau_max",
}
_QP_ENFORCEMENT = ("rows of the QP: each becomes a bound on the acceleration that lets the joint or frame "
                   "brake in time at the control period; |tau| <= tau_max is a hard row")


def _cell(value: float, unit: str) -> str:
    return f"{number(value)} {unit}" if np.isfinite(value) else "none"


def limits_text(controller: Controller) -> str:
    """The joint limits table, the Cartesian bounds, the collision pairs and which bound each
    entry of info->relaxed is."""
    lines = [_joint_and_cartesian_text(controller)]
    pairs = resolve_collision(controller.spec, controller.robot)[0].pairs
    if pairs:
        lines.append(" * Collision pairs (the distance between two bodies' primitives, m; braking in m/s²):")
        lines += [f" *   {_short(p.name)}: distance ≥ {number(p.min_distance)} m; braking at {number(p.braking)} m/s²"
                  for p in pairs]
    if controller.nx and controller.bound_names:  # (a closed form has no bound rows)
        order = ", ".join(f"{i}:{_short(name)}" for i, name in enumerate(controller.bound_names))
        lines += wrap(f"info->relaxed[i], one per joint, Cartesian and collision bound, in this order: {order}.")
    return "\n".join(lines)


def _short(row_name: str) -> str:
    """A bound row's name without its kind (joint1, tool.z, link7-ball), safe in a C comment (an
    obstacle's name is the spec's free text)."""
    return row_name.split(":", 1)[1].replace("*/", "*\\/")


def _joint_and_cartesian_text(controller: Controller) -> str:
    lim, names = controller.robot.limits, controller.robot.joint_names
    how = _ENFORCEMENT.get(controller.formulation, _QP_ENFORCEMENT)
    lines = wrap(f"Limits, compiled ({how}; none: no limit):")
    rows = [["joint", "q min", "q max", "|dq| max", "|ddq| max", "|tau| max"]]
    for j, (name, unit) in enumerate(zip(names, joint_units(controller))):
        torque = joint_force_unit(controller.robot, j)
        rows.append([name, _cell(lim.q_min[j], unit), _cell(lim.q_max[j], unit), _cell(lim.v_max[j], f"{unit}/s"),
                     _cell(lim.a_max[j], f"{unit}/s²"), _cell(controller.tau_max[j], torque)])
    lines.append(columns(rows))
    if how is _QP_ENFORCEMENT:
        nominal = "|ddq| max" if np.all(np.isfinite(lim.a_max)) else \
            f"|ddq| max ({number(DEFAULT_BRAKING)} rad/s² or m/s² where none)"
        torque = (", or at what its own torque limit gives on the way to the limit where that is less: "
                  "(|tau| max ± (nu + g)_j) / M_jj, g_j averaged over the way, the other joints still (a joint "
                  "gravity pulls toward its bound slows down earlier)"
                  if lim.torque_limited_braking else " (limits.joint_braking: torque_limited counts on no more than "
                  "the torque gives)")
        lines += wrap(f"The position bounds assume a joint brakes at {nominal}{torque}. The velocity bounds aim "
                      f"{number(100 * VELOCITY_MARGIN)} % below |dq| max: the torque is held over a period, not the "
                      "acceleration.", indent=" *   ")
    if np.isfinite(lim.a_max).any() and how is _QP_ENFORCEMENT:
        lines += wrap("|ddq| max bounds the command; a joint beyond its compiled position or velocity limit (after "
                      "a push) brakes back harder than that, as its torque limit allows.", indent=" *   ")
    bounds = controller.robot.cartesian_bounds
    if not bounds:
        lines.append(" * Cartesian bounds: none.")
        return "\n".join(lines)
    lines.append(" * Cartesian bounds (a frame's origin p between planes of unit normal d, world frame; m, m/s, m/s²):")
    given = controller.spec.limits.cartesian if len(controller.spec.limits.cartesian) == len(bounds) else [None] * len(bounds)
    for b, spec_bound in zip(bounds, given):
        axis = f" (world {b.label})" if b.axis is not None else ""
        speed = f"|d.v| ≤ {number(b.v_max)} m/s" if np.isfinite(b.v_max) else "speed: no limit"
        lines += [
            f" *   {b.frame}.{b.label}: frame {b.frame}, d = {fmt_list(b.direction)}{axis}",
            f" *     {interval_text('d.p', b.c_min, b.c_max, 'm', DIGITS)}; {speed}; braking at {number(b.a_max)} m/s²",
        ]
        if spec_bound is not None and spec_bound.expressed_in not in (None, "world"):
            given = f"axis {spec_bound.axis}" if spec_bound.axis is not None else f"normal {fmt_list(spec_bound.normal)}"
            lines.append(f" *     (the spec gives {given} in frame {spec_bound.expressed_in}: "
                         "d and the offsets above are that plane in the world)")
    return "\n".join(lines)


# -- run-time parameters ---------------------------------------------------------------------------


def _range(e: ParameterInput) -> str:
    lower = sorted(set(e.lower))
    upper = sorted(set(e.upper))
    if len(lower) == 1 and len(upper) == 1:
        return f"{'(' if e.lower_open else '['}{number(lower[0])}, {number(upper[0])}]"
    if e.name.startswith(("joint_", "cartesian.")):
        return "(0, compiled]" if e.lower_open else "within the compiled [min, max]"
    return "per component"


def parameters_doc_text(controller: Controller, name: str) -> str:
    """The run-time parameters: the API in short, and each field's unit, default and range."""
    layout = controller.param_layout
    if not layout.entries:
        return (" * Run-time parameters: none (the spec has no `parameters` section); the gains and limits\n"
                " * below are constants of the code.")
    period = controller.problem.period
    steps = ramp_steps(layout.ramp_time, period)
    duration = f"{number(steps * period)} s"
    if number(steps * period) != number(layout.ramp_time):  # (whole periods: a ramp_time of 2.5 periods takes 3)
        duration += f"; ramp_time {number(layout.ramp_time)} s in whole periods"
    lines = wrap(
        f"Run-time parameters ({name}_params, SI units; the compiled values are the defaults). "
        f"{name}_set_params checks a whole set and either takes it or keeps the old one, naming the wrong "
        f"field; a set taken is reached linearly over {steps} step(s) ({duration}), so a "
        "change makes no torque jump. Limits only narrow: each stays within its compiled value.")
    rows = [["field", "unit", "default", "range", "components"]]
    for e in layout.entries:
        field = e.c_name if e.size == 1 else f"{e.c_name}[{e.size}]"
        rows.append([field, e.unit or "-", _values(np.array(e.default)), _range(e),
                     " ".join(e.components) if e.size > 1 else ""])
    lines.append(columns(rows))
    if any(e.name.endswith(".activation") for e in layout.entries):
        lines += wrap("activation: 1 = the task as compiled; 0 = as if it were not in the spec (it neither moves "
                      "the robot nor takes directions from the levels below); in between the task applies that "
                      "fraction of its correction and leaves the rest of its directions to the levels below. (A lowest "
                      "level compiled as least squares stays so with the levels above off; where a bound binds, "
                      "it then differs from the spec without them.)")
    return "\n".join(lines)


def parameters_struct(controller: Controller, big: str) -> tuple[str, str]:
    """The fields of <name>_params and the field-index macros."""
    entries = controller.param_layout.entries
    if not entries:
        return "    double unused; /* no run-time parameters */", "/* (no run-time parameters) */"
    fields, macros = [], []
    for i, e in enumerate(entries):
        declaration = f"double {e.c_name}" + (f"[{e.size}]" if e.size > 1 else "") + ";"
        detail = e.unit + (f", {' '.join(e.components)}" if e.size > 1 else "")
        fields.append(f"    {declaration:<40} /* {detail.strip(', ') or 'unitless'} */")
        macros.append(f"#define {big}_PARAM_{e.c_name.upper()} {i}")
    return "\n".join(fields), "\n".join(macros)


# -- statuses, model, timing -----------------------------------------------------------------------


def status_text(name: str, big: str, takes_ref: bool, bound_rows: int, clips: bool, measured: bool) -> str:
    """The status table; `bound_rows`: the law's joint/Cartesian bound rows (none in a closed form),
    `clips`: its torque is clipped to the limits rather than bounded (osc, projector), `measured`:
    it reads tau_ext (controller.external_torque)."""
    if bound_rows:
        rows = [
            ("0", "OK", "every torque limit and joint/Cartesian bound holds (checked after the solve)"),
            ("1", "LIMITS_RELAXED", "a joint/Cartesian bound is crossed (those in info->relaxed): the torque"),
            ("", "", "limits cannot hold it, and it is violated as little as they allow (tasks"),
            ("", "", "come after); or the state is already beyond its position or velocity limit"),
            ("", "", "(after a push), and the bound brings it back; or it is too close to a position"),
            ("", "", "limit for its speed, and crosses it during this step whatever the torque"),
        ]
    else:
        rows = [
            ("0", "OK", "the torque is within its limits" + (" (clipped to them)" if clips else "") + "; this"),
            ("", "", "controller has no joint or Cartesian bound rows: those limits are neither"),
            ("", "", "enforced nor checked"),
            ("1", "LIMITS_RELAXED", "not returned by this controller (no bound rows)"),
        ]
    rows += [
        ("-1", "NONFINITE_INPUT", "an input was NaN or infinite" + (" (or ref NULL: the controller takes one)"
                                                                      if takes_ref else "")),
        *([("", "", "(not tau_ext: this controller does not read it)")] if not measured else []),
        ("-2", "SOLVER_FAILED", "the QP solver failed (also on non-finite QP data)"),
        ("-3", "INVALID_OUTPUT", "the solution was not finite or broke a torque limit"),
        ("-4", "NOT_INITIALIZED", f"{name}_init was not called or failed"),
        ("-5", "BAD_ARGUMENT", "ws, q, dq or tau is NULL: nothing was written"),
    ]
    return table([(f"{code:>2}  {big}_STATUS_{label}" if label else "", text) for code, label, text in rows],
                 indent=" *  ")


def timing_text(name: str, spec_file: str) -> str:
    return "\n".join([
        f" * Timing. Not measured by `dcts compile`: `dcts bench {spec_file}` (or spec.yaml, its copy in",
        f" * the bundle) times {name}_step on the host without Python (median, p99 and max over 10,000",
        " * closed-loop and 10,000 independent states), with the QP iterations and solves per step, the",
        " * workspace and .text sizes.",
    ])


def model_texts(model: dict) -> tuple[str, str]:
    """The header's and the README's note on the robot model (modified or the spec's own)."""
    if not model["modified"]:
        text = f"the spec's robot (model SHA-256 {model['sha256']})"
        return text, text
    changes = describe_changes(model.get("changes", {}))
    header = (
        f"MODIFIED, not the spec's robot: {changes};\n"
        f" *                model SHA-256 {model['sha256']}\n"
        f" *                (the spec's robot: {model['spec_model_sha256']}).\n"
        f" *                Generated for this model (model mismatch); the spec SHA-256 above is unchanged."
    )
    readme = (
        f"**modified**, not the spec's robot: {changes}; model SHA-256 `{model['sha256']}` (the spec's "
        f"robot: `{model['spec_model_sha256']}`). The controller was generated for this model (model "
        "mismatch); the spec's SHA-256 is unchanged."
    )
    return header, readme
