"""Bandwidth report of a run (issue 5): what the swarm's inter-satellite traffic cost, from the MCAP alone.

Read with the public contract only (the `mcap` reader and the `mcap-protobuf-support` decoder,
which decodes from the schemas embedded in the file): every `isl/tx/<id>` sample (what the agents
offered to their radios), every `isl/rx/<id>` sample (what the channel delivered), every
`link/stats` (the channel's own cumulative counters), the channel's `link_config` event and the
truth (positions at the time of sending, for an independent range check).

Two independent accountings are compared and must agree exactly: bytes and messages counted in
the recording (tx samples the channel accepts by the rules of link/model.py `check_tx`, and rx
samples) against the channel's counters (the last `LinkStats` of the recording and
`summary.json["channel"]`). Bytes with overhead = payload + the configured per-packet overhead.

Figures (matplotlib, PNG next to the HTML): cumulative bytes and messages per agent over time,
the link matrix (delivered bytes, transmitter x receiver), drops by cause per transmitter. A
comparison mode puts two runs side by side (e.g. periodic versus event-triggered broadcasting).

The package is split by job, each module importing only the ones before it: `read` (`LinkTraffic` from the recording) <- `accounting` (totals, consistency, series) <- `figures` <- `page` (the report section, its page, the comparison).
"""
