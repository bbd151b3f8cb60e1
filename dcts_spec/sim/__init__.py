"""Simulation of the controlled robot in MuJoCo.

- `scenario`: the spec's scenario in SI units; `disturbances`: pushes and joint-torque profiles;
  `sensing`: the τ_ext the controller receives; `references`: held references and waypoints;
  `mismatch`: the controller's robot with scaled masses.
- `runtime`: the controller in the loop (Python or generated C); `runner`: the closed loop and
  its `log`; `mujoco_model`: the MuJoCo robot built from the Pinocchio model.
- `viewer`, `video`, `camera`, `display`, `progress`: watching a run; `commands`: `dcts simulate`
  and `dcts compare`.

Nothing is imported here on purpose: `display` must be importable before MuJoCo, which reads
MUJOCO_GL once, when it is first imported.
"""
