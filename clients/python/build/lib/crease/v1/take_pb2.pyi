from crease.v1 import crease_pb2 as _crease_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class TakeHeader(_message.Message):
    __slots__ = ("take", "name", "room", "model_sha256", "started_unix_us", "bones", "controls", "actors")
    TAKE_FIELD_NUMBER: _ClassVar[int]
    NAME_FIELD_NUMBER: _ClassVar[int]
    ROOM_FIELD_NUMBER: _ClassVar[int]
    MODEL_SHA256_FIELD_NUMBER: _ClassVar[int]
    STARTED_UNIX_US_FIELD_NUMBER: _ClassVar[int]
    BONES_FIELD_NUMBER: _ClassVar[int]
    CONTROLS_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    take: str
    name: str
    room: _crease_pb2.OpenRoomRequest
    model_sha256: str
    started_unix_us: int
    bones: int
    controls: int
    actors: _containers.RepeatedCompositeFieldContainer[TakeActor]
    def __init__(self, take: _Optional[str] = ..., name: _Optional[str] = ..., room: _Optional[_Union[_crease_pb2.OpenRoomRequest, _Mapping]] = ..., model_sha256: _Optional[str] = ..., started_unix_us: _Optional[int] = ..., bones: _Optional[int] = ..., controls: _Optional[int] = ..., actors: _Optional[_Iterable[_Union[TakeActor, _Mapping]]] = ...) -> None: ...

class TakeActor(_message.Message):
    __slots__ = ("actor", "model_sha256", "bones", "controls")
    ACTOR_FIELD_NUMBER: _ClassVar[int]
    MODEL_SHA256_FIELD_NUMBER: _ClassVar[int]
    BONES_FIELD_NUMBER: _ClassVar[int]
    CONTROLS_FIELD_NUMBER: _ClassVar[int]
    actor: str
    model_sha256: str
    bones: int
    controls: int
    def __init__(self, actor: _Optional[str] = ..., model_sha256: _Optional[str] = ..., bones: _Optional[int] = ..., controls: _Optional[int] = ...) -> None: ...

class TakeFrame(_message.Message):
    __slots__ = ("frame", "received_us", "controls", "transforms", "actors")
    FRAME_FIELD_NUMBER: _ClassVar[int]
    RECEIVED_US_FIELD_NUMBER: _ClassVar[int]
    CONTROLS_FIELD_NUMBER: _ClassVar[int]
    TRANSFORMS_FIELD_NUMBER: _ClassVar[int]
    ACTORS_FIELD_NUMBER: _ClassVar[int]
    frame: _crease_pb2.ControlFrame
    received_us: int
    controls: _containers.RepeatedScalarFieldContainer[float]
    transforms: _containers.RepeatedScalarFieldContainer[float]
    actors: _containers.RepeatedCompositeFieldContainer[TakeActorPose]
    def __init__(self, frame: _Optional[_Union[_crease_pb2.ControlFrame, _Mapping]] = ..., received_us: _Optional[int] = ..., controls: _Optional[_Iterable[float]] = ..., transforms: _Optional[_Iterable[float]] = ..., actors: _Optional[_Iterable[_Union[TakeActorPose, _Mapping]]] = ...) -> None: ...

class TakeActorPose(_message.Message):
    __slots__ = ("controls", "transforms")
    CONTROLS_FIELD_NUMBER: _ClassVar[int]
    TRANSFORMS_FIELD_NUMBER: _ClassVar[int]
    controls: _containers.RepeatedScalarFieldContainer[float]
    transforms: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, controls: _Optional[_Iterable[float]] = ..., transforms: _Optional[_Iterable[float]] = ...) -> None: ...
