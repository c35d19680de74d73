from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Level(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    LEVEL_UNSPECIFIED: _ClassVar[Level]
    LEVEL_BASE: _ClassVar[Level]
    LEVEL_DETAIL: _ClassVar[Level]

class Skinning(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    SKINNING_UNSPECIFIED: _ClassVar[Skinning]
    SKINNING_LBS: _ClassVar[Skinning]
    SKINNING_DQS: _ClassVar[Skinning]

class Encoding(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    ENCODING_UNSPECIFIED: _ClassVar[Encoding]
    ENCODING_VERTICES: _ClassVar[Encoding]
    ENCODING_PALETTE: _ClassVar[Encoding]
LEVEL_UNSPECIFIED: Level
LEVEL_BASE: Level
LEVEL_DETAIL: Level
SKINNING_UNSPECIFIED: Skinning
SKINNING_LBS: Skinning
SKINNING_DQS: Skinning
ENCODING_UNSPECIFIED: Encoding
ENCODING_VERTICES: Encoding
ENCODING_PALETTE: Encoding

class Vec3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Box3(_message.Message):
    __slots__ = ("min", "max")
    MIN_FIELD_NUMBER: _ClassVar[int]
    MAX_FIELD_NUMBER: _ClassVar[int]
    min: Vec3
    max: Vec3
    def __init__(self, min: _Optional[_Union[Vec3, _Mapping]] = ..., max: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...

class ListModelsRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ListModelsResponse(_message.Message):
    __slots__ = ("models", "cluster")
    MODELS_FIELD_NUMBER: _ClassVar[int]
    CLUSTER_FIELD_NUMBER: _ClassVar[int]
    models: _containers.RepeatedCompositeFieldContainer[ModelInfo]
    cluster: _containers.RepeatedCompositeFieldContainer[StoredModel]
    def __init__(self, models: _Optional[_Iterable[_Union[ModelInfo, _Mapping]]] = ..., cluster: _Optional[_Iterable[_Union[StoredModel, _Mapping]]] = ...) -> None: ...

class StoredModel(_message.Message):
    __slots__ = ("name", "sha256", "bytes")
    NAME_FIELD_NUMBER: _ClassVar[int]
    SHA256_FIELD_NUMBER: _ClassVar[int]
    BYTES_FIELD_NUMBER: _ClassVar[int]
    name: str
    sha256: str
    bytes: int
    def __init__(self, name: _Optional[str] = ..., sha256: _Optional[str] = ..., bytes: _Optional[int] = ...) -> None: ...

class ModelChunk(_message.Message):
    __slots__ = ("name", "size", "sha256", "data")
    NAME_FIELD_NUMBER: _ClassVar[int]
    SIZE_FIELD_NUMBER: _ClassVar[int]
    SHA256_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    name: str
    size: int
    sha256: str
    data: bytes
    def __init__(self, name: _Optional[str] = ..., size: _Optional[int] = ..., sha256: _Optional[str] = ..., data: _Optional[bytes] = ...) -> None: ...

class DeleteModelRequest(_message.Message):
    __slots__ = ("model",)
    MODEL_FIELD_NUMBER: _ClassVar[int]
    model: str
    def __init__(self, model: _Optional[str] = ...) -> None: ...

class DeleteModelResponse(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class GetModelRequest(_message.Message):
    __slots__ = ("model",)
    MODEL_FIELD_NUMBER: _ClassVar[int]
    model: str
    def __init__(self, model: _Optional[str] = ...) -> None: ...

class ControlPoint(_message.Message):
    __slots__ = ("id", "name", "vertex", "rest")
    ID_FIELD_NUMBER: _ClassVar[int]
    NAME_FIELD_NUMBER: _ClassVar[int]
    VERTEX_FIELD_NUMBER: _ClassVar[int]
    REST_FIELD_NUMBER: _ClassVar[int]
    id: int
    name: str
    vertex: int
    rest: Vec3
    def __init__(self, id: _Optional[int] = ..., name: _Optional[str] = ..., vertex: _Optional[int] = ..., rest: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...

class ModelInfo(_message.Message):
    __slots__ = ("name", "base_vertices", "base_triangles", "detail_vertices", "detail_triangles", "control_points", "bounds", "method", "default_beta", "bones", "skinning")
    NAME_FIELD_NUMBER: _ClassVar[int]
    BASE_VERTICES_FIELD_NUMBER: _ClassVar[int]
    BASE_TRIANGLES_FIELD_NUMBER: _ClassVar[int]
    DETAIL_VERTICES_FIELD_NUMBER: _ClassVar[int]
    DETAIL_TRIANGLES_FIELD_NUMBER: _ClassVar[int]
    CONTROL_POINTS_FIELD_NUMBER: _ClassVar[int]
    BOUNDS_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    DEFAULT_BETA_FIELD_NUMBER: _ClassVar[int]
    BONES_FIELD_NUMBER: _ClassVar[int]
    SKINNING_FIELD_NUMBER: _ClassVar[int]
    name: str
    base_vertices: int
    base_triangles: int
    detail_vertices: int
    detail_triangles: int
    control_points: _containers.RepeatedCompositeFieldContainer[ControlPoint]
    bounds: Box3
    method: str
    default_beta: float
    bones: int
    skinning: Skinning
    def __init__(self, name: _Optional[str] = ..., base_vertices: _Optional[int] = ..., base_triangles: _Optional[int] = ..., detail_vertices: _Optional[int] = ..., detail_triangles: _Optional[int] = ..., control_points: _Optional[_Iterable[_Union[ControlPoint, _Mapping]]] = ..., bounds: _Optional[_Union[Box3, _Mapping]] = ..., method: _Optional[str] = ..., default_beta: _Optional[float] = ..., bones: _Optional[int] = ..., skinning: _Optional[_Union[Skinning, str]] = ...) -> None: ...

class OpenRoomRequest(_message.Message):
    __slots__ = ("room", "model", "beta", "filter", "retarget", "refine", "skinning", "actors")
    ROOM_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    BETA_FIELD_NUMBER: _ClassVar[int]
    FILTER_FIELD_NUMBER: _ClassVar[int]
    RETARGET_FIELD_NUMBER: _ClassVar[int]
    REFINE_FIELD_NUMBER: _ClassVar[int]
    SKINNING_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    room: str
    model: str
    beta: float
    filter: MarkerFilter
    retarget: Retarget
    refine: Refine
    skinning: Skinning
    actors: _containers.RepeatedCompositeFieldContainer[Actor]
    def __init__(self, room: _Optional[str] = ..., model: _Optional[str] = ..., beta: _Optional[float] = ..., filter: _Optional[_Union[MarkerFilter, _Mapping]] = ..., retarget: _Optional[_Union[Retarget, _Mapping]] = ..., refine: _Optional[_Union[Refine, _Mapping]] = ..., skinning: _Optional[_Union[Skinning, str]] = ..., actors: _Optional[_Iterable[_Union[Actor, _Mapping]]] = ...) -> None: ...

class Actor(_message.Message):
    __slots__ = ("name", "model", "side", "mirror", "performer", "beta", "filter", "retarget", "refine", "skinning")
    NAME_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    SIDE_FIELD_NUMBER: _ClassVar[int]
    MIRROR_FIELD_NUMBER: _ClassVar[int]
    PERFORMER_FIELD_NUMBER: _ClassVar[int]
    BETA_FIELD_NUMBER: _ClassVar[int]
    FILTER_FIELD_NUMBER: _ClassVar[int]
    RETARGET_FIELD_NUMBER: _ClassVar[int]
    REFINE_FIELD_NUMBER: _ClassVar[int]
    SKINNING_FIELD_NUMBER: _ClassVar[int]
    name: str
    model: str
    side: str
    mirror: str
    performer: str
    beta: float
    filter: MarkerFilter
    retarget: Retarget
    refine: Refine
    skinning: Skinning
    def __init__(self, name: _Optional[str] = ..., model: _Optional[str] = ..., side: _Optional[str] = ..., mirror: _Optional[str] = ..., performer: _Optional[str] = ..., beta: _Optional[float] = ..., filter: _Optional[_Union[MarkerFilter, _Mapping]] = ..., retarget: _Optional[_Union[Retarget, _Mapping]] = ..., refine: _Optional[_Union[Refine, _Mapping]] = ..., skinning: _Optional[_Union[Skinning, str]] = ...) -> None: ...

class Refine(_message.Message):
    __slots__ = ("iterations", "strength")
    ITERATIONS_FIELD_NUMBER: _ClassVar[int]
    STRENGTH_FIELD_NUMBER: _ClassVar[int]
    iterations: int
    strength: float
    def __init__(self, iterations: _Optional[int] = ..., strength: _Optional[float] = ...) -> None: ...

class Retarget(_message.Message):
    __slots__ = ("map_toml", "map_name", "markers", "units")
    MAP_TOML_FIELD_NUMBER: _ClassVar[int]
    MAP_NAME_FIELD_NUMBER: _ClassVar[int]
    MARKERS_FIELD_NUMBER: _ClassVar[int]
    UNITS_FIELD_NUMBER: _ClassVar[int]
    map_toml: str
    map_name: str
    markers: _containers.RepeatedScalarFieldContainer[str]
    units: str
    def __init__(self, map_toml: _Optional[str] = ..., map_name: _Optional[str] = ..., markers: _Optional[_Iterable[str]] = ..., units: _Optional[str] = ...) -> None: ...

class MarkerFilter(_message.Message):
    __slots__ = ("min_cutoff_hz", "beta", "d_cutoff_hz")
    MIN_CUTOFF_HZ_FIELD_NUMBER: _ClassVar[int]
    BETA_FIELD_NUMBER: _ClassVar[int]
    D_CUTOFF_HZ_FIELD_NUMBER: _ClassVar[int]
    min_cutoff_hz: float
    beta: float
    d_cutoff_hz: float
    def __init__(self, min_cutoff_hz: _Optional[float] = ..., beta: _Optional[float] = ..., d_cutoff_hz: _Optional[float] = ...) -> None: ...

class GetRoomRequest(_message.Message):
    __slots__ = ("room",)
    ROOM_FIELD_NUMBER: _ClassVar[int]
    room: str
    def __init__(self, room: _Optional[str] = ...) -> None: ...

class RoomInfo(_message.Message):
    __slots__ = ("room", "model", "beta", "filter", "subscribers", "published", "owner", "replica", "retarget", "refine", "skinning", "actors")
    ROOM_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    BETA_FIELD_NUMBER: _ClassVar[int]
    FILTER_FIELD_NUMBER: _ClassVar[int]
    SUBSCRIBERS_FIELD_NUMBER: _ClassVar[int]
    PUBLISHED_FIELD_NUMBER: _ClassVar[int]
    OWNER_FIELD_NUMBER: _ClassVar[int]
    REPLICA_FIELD_NUMBER: _ClassVar[int]
    RETARGET_FIELD_NUMBER: _ClassVar[int]
    REFINE_FIELD_NUMBER: _ClassVar[int]
    SKINNING_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    room: str
    model: ModelInfo
    beta: float
    filter: MarkerFilter
    subscribers: int
    published: int
    owner: str
    replica: str
    retarget: Retarget
    refine: Refine
    skinning: Skinning
    actors: _containers.RepeatedCompositeFieldContainer[ActorInfo]
    def __init__(self, room: _Optional[str] = ..., model: _Optional[_Union[ModelInfo, _Mapping]] = ..., beta: _Optional[float] = ..., filter: _Optional[_Union[MarkerFilter, _Mapping]] = ..., subscribers: _Optional[int] = ..., published: _Optional[int] = ..., owner: _Optional[str] = ..., replica: _Optional[str] = ..., retarget: _Optional[_Union[Retarget, _Mapping]] = ..., refine: _Optional[_Union[Refine, _Mapping]] = ..., skinning: _Optional[_Union[Skinning, str]] = ..., actors: _Optional[_Iterable[_Union[ActorInfo, _Mapping]]] = ...) -> None: ...

class ActorInfo(_message.Message):
    __slots__ = ("actor", "model")
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    actor: Actor
    model: ModelInfo
    def __init__(self, actor: _Optional[_Union[Actor, _Mapping]] = ..., model: _Optional[_Union[ModelInfo, _Mapping]] = ...) -> None: ...

class OpenRoomResponse(_message.Message):
    __slots__ = ("room", "publish_token", "model")
    ROOM_FIELD_NUMBER: _ClassVar[int]
    PUBLISH_TOKEN_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    room: str
    publish_token: str
    model: ModelInfo
    def __init__(self, room: _Optional[str] = ..., publish_token: _Optional[str] = ..., model: _Optional[_Union[ModelInfo, _Mapping]] = ...) -> None: ...

class CloseRoomRequest(_message.Message):
    __slots__ = ("room",)
    ROOM_FIELD_NUMBER: _ClassVar[int]
    room: str
    def __init__(self, room: _Optional[str] = ...) -> None: ...

class CloseRoomResponse(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ControlFrame(_message.Message):
    __slots__ = ("room", "seq", "capture_time_us", "positions", "valid", "markers", "markers_valid", "actors")
    ROOM_FIELD_NUMBER: _ClassVar[int]
    SEQ_FIELD_NUMBER: _ClassVar[int]
    CAPTURE_TIME_US_FIELD_NUMBER: _ClassVar[int]
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    VALID_FIELD_NUMBER: _ClassVar[int]
    MARKERS_FIELD_NUMBER: _ClassVar[int]
    MARKERS_VALID_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    room: str
    seq: int
    capture_time_us: int
    positions: _containers.RepeatedScalarFieldContainer[float]
    valid: bytes
    markers: _containers.RepeatedScalarFieldContainer[float]
    markers_valid: bytes
    actors: _containers.RepeatedCompositeFieldContainer[ActorControls]
    def __init__(self, room: _Optional[str] = ..., seq: _Optional[int] = ..., capture_time_us: _Optional[int] = ..., positions: _Optional[_Iterable[float]] = ..., valid: _Optional[bytes] = ..., markers: _Optional[_Iterable[float]] = ..., markers_valid: _Optional[bytes] = ..., actors: _Optional[_Iterable[_Union[ActorControls, _Mapping]]] = ...) -> None: ...

class ActorControls(_message.Message):
    __slots__ = ("actor", "positions", "valid", "markers", "markers_valid")
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    VALID_FIELD_NUMBER: _ClassVar[int]
    MARKERS_FIELD_NUMBER: _ClassVar[int]
    MARKERS_VALID_FIELD_NUMBER: _ClassVar[int]
    actor: str
    positions: _containers.RepeatedScalarFieldContainer[float]
    valid: bytes
    markers: _containers.RepeatedScalarFieldContainer[float]
    markers_valid: bytes
    def __init__(self, actor: _Optional[str] = ..., positions: _Optional[_Iterable[float]] = ..., valid: _Optional[bytes] = ..., markers: _Optional[_Iterable[float]] = ..., markers_valid: _Optional[bytes] = ...) -> None: ...

class FrameError(_message.Message):
    __slots__ = ("code", "message", "frame")
    CODE_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    code: int
    message: str
    frame: int
    def __init__(self, code: _Optional[int] = ..., message: _Optional[str] = ..., frame: _Optional[int] = ...) -> None: ...

class PublishAck(_message.Message):
    __slots__ = ("seq", "server_latency_us", "held_controls", "error", "control_residual", "control_residual_capture", "confidence", "actors")
    SEQ_FIELD_NUMBER: _ClassVar[int]
    SERVER_LATENCY_US_FIELD_NUMBER: _ClassVar[int]
    HELD_CONTROLS_FIELD_NUMBER: _ClassVar[int]
    ERROR_FIELD_NUMBER: _ClassVar[int]
    CONTROL_RESIDUAL_FIELD_NUMBER: _ClassVar[int]
    CONTROL_RESIDUAL_CAPTURE_FIELD_NUMBER: _ClassVar[int]
    CONFIDENCE_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    seq: int
    server_latency_us: int
    held_controls: int
    error: FrameError
    control_residual: float
    control_residual_capture: float
    confidence: float
    actors: _containers.RepeatedCompositeFieldContainer[ActorAck]
    def __init__(self, seq: _Optional[int] = ..., server_latency_us: _Optional[int] = ..., held_controls: _Optional[int] = ..., error: _Optional[_Union[FrameError, _Mapping]] = ..., control_residual: _Optional[float] = ..., control_residual_capture: _Optional[float] = ..., confidence: _Optional[float] = ..., actors: _Optional[_Iterable[_Union[ActorAck, _Mapping]]] = ...) -> None: ...

class ActorAck(_message.Message):
    __slots__ = ("actor", "held", "held_controls", "control_residual", "control_residual_capture", "confidence")
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    HELD_FIELD_NUMBER: _ClassVar[int]
    HELD_CONTROLS_FIELD_NUMBER: _ClassVar[int]
    CONTROL_RESIDUAL_FIELD_NUMBER: _ClassVar[int]
    CONTROL_RESIDUAL_CAPTURE_FIELD_NUMBER: _ClassVar[int]
    CONFIDENCE_FIELD_NUMBER: _ClassVar[int]
    actor: str
    held: bool
    held_controls: int
    control_residual: float
    control_residual_capture: float
    confidence: float
    def __init__(self, actor: _Optional[str] = ..., held: _Optional[bool] = ..., held_controls: _Optional[int] = ..., control_residual: _Optional[float] = ..., control_residual_capture: _Optional[float] = ..., confidence: _Optional[float] = ...) -> None: ...

class SubscribeRequest(_message.Message):
    __slots__ = ("room", "level", "encoding")
    ROOM_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    ENCODING_FIELD_NUMBER: _ClassVar[int]
    room: str
    level: Level
    encoding: Encoding
    def __init__(self, room: _Optional[str] = ..., level: _Optional[_Union[Level, str]] = ..., encoding: _Optional[_Union[Encoding, str]] = ...) -> None: ...

class Topology(_message.Message):
    __slots__ = ("model", "level", "vertex_count", "triangle_count", "indices", "quantization", "vertex_order", "bits", "actor", "actor_index", "actor_count")
    MODEL_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    VERTEX_COUNT_FIELD_NUMBER: _ClassVar[int]
    TRIANGLE_COUNT_FIELD_NUMBER: _ClassVar[int]
    INDICES_FIELD_NUMBER: _ClassVar[int]
    QUANTIZATION_FIELD_NUMBER: _ClassVar[int]
    VERTEX_ORDER_FIELD_NUMBER: _ClassVar[int]
    BITS_FIELD_NUMBER: _ClassVar[int]
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    ACTOR_INDEX_FIELD_NUMBER: _ClassVar[int]
    ACTOR_COUNT_FIELD_NUMBER: _ClassVar[int]
    model: str
    level: Level
    vertex_count: int
    triangle_count: int
    indices: bytes
    quantization: Box3
    vertex_order: _containers.RepeatedScalarFieldContainer[int]
    bits: int
    actor: str
    actor_index: int
    actor_count: int
    def __init__(self, model: _Optional[str] = ..., level: _Optional[_Union[Level, str]] = ..., vertex_count: _Optional[int] = ..., triangle_count: _Optional[int] = ..., indices: _Optional[bytes] = ..., quantization: _Optional[_Union[Box3, _Mapping]] = ..., vertex_order: _Optional[_Iterable[int]] = ..., bits: _Optional[int] = ..., actor: _Optional[str] = ..., actor_index: _Optional[int] = ..., actor_count: _Optional[int] = ...) -> None: ...

class Frame(_message.Message):
    __slots__ = ("seq", "capture_time_us", "server_latency_us", "data", "skipped", "actors")
    SEQ_FIELD_NUMBER: _ClassVar[int]
    CAPTURE_TIME_US_FIELD_NUMBER: _ClassVar[int]
    SERVER_LATENCY_US_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    SKIPPED_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    seq: int
    capture_time_us: int
    server_latency_us: int
    data: bytes
    skipped: int
    actors: _containers.RepeatedCompositeFieldContainer[ActorFrame]
    def __init__(self, seq: _Optional[int] = ..., capture_time_us: _Optional[int] = ..., server_latency_us: _Optional[int] = ..., data: _Optional[bytes] = ..., skipped: _Optional[int] = ..., actors: _Optional[_Iterable[_Union[ActorFrame, _Mapping]]] = ...) -> None: ...

class ActorFrame(_message.Message):
    __slots__ = ("actor", "data", "held", "placement")
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    HELD_FIELD_NUMBER: _ClassVar[int]
    PLACEMENT_FIELD_NUMBER: _ClassVar[int]
    actor: int
    data: bytes
    held: bool
    placement: ActorPlacement
    def __init__(self, actor: _Optional[int] = ..., data: _Optional[bytes] = ..., held: _Optional[bool] = ..., placement: _Optional[_Union[ActorPlacement, _Mapping]] = ...) -> None: ...

class ActorPlacement(_message.Message):
    __slots__ = ("scale", "translation", "rotation")
    SCALE_FIELD_NUMBER: _ClassVar[int]
    TRANSLATION_FIELD_NUMBER: _ClassVar[int]
    ROTATION_FIELD_NUMBER: _ClassVar[int]
    scale: float
    translation: Vec3
    rotation: Quat
    def __init__(self, scale: _Optional[float] = ..., translation: _Optional[_Union[Vec3, _Mapping]] = ..., rotation: _Optional[_Union[Quat, _Mapping]] = ...) -> None: ...

class Quat(_message.Message):
    __slots__ = ("x", "y", "z", "w")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    W_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    w: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ..., w: _Optional[float] = ...) -> None: ...

class PaletteTopology(_message.Message):
    __slots__ = ("model", "level", "version", "vertex_count", "triangle_count", "indices", "bounds", "bones", "base_vertices", "rest_positions", "influences", "skin_bones", "skin_weights", "subdivision", "examples", "detail_rows", "detail_scales", "actor", "actor_index", "actor_count")
    MODEL_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    VERSION_FIELD_NUMBER: _ClassVar[int]
    VERTEX_COUNT_FIELD_NUMBER: _ClassVar[int]
    TRIANGLE_COUNT_FIELD_NUMBER: _ClassVar[int]
    INDICES_FIELD_NUMBER: _ClassVar[int]
    BOUNDS_FIELD_NUMBER: _ClassVar[int]
    BONES_FIELD_NUMBER: _ClassVar[int]
    BASE_VERTICES_FIELD_NUMBER: _ClassVar[int]
    REST_POSITIONS_FIELD_NUMBER: _ClassVar[int]
    INFLUENCES_FIELD_NUMBER: _ClassVar[int]
    SKIN_BONES_FIELD_NUMBER: _ClassVar[int]
    SKIN_WEIGHTS_FIELD_NUMBER: _ClassVar[int]
    SUBDIVISION_FIELD_NUMBER: _ClassVar[int]
    EXAMPLES_FIELD_NUMBER: _ClassVar[int]
    DETAIL_ROWS_FIELD_NUMBER: _ClassVar[int]
    DETAIL_SCALES_FIELD_NUMBER: _ClassVar[int]
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    ACTOR_INDEX_FIELD_NUMBER: _ClassVar[int]
    ACTOR_COUNT_FIELD_NUMBER: _ClassVar[int]
    model: str
    level: Level
    version: int
    vertex_count: int
    triangle_count: int
    indices: bytes
    bounds: Box3
    bones: int
    base_vertices: int
    rest_positions: bytes
    influences: int
    skin_bones: bytes
    skin_weights: bytes
    subdivision: _containers.RepeatedCompositeFieldContainer[SubdivisionStep]
    examples: int
    detail_rows: bytes
    detail_scales: bytes
    actor: str
    actor_index: int
    actor_count: int
    def __init__(self, model: _Optional[str] = ..., level: _Optional[_Union[Level, str]] = ..., version: _Optional[int] = ..., vertex_count: _Optional[int] = ..., triangle_count: _Optional[int] = ..., indices: _Optional[bytes] = ..., bounds: _Optional[_Union[Box3, _Mapping]] = ..., bones: _Optional[int] = ..., base_vertices: _Optional[int] = ..., rest_positions: _Optional[bytes] = ..., influences: _Optional[int] = ..., skin_bones: _Optional[bytes] = ..., skin_weights: _Optional[bytes] = ..., subdivision: _Optional[_Iterable[_Union[SubdivisionStep, _Mapping]]] = ..., examples: _Optional[int] = ..., detail_rows: _Optional[bytes] = ..., detail_scales: _Optional[bytes] = ..., actor: _Optional[str] = ..., actor_index: _Optional[int] = ..., actor_count: _Optional[int] = ...) -> None: ...

class SubdivisionStep(_message.Message):
    __slots__ = ("rows", "columns", "row_ptr", "cols", "weight_index", "weights")
    ROWS_FIELD_NUMBER: _ClassVar[int]
    COLUMNS_FIELD_NUMBER: _ClassVar[int]
    ROW_PTR_FIELD_NUMBER: _ClassVar[int]
    COLS_FIELD_NUMBER: _ClassVar[int]
    WEIGHT_INDEX_FIELD_NUMBER: _ClassVar[int]
    WEIGHTS_FIELD_NUMBER: _ClassVar[int]
    rows: int
    columns: int
    row_ptr: bytes
    cols: bytes
    weight_index: bytes
    weights: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, rows: _Optional[int] = ..., columns: _Optional[int] = ..., row_ptr: _Optional[bytes] = ..., cols: _Optional[bytes] = ..., weight_index: _Optional[bytes] = ..., weights: _Optional[_Iterable[float]] = ...) -> None: ...

class MeshFrame(_message.Message):
    __slots__ = ("topology", "frame", "palette_topology")
    TOPOLOGY_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    PALETTE_TOPOLOGY_FIELD_NUMBER: _ClassVar[int]
    topology: Topology
    frame: Frame
    palette_topology: PaletteTopology
    def __init__(self, topology: _Optional[_Union[Topology, _Mapping]] = ..., frame: _Optional[_Union[Frame, _Mapping]] = ..., palette_topology: _Optional[_Union[PaletteTopology, _Mapping]] = ...) -> None: ...

class SynthesizeRequest(_message.Message):
    __slots__ = ("model", "level", "beta", "frames", "refine", "skinning")
    MODEL_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    BETA_FIELD_NUMBER: _ClassVar[int]
    FRAMES_FIELD_NUMBER: _ClassVar[int]
    REFINE_FIELD_NUMBER: _ClassVar[int]
    SKINNING_FIELD_NUMBER: _ClassVar[int]
    model: str
    level: Level
    beta: float
    frames: _containers.RepeatedCompositeFieldContainer[ControlFrame]
    refine: Refine
    skinning: Skinning
    def __init__(self, model: _Optional[str] = ..., level: _Optional[_Union[Level, str]] = ..., beta: _Optional[float] = ..., frames: _Optional[_Iterable[_Union[ControlFrame, _Mapping]]] = ..., refine: _Optional[_Union[Refine, _Mapping]] = ..., skinning: _Optional[_Union[Skinning, str]] = ...) -> None: ...

class StartTakeRequest(_message.Message):
    __slots__ = ("room", "name")
    ROOM_FIELD_NUMBER: _ClassVar[int]
    NAME_FIELD_NUMBER: _ClassVar[int]
    room: str
    name: str
    def __init__(self, room: _Optional[str] = ..., name: _Optional[str] = ...) -> None: ...

class StopTakeRequest(_message.Message):
    __slots__ = ("room",)
    ROOM_FIELD_NUMBER: _ClassVar[int]
    room: str
    def __init__(self, room: _Optional[str] = ...) -> None: ...

class ListTakesRequest(_message.Message):
    __slots__ = ("room",)
    ROOM_FIELD_NUMBER: _ClassVar[int]
    room: str
    def __init__(self, room: _Optional[str] = ...) -> None: ...

class ListTakesResponse(_message.Message):
    __slots__ = ("takes",)
    TAKES_FIELD_NUMBER: _ClassVar[int]
    takes: _containers.RepeatedCompositeFieldContainer[TakeInfo]
    def __init__(self, takes: _Optional[_Iterable[_Union[TakeInfo, _Mapping]]] = ...) -> None: ...

class GetTakeRequest(_message.Message):
    __slots__ = ("take",)
    TAKE_FIELD_NUMBER: _ClassVar[int]
    take: str
    def __init__(self, take: _Optional[str] = ...) -> None: ...

class TakeChunk(_message.Message):
    __slots__ = ("data",)
    DATA_FIELD_NUMBER: _ClassVar[int]
    data: bytes
    def __init__(self, data: _Optional[bytes] = ...) -> None: ...

class TakeInfo(_message.Message):
    __slots__ = ("take", "room", "name", "model", "model_sha256", "started_unix_us", "frames", "duration_us", "bytes", "recording", "truncated")
    TAKE_FIELD_NUMBER: _ClassVar[int]
    ROOM_FIELD_NUMBER: _ClassVar[int]
    NAME_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    MODEL_SHA256_FIELD_NUMBER: _ClassVar[int]
    STARTED_UNIX_US_FIELD_NUMBER: _ClassVar[int]
    FRAMES_FIELD_NUMBER: _ClassVar[int]
    DURATION_US_FIELD_NUMBER: _ClassVar[int]
    BYTES_FIELD_NUMBER: _ClassVar[int]
    RECORDING_FIELD_NUMBER: _ClassVar[int]
    TRUNCATED_FIELD_NUMBER: _ClassVar[int]
    take: str
    room: str
    name: str
    model: str
    model_sha256: str
    started_unix_us: int
    frames: int
    duration_us: int
    bytes: int
    recording: bool
    truncated: bool
    def __init__(self, take: _Optional[str] = ..., room: _Optional[str] = ..., name: _Optional[str] = ..., model: _Optional[str] = ..., model_sha256: _Optional[str] = ..., started_unix_us: _Optional[int] = ..., frames: _Optional[int] = ..., duration_us: _Optional[int] = ..., bytes: _Optional[int] = ..., recording: _Optional[bool] = ..., truncated: _Optional[bool] = ...) -> None: ...
