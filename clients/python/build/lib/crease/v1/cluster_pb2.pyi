from crease.v1 import crease_pb2 as _crease_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class RoomEntry(_message.Message):
    __slots__ = ("model", "model_sha256", "beta", "filter", "owner", "token_sha256", "base_bits", "detail_bits", "spatial_order", "keyframe_interval", "lease_ms", "renewed_unix_ms", "adoptions", "retarget", "refine", "skinning", "actors")
    MODEL_FIELD_NUMBER: _ClassVar[int]
    MODEL_SHA256_FIELD_NUMBER: _ClassVar[int]
    BETA_FIELD_NUMBER: _ClassVar[int]
    FILTER_FIELD_NUMBER: _ClassVar[int]
    OWNER_FIELD_NUMBER: _ClassVar[int]
    TOKEN_SHA256_FIELD_NUMBER: _ClassVar[int]
    BASE_BITS_FIELD_NUMBER: _ClassVar[int]
    DETAIL_BITS_FIELD_NUMBER: _ClassVar[int]
    SPATIAL_ORDER_FIELD_NUMBER: _ClassVar[int]
    KEYFRAME_INTERVAL_FIELD_NUMBER: _ClassVar[int]
    LEASE_MS_FIELD_NUMBER: _ClassVar[int]
    RENEWED_UNIX_MS_FIELD_NUMBER: _ClassVar[int]
    ADOPTIONS_FIELD_NUMBER: _ClassVar[int]
    RETARGET_FIELD_NUMBER: _ClassVar[int]
    REFINE_FIELD_NUMBER: _ClassVar[int]
    SKINNING_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    model: str
    model_sha256: str
    beta: float
    filter: _crease_pb2.MarkerFilter
    owner: str
    token_sha256: bytes
    base_bits: int
    detail_bits: int
    spatial_order: bool
    keyframe_interval: int
    lease_ms: int
    renewed_unix_ms: int
    adoptions: int
    retarget: _crease_pb2.Retarget
    refine: _crease_pb2.Refine
    skinning: _crease_pb2.Skinning
    actors: _containers.RepeatedCompositeFieldContainer[ActorEntry]
    def __init__(self, model: _Optional[str] = ..., model_sha256: _Optional[str] = ..., beta: _Optional[float] = ..., filter: _Optional[_Union[_crease_pb2.MarkerFilter, _Mapping]] = ..., owner: _Optional[str] = ..., token_sha256: _Optional[bytes] = ..., base_bits: _Optional[int] = ..., detail_bits: _Optional[int] = ..., spatial_order: _Optional[bool] = ..., keyframe_interval: _Optional[int] = ..., lease_ms: _Optional[int] = ..., renewed_unix_ms: _Optional[int] = ..., adoptions: _Optional[int] = ..., retarget: _Optional[_Union[_crease_pb2.Retarget, _Mapping]] = ..., refine: _Optional[_Union[_crease_pb2.Refine, _Mapping]] = ..., skinning: _Optional[_Union[_crease_pb2.Skinning, str]] = ..., actors: _Optional[_Iterable[_Union[ActorEntry, _Mapping]]] = ...) -> None: ...

class ActorEntry(_message.Message):
    __slots__ = ("actor", "model_sha256")
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    MODEL_SHA256_FIELD_NUMBER: _ClassVar[int]
    actor: _crease_pb2.Actor
    model_sha256: str
    def __init__(self, actor: _Optional[_Union[_crease_pb2.Actor, _Mapping]] = ..., model_sha256: _Optional[str] = ...) -> None: ...

class Interest(_message.Message):
    __slots__ = ("replica", "level", "ttl_ms", "encoding")
    REPLICA_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    TTL_MS_FIELD_NUMBER: _ClassVar[int]
    ENCODING_FIELD_NUMBER: _ClassVar[int]
    replica: str
    level: _crease_pb2.Level
    ttl_ms: int
    encoding: _crease_pb2.Encoding
    def __init__(self, replica: _Optional[str] = ..., level: _Optional[_Union[_crease_pb2.Level, str]] = ..., ttl_ms: _Optional[int] = ..., encoding: _Optional[_Union[_crease_pb2.Encoding, str]] = ...) -> None: ...

class ForwardedControl(_message.Message):
    __slots__ = ("frame", "replica")
    FRAME_FIELD_NUMBER: _ClassVar[int]
    REPLICA_FIELD_NUMBER: _ClassVar[int]
    frame: _crease_pb2.ControlFrame
    replica: str
    def __init__(self, frame: _Optional[_Union[_crease_pb2.ControlFrame, _Mapping]] = ..., replica: _Optional[str] = ...) -> None: ...
