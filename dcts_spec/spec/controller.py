"""The `controller` section: formulation, solver, period, use of measured external torque."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .types import Number, NumberList, Range, ScalarOrVector, StrictModel

Formulation = Literal["dcts", "osc", "projector", "qp_mt", "qp_md"]
Solver = Literal["daqp"]


class ControllerSpec(StrictModel):
    """How the torque is computed: the formulation, its solver and its settings."""

    formulation: Formulation = Field("dcts", description=(
        "how the priorities are enforced (docs/formulations.md): dcts (strict priorities, tasks scaled "
        "under limits), osc (operational-space control), projector (null-space projectors), qp_mt and "
        "qp_md (one weighted QP; minimum torque or joint damping as regularization)"),
        examples=["dcts", "qp_md"])
    solver: Solver = Field("daqp", description=(
        "QP solver: DAQP, the same in Python and in the generated C (dcts solves a cascade of ordinary QPs)"),
        examples=["daqp"])
    period: Annotated[Number, Range(1e-5, 0.1, "s")] = Field(0.001, description="control period, s", examples=[0.001, 0.0005])
    external_torque: Literal["measured", "ignored"] = Field(
        "measured", description="use the measured external joint torque (Nm) in tasks and limits, or ignore it",
        examples=["measured", "ignored"],
    )
    priority_weights: Annotated[NumberList, Range(1e-10, 1e20)] | None = Field(
        None,
        description="QP-MT and QP-MD only (soft priorities): weight of each priority level, highest first, unitless; "
        "default: 1e6 for the lowest level and 1e3 times more for each level above (three levels: [1e12, 1e9, 1e6]). "
        "dcts solves its levels lexicographically and takes no weights",
        examples=[[1e9, 1e6]],
    )
    joint_damping: Annotated[ScalarOrVector, Range(0, 1e4, "1/s")] = Field(
        5.0, description="QP-MD's joint damping D in 1/s (q̈_d = −D q̇), one value or one per joint", examples=[5.0, 10])
    fallback_damping: Annotated[ScalarOrVector, Range(0, 1e5, "Nm·s/rad")] = Field(
        10.0,
        description="damping D of the safe fallback torque, in Nm·s/rad, one value or one per joint: each joint's "
        "velocity decays at the rate min(D/M_jj(q), 0.5/period), stable at the control period whatever the joint's inertia",
        examples=[10.0, [20, 20, 10, 10, 5, 5, 2]],
    )
    minimized_torque: Literal["full", "without_gravity"] = Field(
        "full",
        description="QP-MT only: the torque whose norm r = ‖·‖² is minimized: full (τ, gravity included, the "
        "paper's eq. (3) as written) or without_gravity (τ − g, as its OSC of eq. (1) computes the torque "
        "before adding g); the paper does not say which it ran",
        examples=["full", "without_gravity"])
    regularization_weight: Annotated[Number, Range(0, 1e6, open=True)] = Field(
        1e-4, description="weight w of QP-MT/QP-MD's regularization term, relative to the lowest level's, unitless",
        examples=[1e-4])
