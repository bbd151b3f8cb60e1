"""The robot's kinematic tree as C tables: the fallback torque's dynamics run as loops over them.

The fallback torque (formulations/fallback.py) needs ν + g, M's diagonal and M a for one
acceleration a: two RNEA passes and the CRBA's diagonal. CasADi expands them into one expression
whose code grows with the arithmetic (1,558 operations and 11.8 kB of Cortex-M7 flash for a
7-joint arm, 8,220 operations for TALOS's 28 joints); the same algorithms as loops over these
tables (controller.c.in, "Rigid-body dynamics of the fallback torque") are ~3 kB of code plus
~0.23 kB of tables per joint. The numbers are those `symbolic.dynamics` builds its expressions
from (`JointGeometry`: round-off zeros made exact), so both runtimes compute the same sums, in a
different order.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..symbolic.dynamics import JointGeometry
from .c_literals import c_array, c_rows


def rigid_body_values(model: pin.Model) -> dict[str, str]:
    """The template values RB_* of a fixed-base model of 1-dof joints (velocity j is joint j + 1)."""
    joints = [JointGeometry.of(model, i) for i in range(1, model.njoints)]
    for j, joint in enumerate(joints):
        if joint.idx_v != j:  # (1-dof joints in model order: always, for the models dcts builds)
            raise ValueError(f"joint {joint.name!r} is velocity {joint.idx_v}, expected {j}")
    if np.any(np.asarray(model.gravity.angular) != 0.0):
        raise ValueError("the model's gravity has an angular part")
    bodies = [model.inertias[i] for i in range(1, model.njoints)]
    return {
        "RB_PARENT": ", ".join(str(joint.parent - 1) for joint in joints),
        "RB_ROTATION": c_rows(joint.rotation for joint in joints),
        "RB_TRANSLATION": c_rows(joint.translation for joint in joints),
        "RB_AXIS": c_rows(joint.axis for joint in joints),
        "RB_REVOLUTE": ", ".join(str(int(joint.revolute)) for joint in joints),
        "RB_MASS": c_array(np.array([float(body.mass) for body in bodies])),
        "RB_COM": c_rows(np.asarray(body.lever) for body in bodies),
        "RB_INERTIA": c_rows(np.asarray(body.inertia) for body in bodies),
        "RB_GRAVITY": c_array(np.asarray(model.gravity.linear, dtype=float)),
    }
