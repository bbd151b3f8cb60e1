"""The τ_ext the controller receives: a perfect one-step-late estimate, nothing, or a noisy one."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..spec.scenario import ExternalTorqueSensing
from ..spec.types import as_list


class TorqueSensor:
    """External joint torque as a model-based estimator with a one-step delay sees it.

    `ideal`: at step k, the torque that acted during the previous control period, found with
    the *controller's* model from the measured motion,

        τ̂_ext,k = M_c(q_{k−1}) a_{k−1} + ν_c(q_{k−1}, q̇_{k−1}) + g_c(q_{k−1}) − τ_{k−1},
        a_{k−1} = (q̇_k − q̇_{k−1}) / T,

    so it contains the pushes, the payloads and the mass mismatch. With the controller's model
    equal to the simulated one, one substep per period and an Euler-type integrator it equals the
    true τ_ext of step k−1 exactly (the semi-implicit step makes a_{k−1} the acceleration at step
    k−1); with rk4 (the default) a_{k−1} is the period's mean acceleration, and the estimate is
    off by ~5e-5 of the torque (the tests' push). At k = 0 nothing has been observed yet: it is 0.

    `ignored`: always 0. `noisy`: ideal plus seeded Gaussian noise and a constant bias.
    """

    def __init__(self, sensing: ExternalTorqueSensing, model: pin.Model, steps: int):
        self.mode = sensing.mode
        self._model = model
        self._data = model.createData()
        n = model.nv
        self._offset = np.zeros((1, n))  # added noise and bias per step
        if self.mode == "noisy":
            rng = np.random.default_rng(sensing.seed)
            std = np.array(as_list(sensing.noise_std, n))
            self._offset = rng.standard_normal((steps, n)) * std + np.array(as_list(sensing.bias, n))

    def measure(self, k: int, q_prev: np.ndarray, dq_prev: np.ndarray, ddq_prev: np.ndarray,
                tau_prev: np.ndarray, out: np.ndarray) -> None:
        """τ_ext for step k, into `out`; the arguments describe step k − 1 (unused at k = 0)."""
        if self.mode == "ignored":
            out[:] = 0.0
            return
        if k == 0:
            out[:] = self._offset[0]
            return
        np.subtract(pin.rnea(self._model, self._data, q_prev, dq_prev, ddq_prev), tau_prev, out=out)
        if self.mode == "noisy":
            out += self._offset[k]
