from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Header(_message.Message):
    __slots__ = ("run", "source", "step", "t", "seq")
    RUN_FIELD_NUMBER: _ClassVar[int]
    SOURCE_FIELD_NUMBER: _ClassVar[int]
    STEP_FIELD_NUMBER: _ClassVar[int]
    T_FIELD_NUMBER: _ClassVar[int]
    SEQ_FIELD_NUMBER: _ClassVar[int]
    run: str
    source: str
    step: int
    t: float
    seq: int
    def __init__(self, run: _Optional[str] = ..., source: _Optional[str] = ..., step: _Optional[int] = ..., t: _Optional[float] = ..., seq: _Optional[int] = ...) -> None: ...

class Vector3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Quaternion(_message.Message):
    __slots__ = ("w", "x", "y", "z")
    W_FIELD_NUMBER: _ClassVar[int]
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    w: float
    x: float
    y: float
    z: float
    def __init__(self, w: _Optional[float] = ..., x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Tick(_message.Message):
    __slots__ = ("header", "step_s", "u_rad", "alive", "final")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    STEP_S_FIELD_NUMBER: _ClassVar[int]
    U_RAD_FIELD_NUMBER: _ClassVar[int]
    ALIVE_FIELD_NUMBER: _ClassVar[int]
    FINAL_FIELD_NUMBER: _ClassVar[int]
    header: Header
    step_s: float
    u_rad: float
    alive: _containers.RepeatedScalarFieldContainer[str]
    final: bool
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., step_s: _Optional[float] = ..., u_rad: _Optional[float] = ..., alive: _Optional[_Iterable[str]] = ..., final: _Optional[bool] = ...) -> None: ...

class BodyState(_message.Message):
    __slots__ = ("id", "position_m", "velocity_mps", "delta_v_mps", "alive", "attitude", "angular_velocity_radps", "accel_cmd_mps2", "kind", "roe_m", "torque_cmd_nm")
    ID_FIELD_NUMBER: _ClassVar[int]
    POSITION_M_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_MPS_FIELD_NUMBER: _ClassVar[int]
    DELTA_V_MPS_FIELD_NUMBER: _ClassVar[int]
    ALIVE_FIELD_NUMBER: _ClassVar[int]
    ATTITUDE_FIELD_NUMBER: _ClassVar[int]
    ANGULAR_VELOCITY_RADPS_FIELD_NUMBER: _ClassVar[int]
    ACCEL_CMD_MPS2_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    ROE_M_FIELD_NUMBER: _ClassVar[int]
    TORQUE_CMD_NM_FIELD_NUMBER: _ClassVar[int]
    id: str
    position_m: Vector3
    velocity_mps: Vector3
    delta_v_mps: float
    alive: bool
    attitude: Quaternion
    angular_velocity_radps: Vector3
    accel_cmd_mps2: Vector3
    kind: str
    roe_m: _containers.RepeatedScalarFieldContainer[float]
    torque_cmd_nm: Vector3
    def __init__(self, id: _Optional[str] = ..., position_m: _Optional[_Union[Vector3, _Mapping]] = ..., velocity_mps: _Optional[_Union[Vector3, _Mapping]] = ..., delta_v_mps: _Optional[float] = ..., alive: _Optional[bool] = ..., attitude: _Optional[_Union[Quaternion, _Mapping]] = ..., angular_velocity_radps: _Optional[_Union[Vector3, _Mapping]] = ..., accel_cmd_mps2: _Optional[_Union[Vector3, _Mapping]] = ..., kind: _Optional[str] = ..., roe_m: _Optional[_Iterable[float]] = ..., torque_cmd_nm: _Optional[_Union[Vector3, _Mapping]] = ...) -> None: ...

class Truth(_message.Message):
    __slots__ = ("header", "bodies", "u_rad", "semi_major_axis_m", "mean_motion_radps")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    BODIES_FIELD_NUMBER: _ClassVar[int]
    U_RAD_FIELD_NUMBER: _ClassVar[int]
    SEMI_MAJOR_AXIS_M_FIELD_NUMBER: _ClassVar[int]
    MEAN_MOTION_RADPS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    bodies: _containers.RepeatedCompositeFieldContainer[BodyState]
    u_rad: float
    semi_major_axis_m: float
    mean_motion_radps: float
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., bodies: _Optional[_Iterable[_Union[BodyState, _Mapping]]] = ..., u_rad: _Optional[float] = ..., semi_major_axis_m: _Optional[float] = ..., mean_motion_radps: _Optional[float] = ...) -> None: ...

class RelativeState(_message.Message):
    __slots__ = ("id", "position_m", "velocity_mps")
    ID_FIELD_NUMBER: _ClassVar[int]
    POSITION_M_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_MPS_FIELD_NUMBER: _ClassVar[int]
    id: str
    position_m: Vector3
    velocity_mps: Vector3
    def __init__(self, id: _Optional[str] = ..., position_m: _Optional[_Union[Vector3, _Mapping]] = ..., velocity_mps: _Optional[_Union[Vector3, _Mapping]] = ...) -> None: ...

class RelStimulus(_message.Message):
    __slots__ = ("header", "u_rad", "neighbours")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    U_RAD_FIELD_NUMBER: _ClassVar[int]
    NEIGHBOURS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    u_rad: float
    neighbours: _containers.RepeatedCompositeFieldContainer[RelativeState]
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., u_rad: _Optional[float] = ..., neighbours: _Optional[_Iterable[_Union[RelativeState, _Mapping]]] = ...) -> None: ...

class ScenePose(_message.Message):
    __slots__ = ("id", "position_cam_m", "attitude_cam")
    ID_FIELD_NUMBER: _ClassVar[int]
    POSITION_CAM_M_FIELD_NUMBER: _ClassVar[int]
    ATTITUDE_CAM_FIELD_NUMBER: _ClassVar[int]
    id: str
    position_cam_m: Vector3
    attitude_cam: Quaternion
    def __init__(self, id: _Optional[str] = ..., position_cam_m: _Optional[_Union[Vector3, _Mapping]] = ..., attitude_cam: _Optional[_Union[Quaternion, _Mapping]] = ...) -> None: ...

class SceneStimulus(_message.Message):
    __slots__ = ("header", "u_rad", "bodies", "pointing_error_rad")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    U_RAD_FIELD_NUMBER: _ClassVar[int]
    BODIES_FIELD_NUMBER: _ClassVar[int]
    POINTING_ERROR_RAD_FIELD_NUMBER: _ClassVar[int]
    header: Header
    u_rad: float
    bodies: _containers.RepeatedCompositeFieldContainer[ScenePose]
    pointing_error_rad: Vector3
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., u_rad: _Optional[float] = ..., bodies: _Optional[_Iterable[_Union[ScenePose, _Mapping]]] = ..., pointing_error_rad: _Optional[_Union[Vector3, _Mapping]] = ...) -> None: ...

class ActuatorCommand(_message.Message):
    __slots__ = ("header", "accel_mps2", "controller", "isl_tx_count", "torque_nm")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    ACCEL_MPS2_FIELD_NUMBER: _ClassVar[int]
    CONTROLLER_FIELD_NUMBER: _ClassVar[int]
    ISL_TX_COUNT_FIELD_NUMBER: _ClassVar[int]
    TORQUE_NM_FIELD_NUMBER: _ClassVar[int]
    header: Header
    accel_mps2: Vector3
    controller: str
    isl_tx_count: int
    torque_nm: Vector3
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., accel_mps2: _Optional[_Union[Vector3, _Mapping]] = ..., controller: _Optional[str] = ..., isl_tx_count: _Optional[int] = ..., torque_nm: _Optional[_Union[Vector3, _Mapping]] = ...) -> None: ...

class Measurement(_message.Message):
    __slots__ = ("name", "subject", "values", "shape")
    NAME_FIELD_NUMBER: _ClassVar[int]
    SUBJECT_FIELD_NUMBER: _ClassVar[int]
    VALUES_FIELD_NUMBER: _ClassVar[int]
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    name: str
    subject: str
    values: _containers.RepeatedScalarFieldContainer[float]
    shape: _containers.RepeatedScalarFieldContainer[int]
    def __init__(self, name: _Optional[str] = ..., subject: _Optional[str] = ..., values: _Optional[_Iterable[float]] = ..., shape: _Optional[_Iterable[int]] = ...) -> None: ...

class Measurements(_message.Message):
    __slots__ = ("header", "u_rad", "neighbours", "items")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    U_RAD_FIELD_NUMBER: _ClassVar[int]
    NEIGHBOURS_FIELD_NUMBER: _ClassVar[int]
    ITEMS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    u_rad: float
    neighbours: _containers.RepeatedCompositeFieldContainer[RelativeState]
    items: _containers.RepeatedCompositeFieldContainer[Measurement]
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., u_rad: _Optional[float] = ..., neighbours: _Optional[_Iterable[_Union[RelativeState, _Mapping]]] = ..., items: _Optional[_Iterable[_Union[Measurement, _Mapping]]] = ...) -> None: ...

class NeighbourDecision(_message.Message):
    __slots__ = ("neighbour", "behaviour", "d_min_m", "roe_rel_m", "accel_mps2")
    NEIGHBOUR_FIELD_NUMBER: _ClassVar[int]
    BEHAVIOUR_FIELD_NUMBER: _ClassVar[int]
    D_MIN_M_FIELD_NUMBER: _ClassVar[int]
    ROE_REL_M_FIELD_NUMBER: _ClassVar[int]
    ACCEL_MPS2_FIELD_NUMBER: _ClassVar[int]
    neighbour: str
    behaviour: str
    d_min_m: float
    roe_rel_m: _containers.RepeatedScalarFieldContainer[float]
    accel_mps2: Vector3
    def __init__(self, neighbour: _Optional[str] = ..., behaviour: _Optional[str] = ..., d_min_m: _Optional[float] = ..., roe_rel_m: _Optional[_Iterable[float]] = ..., accel_mps2: _Optional[_Union[Vector3, _Mapping]] = ...) -> None: ...

class TrackEstimate(_message.Message):
    __slots__ = ("track", "truth_id", "roe_m", "covariance_m2", "position_m", "velocity_mps", "age_steps")
    TRACK_FIELD_NUMBER: _ClassVar[int]
    TRUTH_ID_FIELD_NUMBER: _ClassVar[int]
    ROE_M_FIELD_NUMBER: _ClassVar[int]
    COVARIANCE_M2_FIELD_NUMBER: _ClassVar[int]
    POSITION_M_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_MPS_FIELD_NUMBER: _ClassVar[int]
    AGE_STEPS_FIELD_NUMBER: _ClassVar[int]
    track: str
    truth_id: str
    roe_m: _containers.RepeatedScalarFieldContainer[float]
    covariance_m2: _containers.RepeatedScalarFieldContainer[float]
    position_m: Vector3
    velocity_mps: Vector3
    age_steps: int
    def __init__(self, track: _Optional[str] = ..., truth_id: _Optional[str] = ..., roe_m: _Optional[_Iterable[float]] = ..., covariance_m2: _Optional[_Iterable[float]] = ..., position_m: _Optional[_Union[Vector3, _Mapping]] = ..., velocity_mps: _Optional[_Union[Vector3, _Mapping]] = ..., age_steps: _Optional[int] = ...) -> None: ...

class Telemetry(_message.Message):
    __slots__ = ("header", "mode", "controller", "decisions", "tracks", "accel_mps2", "compute_s", "rejected_packets", "missed_steps", "items")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    MODE_FIELD_NUMBER: _ClassVar[int]
    CONTROLLER_FIELD_NUMBER: _ClassVar[int]
    DECISIONS_FIELD_NUMBER: _ClassVar[int]
    TRACKS_FIELD_NUMBER: _ClassVar[int]
    ACCEL_MPS2_FIELD_NUMBER: _ClassVar[int]
    COMPUTE_S_FIELD_NUMBER: _ClassVar[int]
    REJECTED_PACKETS_FIELD_NUMBER: _ClassVar[int]
    MISSED_STEPS_FIELD_NUMBER: _ClassVar[int]
    ITEMS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    mode: str
    controller: str
    decisions: _containers.RepeatedCompositeFieldContainer[NeighbourDecision]
    tracks: _containers.RepeatedCompositeFieldContainer[TrackEstimate]
    accel_mps2: Vector3
    compute_s: float
    rejected_packets: int
    missed_steps: int
    items: _containers.RepeatedCompositeFieldContainer[Measurement]
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., mode: _Optional[str] = ..., controller: _Optional[str] = ..., decisions: _Optional[_Iterable[_Union[NeighbourDecision, _Mapping]]] = ..., tracks: _Optional[_Iterable[_Union[TrackEstimate, _Mapping]]] = ..., accel_mps2: _Optional[_Union[Vector3, _Mapping]] = ..., compute_s: _Optional[float] = ..., rejected_packets: _Optional[int] = ..., missed_steps: _Optional[int] = ..., items: _Optional[_Iterable[_Union[Measurement, _Mapping]]] = ...) -> None: ...

class IslPacket(_message.Message):
    __slots__ = ("header", "src", "dst", "type", "payload", "sent_t")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    SRC_FIELD_NUMBER: _ClassVar[int]
    DST_FIELD_NUMBER: _ClassVar[int]
    TYPE_FIELD_NUMBER: _ClassVar[int]
    PAYLOAD_FIELD_NUMBER: _ClassVar[int]
    SENT_T_FIELD_NUMBER: _ClassVar[int]
    header: Header
    src: str
    dst: str
    type: str
    payload: bytes
    sent_t: float
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., src: _Optional[str] = ..., dst: _Optional[str] = ..., type: _Optional[str] = ..., payload: _Optional[bytes] = ..., sent_t: _Optional[float] = ...) -> None: ...

class Beacon(_message.Message):
    __slots__ = ("id", "mode", "health", "estimate_summary")
    ID_FIELD_NUMBER: _ClassVar[int]
    MODE_FIELD_NUMBER: _ClassVar[int]
    HEALTH_FIELD_NUMBER: _ClassVar[int]
    ESTIMATE_SUMMARY_FIELD_NUMBER: _ClassVar[int]
    id: str
    mode: str
    health: str
    estimate_summary: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, id: _Optional[str] = ..., mode: _Optional[str] = ..., health: _Optional[str] = ..., estimate_summary: _Optional[_Iterable[float]] = ...) -> None: ...

class LinkCounter(_message.Message):
    __slots__ = ("src", "dst", "type", "messages", "payload_bytes", "wire_bytes", "dropped_range", "dropped_occulted", "dropped_lost", "dropped_queue", "dropped_fault")
    SRC_FIELD_NUMBER: _ClassVar[int]
    DST_FIELD_NUMBER: _ClassVar[int]
    TYPE_FIELD_NUMBER: _ClassVar[int]
    MESSAGES_FIELD_NUMBER: _ClassVar[int]
    PAYLOAD_BYTES_FIELD_NUMBER: _ClassVar[int]
    WIRE_BYTES_FIELD_NUMBER: _ClassVar[int]
    DROPPED_RANGE_FIELD_NUMBER: _ClassVar[int]
    DROPPED_OCCULTED_FIELD_NUMBER: _ClassVar[int]
    DROPPED_LOST_FIELD_NUMBER: _ClassVar[int]
    DROPPED_QUEUE_FIELD_NUMBER: _ClassVar[int]
    DROPPED_FAULT_FIELD_NUMBER: _ClassVar[int]
    src: str
    dst: str
    type: str
    messages: int
    payload_bytes: int
    wire_bytes: int
    dropped_range: int
    dropped_occulted: int
    dropped_lost: int
    dropped_queue: int
    dropped_fault: int
    def __init__(self, src: _Optional[str] = ..., dst: _Optional[str] = ..., type: _Optional[str] = ..., messages: _Optional[int] = ..., payload_bytes: _Optional[int] = ..., wire_bytes: _Optional[int] = ..., dropped_range: _Optional[int] = ..., dropped_occulted: _Optional[int] = ..., dropped_lost: _Optional[int] = ..., dropped_queue: _Optional[int] = ..., dropped_fault: _Optional[int] = ...) -> None: ...

class LinkStats(_message.Message):
    __slots__ = ("header", "links", "rejected_packets", "tx_messages", "rx_messages")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    LINKS_FIELD_NUMBER: _ClassVar[int]
    REJECTED_PACKETS_FIELD_NUMBER: _ClassVar[int]
    TX_MESSAGES_FIELD_NUMBER: _ClassVar[int]
    RX_MESSAGES_FIELD_NUMBER: _ClassVar[int]
    header: Header
    links: _containers.RepeatedCompositeFieldContainer[LinkCounter]
    rejected_packets: int
    tx_messages: int
    rx_messages: int
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., links: _Optional[_Iterable[_Union[LinkCounter, _Mapping]]] = ..., rejected_packets: _Optional[int] = ..., tx_messages: _Optional[int] = ..., rx_messages: _Optional[int] = ...) -> None: ...

class Event(_message.Message):
    __slots__ = ("header", "kind", "subject", "detail")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    SUBJECT_FIELD_NUMBER: _ClassVar[int]
    DETAIL_FIELD_NUMBER: _ClassVar[int]
    header: Header
    kind: str
    subject: str
    detail: str
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., kind: _Optional[str] = ..., subject: _Optional[str] = ..., detail: _Optional[str] = ...) -> None: ...

class UndecodableSample(_message.Message):
    __slots__ = ("header", "key", "payload", "reason")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    KEY_FIELD_NUMBER: _ClassVar[int]
    PAYLOAD_FIELD_NUMBER: _ClassVar[int]
    REASON_FIELD_NUMBER: _ClassVar[int]
    header: Header
    key: str
    payload: bytes
    reason: str
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., key: _Optional[str] = ..., payload: _Optional[bytes] = ..., reason: _Optional[str] = ...) -> None: ...

class RejectedSample(_message.Message):
    __slots__ = ("header", "key", "payload", "reason", "claimed_source", "claimed_run")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    KEY_FIELD_NUMBER: _ClassVar[int]
    PAYLOAD_FIELD_NUMBER: _ClassVar[int]
    REASON_FIELD_NUMBER: _ClassVar[int]
    CLAIMED_SOURCE_FIELD_NUMBER: _ClassVar[int]
    CLAIMED_RUN_FIELD_NUMBER: _ClassVar[int]
    header: Header
    key: str
    payload: bytes
    reason: str
    claimed_source: str
    claimed_run: str
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., key: _Optional[str] = ..., payload: _Optional[bytes] = ..., reason: _Optional[str] = ..., claimed_source: _Optional[str] = ..., claimed_run: _Optional[str] = ...) -> None: ...
