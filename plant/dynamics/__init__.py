"""Translational dynamics kernels of the plant (pure numpy/scipy, no I/O).

- `roe_linear`: near-circular linear ROE model (D'Amico; NOTES-002) with exact zero-order-hold
  propagation, and the linear map ROE <-> LVLH (equivalent to Hill-Clohessy-Wiltshire).
- `absolute_j2`: nonlinear ECI propagation of the reference and every spacecraft (two-body + J2,
  optional exponential-atmosphere drag), relative states in the reference's rotating LVLH frame.
- `cw`: Clohessy-Wiltshire about a circular reference of any radius, exact zero-order-hold step.
- `inertial`: N craft in ECI, two-body + J2 + drag with per-craft mass, area, C_D.
- `propagator`: the `Propagator` protocol and registry (`make_propagator`, `register_propagator`).
- `attitude`: rigid-body attitude of N craft (scalar-last quaternions, Euler's equations, RK4).
- `limits`: actuator limits per axis or by norm.
- `rk_tableau`: the DOP853 tableau and a fixed-step explicit Runge-Kutta step.
- `step_clock`: t = t_base + k dt for the propagators.
- `frames`: LVLH basis and angular velocity, ECI -> LVLH relative-state transform, argument of latitude.
- `constants`: Earth constants.

docs/dynamics.md lists each propagator, its frame, equations and measured accuracy.
"""
