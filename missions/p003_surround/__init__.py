"""Paper 003's room: a leader and six servicers surround an escaping target (docs/paper003.md).

`contract` (names, parameter models, structure, funnel geometry), `fsw/` (the leader's and the
servicers' flight software), `sense` (the plant's sensing kind `p003-relative`), `report` (the
report section). Imports nothing (missions/__init__.py).
"""
