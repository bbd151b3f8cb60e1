"""The `controller` section: formulation, solver, period, use of measured external torque."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .types import Number, NumberList, ScalarOrVector, StrictModel

Formulation = Literal["dcts", "osc", "projector", "qp_mt", "qp_md"]
Solver = Literal["daqp"]


class ControllerSpec(StrictModel):
    formulation: Formulation = "dcts"
    solver: Solver = Field("daqp", description="QP solver: DAQP in its hierarchical (lexicographic) mode, the same in Python and in the generated C")
    period: Number = Field(0.001, gt=0, le=0.1, description="control period in s")
    external_torque: Literal["measured", "ignored"] = Field(
        "measured", description="use the measured external joint torque in tasks and limits"
    )
    priority_weights: NumberList | None = Field(
        None,
        description="QP-MT and QP-MD only (soft priorities): weight of each priority level, highest first "
        "(default 1e6·1e3^(k−i)); dcts solves its levels lexicographically and takes no weights"
    )
    joint_damping: ScalarOrVector = Field(5.0, description="QP-MD's joint damping D in 1/s (q̈_d = −D q̇)")
    fallback_damping: ScalarOrVector = Field(
        10.0,
        description="damping D of the safe fallback torque, in Nm·s/rad: each joint's velocity decays at the rate "
        "min(D/M_jj(q), 0.5/period), stable at the control period whatever the joint's inertia",
    )
    regularization_weight: Number = Field(1e-4, gt=0, description="weight w of QP-MT/QP-MD's regularization term")
