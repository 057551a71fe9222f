"""The link emulator: the inter-satellite channel's physics (range, occultation, loss, latency,
bit rate, queues) and accounting, in a room of its own (issue 11; DESIGN "rooms"): it is link
physics, not transport. `link/model.py` is the pure model, `link/node.py` the companion process
around it (the only path from one agent's transmitter to another's receiver)."""
