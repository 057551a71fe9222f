"""Mission rooms (issue 25, docs/architecture.md "Mission rooms"): one folder per paper.

Each room holds by process: `contract` (names, message fields, parameter models and pure geometry
that the plant and the flight software share; imports nothing of the project but `bus`), and, in
later steps of issue 25, `fsw`, `sense`, `report` and its scenarios. Package `__init__` files here
import nothing, so importing a room's contract loads no flight software, sensing or report code
(tests/test_rooms.py).
"""
