"""Sensing kinds: what the plant tells each agent about the world, one registered kind per sensor
model (issue 11). A mission adds a kind by registering a class here, without editing the plant.

    @register_sensing("my-kind", validate=MyParams.model_validate)
    class MyKind:
        message = pb.Measurements
        def __init__(self, config: PlantConfig): ...   # plant/config.py
        def stimulus(self, ctx: SensingContext, j: int, hdr: pb.Header) -> pb.Measurements: ...

The kind's message goes out on `sc/<id>/sense/<kind>`; `rel` and `scene` have their own messages
(paper 002), every other kind sends `Measurements` (named arrays; bus/codec.py add_measurement),
which the agent turns into `Observation.extra`. `[sensing.params]` is validated at scenario load
by the kind's `validate`.
"""
from swarmhil.plant.sensing.registry import (  # noqa: F401
    SensingContext,
    has_batch_form,
    known_sensing,
    make_sensing,
    register_sensing,
    sensing_message,
    validate_sensing_params,
)
