"""Paper 002's room: behavioural swarm keeping with the relative orbital elements (Sabatini et al.;
docs/paper002-reproduction.md).

`contract`: what the flight software (`fsw`: the behavioural law and its DRE gains) and the
paper's report (`report`: its metrics table and Figs. 7-22) both spell. Imports nothing
(missions/__init__.py).
"""
