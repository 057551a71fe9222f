"""Behaviour stage of the flight software: one module per seed controller behind agent/controller.py.

- `sabatini`: behavioural swarm keeping of paper 002 (collision avoidance / alignment / attraction).
- `dre`: periodic differential-Riccati LQR gains tabulated by the argument of latitude.
"""
