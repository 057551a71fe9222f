"""Translational dynamics kernels of the plant (pure numpy/scipy, no I/O).

- `roe_linear`: near-circular linear ROE model (D'Amico; NOTES-002) with exact zero-order-hold
  propagation, and the linear map ROE <-> LVLH (equivalent to Hill-Clohessy-Wiltshire).
- `absolute_j2`: nonlinear ECI propagation of the reference and every spacecraft (two-body + J2,
  optional exponential-atmosphere drag), relative states in the reference's rotating LVLH frame.
- `frames`: LVLH basis and angular velocity, ECI -> LVLH relative-state transform.
- `constants`: Earth constants.
"""
