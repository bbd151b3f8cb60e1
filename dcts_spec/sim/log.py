"""What a run records at each control step, in preallocated arrays."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np


@dataclass
class SimulationLog:
    """Per control step k (time t_k = k T): the state, the controller's inputs and outputs.

    `tau` is applied during [t_k, t_k + T); `ddq` is the actual mean acceleration over that
    period, (q̇_{k+1} − q̇_k)/T; `tau_ext_true` is the joint torque of the disturbances during that
    period, the mean over its simulation substeps (their impulse over T; with one substep, the
    torque at t_k); payloads and model errors are not disturbances. `tau_ext_measured` is what the
    scenario's sensor gave the controller (which ignores it with controller.external_torque: ignored).
    """

    period: float
    time: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    ddq_commanded: np.ndarray
    tau: np.ndarray
    tau_ext_true: np.ndarray
    tau_ext_measured: np.ndarray
    ref: np.ndarray
    scaling: np.ndarray
    status: np.ndarray
    relaxed: np.ndarray  # (steps, bounds): the joint/Cartesian bounds crossed (status 1)
    bound_names: list[str] = field(default_factory=list)  # the columns of `relaxed`
    # status "ok" with a QP: 1 if the answer was checked to minimize the lowest level's objective
    # given the levels above (StepResult.optimal), 0 if not; −1 where not checked
    optimal: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    # (steps, run-time parameters): the values the controller applied at each step (ramps included)
    param: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    waypoint_times: np.ndarray = field(default_factory=lambda: np.zeros(0))  # NaN where not reached
    wall_time: float = 0.0  # s spent in the simulation loop (controller, physics, logging; not hooks)
    diverged_at: float | None = None  # when MuJoCo rejected the state or the torque: the run stopped

    @classmethod
    def allocate(cls, steps: int, n: int, ref_size: int, levels: int, period: float,
                 bound_names: list[str] = (), param_size: int = 0) -> SimulationLog:
        def zeros(*shape: int) -> np.ndarray:
            return np.zeros((steps, *shape))

        return cls(
            period=period,
            time=np.arange(steps) * period,
            q=zeros(n), dq=zeros(n), ddq=zeros(n), ddq_commanded=zeros(n), tau=zeros(n),
            tau_ext_true=zeros(n), tau_ext_measured=zeros(n), ref=zeros(ref_size), scaling=zeros(levels),
            status=np.zeros(steps, dtype=np.int8), optimal=np.full(steps, -1, dtype=np.int8),
            relaxed=np.zeros((steps, len(bound_names)), dtype=bool), bound_names=list(bound_names),
            param=zeros(param_size),
        )

    @property
    def steps(self) -> int:
        return int(self.time.size)

    @property
    def duration(self) -> float:
        """Simulated time covered by the log."""
        return self.steps * self.period

    def truncate(self, steps: int) -> None:
        """Keep the first `steps` entries (a run that stopped early)."""
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray) and f.name != "waypoint_times":
                setattr(self, f.name, value[:steps])

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-step arrays by name (for saving)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if isinstance(getattr(self, f.name), np.ndarray)}
