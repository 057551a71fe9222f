"""The flight software a plant runs in its own process (batch mode, issue 16): the interface the plant
owns, so that the plant calls flight software without importing it (nor the deploy code that builds it).

`PlantNode(..., local_agents=fsw)` takes any `LocalFlightSoftware`. At each step k the plant calls
`fsw.commands(ctx, rows, sense)` instead of publishing one stimulus message per spacecraft:

- `ctx`: the truth of step k (plant/sensing/registry.py SensingContext);
- `rows`: the indices (into ctx.ids, increasing) of the live spacecraft, the observers;
- `sense()`: the sensing kind's stimuli of those observers as arrays (`StimulusBatch`, the kind's
  `batch(ctx, rows)` form: the same values as the per-spacecraft messages), or, for a kind without
  a batch form, its messages themselves (`StimulusMessages`: built as for the bus, not serialised);
  computed only when called, so flight software that does not look at its observation costs no sensing.

It returns the (N, 3) commanded accelerations in the scenario frame of all N spacecraft (rows
other than `rows` are ignored): the commands in force over step k, as the agents' messages would
have carried them; where spacecraft fly attitude, (N, 6): each row's acceleration and then its
body-frame torque (0 for a command without one, as an `ActuatorCommand` without `torque_nm`). deploy/batch.py `BatchHook` implements it with the agent's `BatchAgents`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Protocol

import numpy as np

if TYPE_CHECKING:  # (annotations only: the registry imports the sensing kinds' modules)
    from swarmhil.plant.sensing.registry import SensingContext


class StimulusBatch(Protocol):
    """The stimuli of R observers (CSR): observer r's neighbours are pairs offsets[r]:offsets[r+1]
    (plant/sensing/builtin.py RelBatch)."""

    offsets: np.ndarray            # (R + 1,)
    neighbour: np.ndarray          # (P,) index of each pair's neighbour in ctx.ids
    rel_position_m: np.ndarray     # (P, 3) r_neighbour - r_observer, scenario frame
    rel_velocity_mps: np.ndarray   # (P, 3)
    owner: np.ndarray | None       # (P,) the observer row r of each pair, when the kind gives it


@dataclass(frozen=True)
class StimulusMessages:
    """The stimuli of R observers from a sensing kind without a batch form: messages[r] is observer
    r's stimulus message (header and all), the one the plant would have published for it."""

    messages: list[Any]


class LocalFlightSoftware(Protocol):
    """Flight software of every spacecraft, called by the plant in its process (see the module)."""

    def commands(self, ctx: SensingContext, rows: np.ndarray,
                 sense: Callable[[], StimulusBatch | StimulusMessages]) -> np.ndarray: ...
