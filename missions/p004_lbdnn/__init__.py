"""Paper 004's room: collaborative servicing under partial feedback (docs/paper004.md).

`contract` (what the plant's sensing kind and the flight software share: names, parameter model),
`fsw/` (the servicers' flight software), `sense` (the plant's sensing kind `p004-partial`),
`report` (the report section). Imports nothing (missions/__init__.py).
"""
