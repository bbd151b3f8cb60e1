"""The τ_ext the controller receives: a perfect one-step-late estimate, nothing, or a noisy one."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..spec.scenario import ExternalTorqueSensing
from ..spec.types import as_list


class TorqueSensor:
    """External joint torque as a model-based estimator with a one-step delay sees it.

    `ideal`: at step k, the torque that acted during the previous control period, found with
    the *controller's* model from the measured motion over that period,

        τ̂_ext,k = M_c(q̄) a + ν_c(q̄, q̄̇) + g_c(q̄) − τ_{k−1},   a = (q̇_k − q̇_{k−1}) / T,

    so it contains the pushes, the payloads and the mass mismatch. With an Euler-type integrator
    and one substep per period, a is the acceleration at step k−1 (the semi-implicit step), and at
    (q̄, q̄̇) = (q_{k−1}, q̇_{k−1}) the estimate is the true τ_ext of step k−1 exactly (with the
    controller's model equal to the simulated one). Otherwise (rk4, the default, or substeps) a is
    the period's mean acceleration, and (q̄, q̄̇) is the period's midpoint, halfway between the two
    states: the state at its start had made up torques that were not there where the motion was
    fast (4.7 Nm on a 13-joint Centauro's torso with nothing pushing, after a torque step that
    took a wrist 1.8 rad/s in one period; 0.013 Nm at the midpoint). At k = 0 nothing has been
    observed yet: it is 0.

    `ignored`: always 0. `noisy`: ideal plus seeded Gaussian noise and a constant bias.
    """

    def __init__(self, sensing: ExternalTorqueSensing, model: pin.Model, steps: int, at_start: bool):
        self.mode = sensing.mode
        self.at_start = at_start  # (an Euler-type integrator, one substep a period)
        self._model = model
        self._data = model.createData()
        n = model.nv
        self._offset = np.zeros((1, n))  # added noise and bias per step
        if self.mode == "noisy":
            rng = np.random.default_rng(sensing.seed)
            std = np.array(as_list(sensing.noise_std, n))
            self._offset = rng.standard_normal((steps, n)) * std + np.array(as_list(sensing.bias, n))

    def measure(self, k: int, q_prev: np.ndarray, dq_prev: np.ndarray, q: np.ndarray, dq: np.ndarray,
                ddq_prev: np.ndarray, tau_prev: np.ndarray, out: np.ndarray) -> None:
        """τ_ext for step k, into `out`, from the period between step k − 1 (q_prev, dq_prev, its
        torque tau_prev, ddq_prev = (dq − dq_prev)/T) and step k (q, dq); unused at k = 0."""
        if self.mode == "ignored":
            out[:] = 0.0
            return
        if k == 0:
            out[:] = self._offset[0]
            return
        if self.at_start:
            q_bar, dq_bar = q_prev, dq_prev
        else:
            q_bar, dq_bar = pin.interpolate(self._model, q_prev, q, 0.5), 0.5 * (dq_prev + dq)
        np.subtract(pin.rnea(self._model, self._data, q_bar, dq_bar, ddq_prev), tau_prev, out=out)
        if self.mode == "noisy":
            out += self._offset[k]
