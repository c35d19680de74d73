"""``Client``: a crease server's gRPC API with NumPy arrays in and out."""

from __future__ import annotations

import hashlib
import time
import urllib.error
import urllib.request
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import grpc
import numpy as np

from .errors import CreaseError, FrameRejected, code_name
from .stream import MeshStream, Topology
from .takes import Take, parse_take
from .v1 import crease_pb2 as pb
from .v1 import crease_pb2_grpc

Level = Literal["base", "detail"]
Encoding = Literal["vertices", "palette"]
Skinning = Literal["lbs", "dqs"]

_LEVEL = {"base": pb.LEVEL_BASE, "detail": pb.LEVEL_DETAIL}
_ENCODING = {"vertices": pb.ENCODING_VERTICES, "palette": pb.ENCODING_PALETTE}
_SKINNING = {None: pb.SKINNING_UNSPECIFIED, "lbs": pb.SKINNING_LBS, "dqs": pb.SKINNING_DQS}
_SKINNING_NAME = {pb.SKINNING_LBS: "lbs", pb.SKINNING_DQS: "dqs", pb.SKINNING_UNSPECIFIED: "lbs"}

#: Most bytes of control frames per Synthesize request: 1 MiB under the server's default 4 MiB
#: message limit (as ``crease synth --server``).
CHUNK_BYTES = 3 << 20
#: Bytes per UploadModel chunk (the server takes at most 4 MiB of data per chunk).
UPLOAD_CHUNK = 1 << 20
#: The receive limit: a batch's frames can be large (a detail palette header is ~1.4 MB).
MAX_RECEIVE = 1 << 30


@dataclass(frozen=True)
class Model:
    """A model a server hosts (``GetModel``), its control points as arrays."""

    name: str
    base_vertices: int
    base_triangles: int
    #: 0 when the model has no detail layer.
    detail_vertices: int
    detail_triangles: int
    bones: int
    method: str
    skinning: str
    default_beta: float
    #: The control points in frame order: names, the rest-mesh vertex each sits on, and
    #: ``(C, 3)`` float32 rest positions.
    control_names: list[str]
    control_vertices: np.ndarray
    control_rest: np.ndarray
    #: ``(2, 3)``: the rest mesh's bounding box, min then max.
    bounds: np.ndarray

    @classmethod
    def from_message(cls, m: pb.ModelInfo) -> "Model":
        cps = sorted(m.control_points, key=lambda c: c.id)
        return cls(
            name=m.name,
            base_vertices=m.base_vertices,
            base_triangles=m.base_triangles,
            detail_vertices=m.detail_vertices,
            detail_triangles=m.detail_triangles,
            bones=m.bones,
            method=m.method,
            skinning=_SKINNING_NAME.get(m.skinning, "lbs"),
            default_beta=m.default_beta,
            control_names=[c.name for c in cps],
            control_vertices=np.array([c.vertex for c in cps], dtype=np.uint32),
            control_rest=np.array([[c.rest.x, c.rest.y, c.rest.z] for c in cps], dtype=np.float32).reshape(-1, 3),
            bounds=np.array(
                [[m.bounds.min.x, m.bounds.min.y, m.bounds.min.z], [m.bounds.max.x, m.bounds.max.y, m.bounds.max.z]],
                dtype=np.float32,
            ),
        )


@dataclass(frozen=True)
class StoredModel:
    """A model file in a cluster's object store (``ListModels``' cluster list)."""

    name: str
    sha256: str
    bytes: int


@dataclass(frozen=True)
class Room:
    """An opened room and the token that publishes into it."""

    room: str
    publish_token: str
    model: Model


@dataclass(frozen=True)
class Ack:
    """The server's answer to one published frame (``PublishAck``)."""

    seq: int
    server_latency_us: int
    held_controls: int
    #: RMS distance from the frame's valid control points to the predicted mesh (model units).
    control_residual: float
    control_residual_capture: float
    #: Distance to the training examples (1: as far as the farthest example from its neighbour).
    confidence: float
    #: ``(code name, message)`` when the frame was refused; None when accepted.
    error: tuple[str, str] | None


@dataclass(frozen=True)
class TakeInfo:
    """A take in a server's takes folder (``ListTakes``)."""

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


@dataclass(frozen=True)
class JobInfo:
    """A batch job on a server (``SubmitJob``, issue 45): its progress and state (``queued``,
    ``running``, ``done``, ``failed``, ``cancelled``)."""

    job: str
    name: str
    model: str
    state: str
    frames_total: int
    frames_done: int
    chunks_total: int
    chunks_done: int
    frames_per_second: float
    eta_seconds: float
    error: str
    #: How its result's frames travel: "vertices" or "palette".
    encoding: str = "vertices"

    @property
    def ended(self) -> bool:
        return self.state in ("done", "failed", "cancelled")


_JOB_STATE = {
    pb.JOB_STATE_QUEUED: "queued",
    pb.JOB_STATE_RUNNING: "running",
    pb.JOB_STATE_DONE: "done",
    pb.JOB_STATE_FAILED: "failed",
    pb.JOB_STATE_CANCELLED: "cancelled",
}


def _job_info(j: pb.JobInfo) -> JobInfo:
    return JobInfo(
        j.job,
        j.name,
        j.model,
        _JOB_STATE.get(j.state, "queued"),
        j.frames_total,
        j.frames_done,
        j.chunks_total,
        j.chunks_done,
        j.frames_per_second,
        j.eta_seconds,
        j.error,
        "palette" if j.encoding == pb.ENCODING_PALETTE else "vertices",
    )


def _take_info(t: pb.TakeInfo) -> TakeInfo:
    return TakeInfo(
        t.take, t.room, t.name, t.model, t.model_sha256, t.started_unix_us, t.frames, t.duration_us, t.bytes, t.recording, t.truncated
    )


def _valid_mask(valid: np.ndarray) -> bytes:
    """The wire's validity bitmask (bit i of byte i // 8, least significant first); empty when
    every point is valid."""
    if valid.all():
        return b""
    return np.packbits(valid.astype(np.uint8), bitorder="little").tobytes()


def _frames(frames: np.ndarray | Iterable[np.ndarray]) -> Iterator[np.ndarray]:
    """The frames of an ``(F, C, 3)`` array or an iterable of ``(C, 3)`` arrays, checked."""
    if isinstance(frames, np.ndarray):
        if frames.ndim != 3 or frames.shape[2] != 3:
            raise ValueError(f"frames: expected an (F, C, 3) array, got shape {frames.shape}")
    for i, f in enumerate(frames):
        f = np.asarray(f, dtype=np.float32)
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"frames[{i}]: expected a (C, 3) array, got shape {f.shape}")
        yield f


def _control_batch(controls: np.ndarray) -> np.ndarray:
    """``controls`` as a float32 ``(F, C, 3)`` array (ValueError otherwise)."""
    controls = np.asarray(controls, dtype=np.float32)
    if controls.ndim != 3 or controls.shape[2] != 3:
        raise ValueError(f"controls: expected an (F, C, 3) array, got shape {controls.shape}")
    return controls


def _frames_per_message(points: int, max_frames: int) -> int:
    """Control frames of ``points`` points per request or message: at most ``max_frames`` and
    ``CHUNK_BYTES`` (an upper bound of an encoded frame: positions, mask, seq, tags), at least 1."""
    return max(1, min(max_frames, CHUNK_BYTES // (12 * points + (points + 7) // 8 + 32)))


def _points(f: np.ndarray) -> tuple[np.ndarray, bytes]:
    """A frame's flat positions (NaN rows sent as 0) and validity mask (NaN rows invalid)."""
    valid = np.isfinite(f).all(axis=1)
    flat = np.where(valid[:, None], f, 0.0).astype(np.float32).reshape(-1)
    return flat, _valid_mask(valid)


class Subscription:
    """A room's mesh stream (``Client.subscribe``): iterate it for ``(seq, vertices)``; ``vertices``
    is ``(V, 3)`` float32 in the model's vertex order (a dict of them by actor for a room of
    several actors). ``topology`` (after the first frame, or ``wait_topology``) says what the
    frames index into. A slow reader skips frames (the room is latest-wins), never delays the
    room; ``cancel()`` (or leaving a ``with`` block) ends the stream."""

    def __init__(self, call: Any, what: str) -> None:
        self._call = call
        self._what = what
        self._stream = MeshStream()
        #: Bytes of the frames received (their ``data``), for a bandwidth figure.
        self.frame_bytes = 0

    @property
    def topologies(self) -> list[Topology]:
        return self._stream.topologies

    @property
    def topology(self) -> Topology:
        """The first (or only) actor's topology; wait_topology() first if no frame came yet."""
        if not self._stream.topologies:
            self.wait_topology()
        return self._stream.topologies[0]

    def wait_topology(self) -> list[Topology]:
        """Reads the stream's topologies (every actor's) and returns them."""
        try:
            while not self._stream.ready:
                out = self._stream.push(next(self._call))
                if out is not None:  # pragma: no cover - push refuses frames before topologies
                    raise CreaseError("INTERNAL", f"{self._what}: a frame before the topology")
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=self._what) from None
        except StopIteration:
            raise CreaseError("UNAVAILABLE", f"{self._what}: the stream ended before its topology") from None
        return self._stream.topologies

    def __iter__(self) -> Iterator[tuple[int, np.ndarray | dict[str, np.ndarray]]]:
        try:
            for message in self._call:
                if message.WhichOneof("body") == "frame":
                    f = message.frame
                    self.frame_bytes += len(f.data) + sum(len(a.data) for a in f.actors)
                out = self._stream.push(message)
                if out is not None:
                    yield out
        except grpc.RpcError as e:
            if e.code() == grpc.StatusCode.CANCELLED:
                return
            raise CreaseError.from_rpc(e, what=self._what) from None

    def cancel(self) -> None:
        self._call.cancel()

    def __enter__(self) -> "Subscription":
        return self

    def __exit__(self, *exc: object) -> None:
        self.cancel()


class Client:
    """A crease server's gRPC API.

    Args:
        url: the server's gRPC address, ``http://host:port`` (``https://`` for TLS).
        token: the server's admin token (opening and closing rooms, takes, models); a room's
            publish token for ``publish`` comes from ``open_room`` or the ``token`` argument.
        ca: with ``https://``, the server's CA certificate (PEM file); default: system roots.
        http: the server's HTTP address (``http://host:port``), for ``take_glb``.
        timeout: seconds for unary calls (None: no limit).

    Errors from the server are raised as ``CreaseError`` with its code and message.
    """

    def __init__(
        self,
        url: str = "http://127.0.0.1:50051",
        token: str | None = None,
        *,
        ca: str | Path | None = None,
        http: str | None = None,
        timeout: float | None = 60.0,
    ) -> None:
        options = [("grpc.max_receive_message_length", MAX_RECEIVE), ("grpc.max_send_message_length", 64 << 20)]
        if url.startswith("https://"):
            creds = grpc.ssl_channel_credentials(Path(ca).read_bytes() if ca else None)
            self._channel = grpc.secure_channel(url.removeprefix("https://"), creds, options)
        elif url.startswith("http://"):
            self._channel = grpc.insecure_channel(url.removeprefix("http://"), options)
        else:
            raise ValueError(f"url {url!r}: expected http://host:port or https://host:port")
        self.url = url
        self.http = http.rstrip("/") if http else None
        self._token = token
        self._timeout = timeout
        self._stub = crease_pb2_grpc.CreaseStub(self._channel)
        self._room_tokens: dict[str, str] = {}

    # -- plumbing ---------------------------------------------------------------------------

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _auth(self, token: str | None = None) -> list[tuple[str, str]]:
        token = token if token is not None else self._token
        return [("authorization", f"Bearer {token}")] if token else []

    def _unary(self, method: str, request: Any, what: str, admin: bool = False) -> Any:
        try:
            return getattr(self._stub, method)(request, timeout=self._timeout, metadata=self._auth() if admin else None)
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=what) from None

    # -- models -----------------------------------------------------------------------------

    def models(self) -> list[Model]:
        """The models the server has loaded."""
        return [Model.from_message(m) for m in self._unary("ListModels", pb.ListModelsRequest(), "ListModels").models]

    def cluster_models(self) -> list[StoredModel]:
        """In a cluster, every model of its object store (loaded here or not); [] on one server."""
        r = self._unary("ListModels", pb.ListModelsRequest(), "ListModels")
        return [StoredModel(m.name, m.sha256, m.bytes) for m in r.cluster]

    def model(self, name: str) -> Model:
        """One model: counts, bones, its control points (names, vertices, rest positions)."""
        return Model.from_message(self._unary("GetModel", pb.GetModelRequest(model=name), f"model {name!r}"))

    def upload_model(self, name: str, model: str | Path | bytes) -> Model:
        """Uploads a model file (``crease train --out``; a path or its bytes) as ``name`` (admin
        token). The server checks its size and SHA-256, writes it into its models folder
        atomically and loads it; in a cluster it is offered to the object store."""
        data = model if isinstance(model, bytes) else Path(model).read_bytes()
        digest = hashlib.sha256(data).hexdigest()

        def chunks() -> Iterator[pb.ModelChunk]:
            yield pb.ModelChunk(name=name, size=len(data), sha256=digest, data=data[:UPLOAD_CHUNK])
            for at in range(UPLOAD_CHUNK, len(data), UPLOAD_CHUNK):
                yield pb.ModelChunk(data=data[at : at + UPLOAD_CHUNK])

        try:
            info = self._stub.UploadModel(chunks(), timeout=self._timeout, metadata=self._auth())
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=f"uploading model {name!r}") from None
        return Model.from_message(info)

    def delete_model(self, name: str) -> None:
        """Deletes a model from the server's folder and registry (admin token); refused
        (FAILED_PRECONDITION) while a room uses it."""
        self._unary("DeleteModel", pb.DeleteModelRequest(model=name), f"deleting model {name!r}", admin=True)

    # -- rooms ------------------------------------------------------------------------------

    def open_room(
        self,
        room: str,
        model: str = "",
        *,
        beta: float = 0.0,
        skinning: Skinning | None = None,
        filter: Mapping[str, float] | None = None,
        refine: Mapping[str, float] | None = None,
        retarget: Mapping[str, Any] | None = None,
        actors: Iterable[Mapping[str, Any]] = (),
    ) -> Room:
        """Opens a room on a model (admin token) and returns it with its publish token, which
        ``publish`` then uses for this room.

        ``filter`` (``min_cutoff_hz``, ``beta``, ``d_cutoff_hz``), ``refine`` (``iterations``,
        ``strength``) and ``retarget`` (``map_toml`` or ``map_name``, ``markers``, ``units``) are
        the fields of the proto messages of the same names; ``actors`` a list of ``Actor`` fields
        (``name``, ``model``, ``side``, ``mirror``, ...) for a room of several actors. Without
        ``refine`` the room gets the server's refinement (``crease-server --refine``, 8 rounds
        at strength 0.01 unless set); ``refine={"iterations": 0}`` turns it off.
        """
        request = pb.OpenRoomRequest(room=room, model=model, beta=beta, skinning=_SKINNING[skinning])
        if filter is not None:
            request.filter.CopyFrom(pb.MarkerFilter(**filter))
        if refine is not None:
            request.refine.CopyFrom(pb.Refine(**refine))
        if retarget is not None:
            request.retarget.CopyFrom(pb.Retarget(**retarget))
        for a in actors:
            request.actors.append(pb.Actor(**a))
        r = self._unary("OpenRoom", request, f"opening room {room!r}", admin=True)
        self._room_tokens[r.room] = r.publish_token
        return Room(r.room, r.publish_token, Model.from_message(r.model))

    def close_room(self, room: str) -> None:
        """Closes a room (admin token); its subscribers' streams end."""
        self._unary("CloseRoom", pb.CloseRoomRequest(room=room), f"closing room {room!r}", admin=True)
        self._room_tokens.pop(room, None)

    def room(self, room: str) -> pb.RoomInfo:
        """A room's model, settings and counters (the ``RoomInfo`` message)."""
        return self._unary("GetRoom", pb.GetRoomRequest(room=room), f"room {room!r}")

    def publish(
        self,
        room: str,
        frames: np.ndarray | Iterable[np.ndarray],
        *,
        token: str | None = None,
        fps: float | None = None,
        first_seq: int = 0,
        markers: bool = False,
        check: bool = True,
    ) -> list[Ack]:
        """Publishes control frames into a room and returns one ack per frame.

        Args:
            frames: an ``(F, C, 3)`` array, or an iterable (a generator of live frames) of
                ``(C, 3)`` arrays, of every control point in model order (model units). A point
                with a NaN coordinate is sent as not seen: the room holds its last position.
            token: the room's publish token (default: the one ``open_room`` returned here, else
                the client's token).
            fps: send at most this many frames per second (subscribers of a latest-wins room
                see every frame only when frames come no faster than they are read); None: as
                fast as the acks allow.
            first_seq: the first frame's sequence number (then +1 per frame).
            markers: the room retargets raw markers: each frame holds the markers the room
                declared (``Retarget.markers``), in the capture's units.
            check: raise ``FrameRejected`` for the first frame the room refused (after every
                frame was sent); False: return its ack with ``error`` set.
        """
        token = token or self._room_tokens.get(room) or self._token
        period = 1.0 / fps if fps else 0.0

        def requests() -> Iterator[pb.ControlFrame]:
            start = time.perf_counter()
            for i, f in enumerate(_frames(frames)):
                if period:
                    wait = start + i * period - time.perf_counter()
                    if wait > 0:
                        time.sleep(wait)
                flat, valid = _points(f)
                now_us = time.time_ns() // 1000
                if markers:
                    yield pb.ControlFrame(room=room, seq=first_seq + i, capture_time_us=now_us, markers=flat, markers_valid=valid)
                else:
                    yield pb.ControlFrame(room=room, seq=first_seq + i, capture_time_us=now_us, positions=flat, valid=valid)

        acks: list[Ack] = []
        try:
            for a in self._stub.Publish(requests(), metadata=self._auth(token)):
                error = (code_name(a.error.code), a.error.message) if a.HasField("error") else None
                acks.append(
                    Ack(
                        a.seq,
                        a.server_latency_us,
                        a.held_controls,
                        a.control_residual,
                        a.control_residual_capture,
                        a.confidence,
                        error,
                    )
                )
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=f"publishing into room {room!r}") from None
        if check:
            for i, a in enumerate(acks):
                if a.error is not None:
                    raise FrameRejected(a.error[0], f"room {room!r} refused frame seq {a.seq}: {a.error[1]}", i, a.seq)
        return acks

    def subscribe(self, room: str, level: Level = "base", encoding: Encoding = "vertices") -> Subscription:
        """A room's meshes: iterate the returned ``Subscription`` for ``(seq, vertices)``.

        ``level`` "base" (the skinned mesh) or "detail" (the subdivided mesh with the detail
        layer); ``encoding`` "vertices" (every vertex quantised to 16 bits) or "palette" (bones
        and the detail kernel vector, skinned here on the CPU exactly as the viewer's GPU does).
        """
        if level not in _LEVEL:
            raise ValueError(f"level {level!r}: expected 'base' or 'detail'")
        if encoding not in _ENCODING:
            raise ValueError(f"encoding {encoding!r}: expected 'vertices' or 'palette'")
        call = self._stub.Subscribe(pb.SubscribeRequest(room=room, level=_LEVEL[level], encoding=_ENCODING[encoding]))
        return Subscription(call, f"subscribing to room {room!r}")

    # -- batches ----------------------------------------------------------------------------

    def synthesize(
        self,
        model: str,
        controls: np.ndarray,
        *,
        level: Level = "base",
        beta: float = 0.0,
        skinning: Skinning | None = None,
        refine: Mapping[str, float] | None = None,
        chunk_frames: int = 2000,
    ) -> np.ndarray:
        """The meshes of a batch of control frames: ``(F, C, 3)`` in, ``(F, V, 3)`` float32 out (model
        vertex order, quantised to 16 bits in the model's pose box).

        NaN rows are occluded points, held at their last valid position across the whole batch
        (requests of at most ``chunk_frames`` frames and 3 MiB carry the held points over, as
        ``crease synth --server`` does). A refused frame raises ``CreaseError`` whose ``frame``
        is its index in ``controls``. ``refine`` as ``open_room``'s: the server's default
        when absent.
        """
        controls = _control_batch(controls)
        if chunk_frames < 1:
            raise ValueError("chunk_frames must be at least 1")
        count, points = controls.shape[0], controls.shape[1]
        per_request = _frames_per_message(points, chunk_frames)
        out: np.ndarray | None = None
        held = np.full((points, 3), np.nan, dtype=np.float32)
        for first in range(0, count, per_request):
            chunk = controls[first : first + per_request]
            request = pb.SynthesizeRequest(model=model, level=_LEVEL[level], beta=beta, skinning=_SKINNING[skinning])
            if refine is not None:
                request.refine.CopyFrom(pb.Refine(**refine))
            for k, f in enumerate(chunk):
                valid = np.isfinite(f).all(axis=1)
                if k == 0 and first > 0:
                    # The first frame of a later request starts from the held points.
                    f = np.where(valid[:, None], f, held)
                flat, mask = _points(f)
                request.frames.append(pb.ControlFrame(seq=first + k, positions=flat, valid=mask))
                held = np.where(valid[:, None], f, held)
            stream = MeshStream()
            received = 0
            what = f"synthesising frames {first}..{first + len(chunk)} of {model!r}"
            try:
                for message in self._stub.Synthesize(request, timeout=None):
                    if not stream.ready:
                        stream.push(message)
                        if stream.ready and out is None:
                            out = np.empty((count, stream.topologies[0].vertex_count, 3), dtype=np.float32)
                        continue
                    if received >= len(chunk):
                        raise CreaseError("INTERNAL", f"{what}: more frames than were sent")
                    assert out is not None
                    stream.decode_into(message, out[first + received])
                    received += 1
            except grpc.RpcError as e:
                raise CreaseError.from_rpc(e, first=first, what=what) from None
            if received != len(chunk):
                raise CreaseError("DATA_LOSS", f"{what}: {received} frames came back for {len(chunk)}")
        if out is None:
            return np.zeros((0, 0, 3), dtype=np.float32)
        return out

    # -- jobs -------------------------------------------------------------------------------

    def submit_job(
        self,
        model: str = "",
        controls: np.ndarray | None = None,
        *,
        take: str = "",
        markers: np.ndarray | None = None,
        marker_names: Sequence[str] = (),
        marker_map: str = "",
        units: str = "",
        level: Level = "base",
        encoding: Encoding = "vertices",
        beta: float = 0.0,
        skinning: Skinning | None = None,
        refine: Mapping[str, float] | None = None,
        name: str = "",
    ) -> JobInfo:
        """Hands a batch to the server as a job that outlives this client (admin token) and
        returns it at once. The frames are one of: ``controls`` (``(F, C, 3)``, NaN rows
        occluded) on ``model``; ``markers`` (``(F, M, 3)`` raw capture markers named
        ``marker_names``, NaN rows missing, in ``units``) on ``model``, retargeted by the server
        through the marker map ``marker_map`` (its TOML text, as ``bench/mocap/*.toml``) as
        ``crease retarget`` does; or ``take``, a take recorded on this server (its model,
        settings and control points; ``model`` and the settings are then ignored). The server
        checks every frame: a refused one raises ``CreaseError`` whose ``frame`` is its index,
        and nothing is queued. ``encoding`` "palette" keeps the bones instead of every vertex
        (``job_result`` skins them on the CPU). ``watch_job`` follows it, ``job_result`` fetches
        it."""
        if encoding not in _ENCODING:
            raise ValueError(f"encoding {encoding!r}: expected 'vertices' or 'palette'")
        given = [n for n, v in (("controls", controls), ("markers", markers), ("take", take or None)) if v is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of controls, markers and take, got {given or 'none'}")
        spec = pb.JobSpec(model=model, level=_LEVEL[level], beta=beta, skinning=_SKINNING[skinning], name=name, take=take, encoding=_ENCODING[encoding])
        if refine is not None:
            spec.refine.CopyFrom(pb.Refine(**refine))
        frames_in = np.zeros((0, 0, 3), dtype=np.float32)
        if markers is not None:
            frames_in = _control_batch(markers)
            if len(marker_names) != frames_in.shape[1]:
                raise ValueError(f"marker_names: {len(marker_names)} names for {frames_in.shape[1]} markers a frame")
            if not marker_map:
                raise ValueError("marker_map: the map's TOML text is needed with markers")
            spec.retarget.CopyFrom(pb.Retarget(map_toml=marker_map, markers=list(marker_names), units=units))
        elif controls is not None:
            frames_in = _control_batch(controls)
        per_message = _frames_per_message(frames_in.shape[1], len(frames_in) or 1)

        def messages() -> Iterator[pb.SubmitJobRequest]:
            yield pb.SubmitJobRequest(spec=spec)
            for first in range(0, len(frames_in), per_message):
                frames = pb.JobFrames()
                for k, f in enumerate(frames_in[first : first + per_message]):
                    flat, mask = _points(f)
                    if markers is not None:
                        frames.frames.append(pb.ControlFrame(seq=first + k, markers=flat, markers_valid=mask))
                    else:
                        frames.frames.append(pb.ControlFrame(seq=first + k, positions=flat, valid=mask))
                yield pb.SubmitJobRequest(frames=frames)

        what = f"submitting take {take!r} as a job" if take else f"submitting a job of {len(frames_in)} frames on {model!r}"
        try:
            info = self._stub.SubmitJob(messages(), timeout=self._timeout, metadata=self._auth())
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=what) from None
        return _job_info(info)

    def watch_job(self, job: str) -> Iterator[JobInfo]:
        """A job's status now, then each change, until it ends."""
        try:
            for info in self._stub.WatchJob(pb.WatchJobRequest(job=job), timeout=None):
                yield _job_info(info)
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=f"watching job {job!r}") from None

    def job_result(self, job: str) -> np.ndarray:
        """A done job's meshes, ``(F, V, 3)`` float32 (model vertex order, quantised to 16 bits in
        the model's pose box, as ``synthesize``'s)."""
        frames_total = None
        for info in self.watch_job(job):
            frames_total = info.frames_total
            break
        stream = MeshStream()
        out: np.ndarray | None = None
        received = 0
        what = f"fetching job {job!r}"
        try:
            for message in self._stub.GetJobResult(pb.GetJobResultRequest(job=job), timeout=None):
                if not stream.ready:
                    stream.push(message)
                    if stream.ready:
                        out = np.empty((frames_total or 0, stream.topologies[0].vertex_count, 3), dtype=np.float32)
                    continue
                if out is None or received >= len(out):
                    raise CreaseError("INTERNAL", f"{what}: more frames than the job holds")
                stream.decode_into(message, out[received])
                received += 1
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=what) from None
        if out is None or received != len(out):
            raise CreaseError("DATA_LOSS", f"{what}: {received} frames came back for {frames_total}")
        return out

    def jobs(self) -> list[JobInfo]:
        """The server's jobs, newest first."""
        return [_job_info(j) for j in self._unary("ListJobs", pb.ListJobsRequest(), "ListJobs").jobs]

    def cancel_job(self, job: str) -> JobInfo:
        """Cancels a queued or running job (admin token): no chunk of it starts after this."""
        return _job_info(self._unary("CancelJob", pb.CancelJobRequest(job=job), f"cancelling job {job!r}", admin=True))

    # -- takes ------------------------------------------------------------------------------

    def start_take(self, room: str, name: str = "") -> TakeInfo:
        """Starts recording a room's take (admin token)."""
        return _take_info(self._unary("StartTake", pb.StartTakeRequest(room=room, name=name), f"starting a take of {room!r}", admin=True))

    def stop_take(self, room: str) -> TakeInfo:
        """Stops a room's take (admin token) and returns it, complete."""
        return _take_info(self._unary("StopTake", pb.StopTakeRequest(room=room), f"stopping the take of {room!r}", admin=True))

    def takes(self, room: str = "") -> list[TakeInfo]:
        """The server's takes, newest first (only ``room``'s when given)."""
        return [_take_info(t) for t in self._unary("ListTakes", pb.ListTakesRequest(room=room), "ListTakes").takes]

    def take_bytes(self, take: str) -> bytes:
        """A take's file as the server holds it (``take.proto`` layout)."""
        try:
            return b"".join(c.data for c in self._stub.GetTake(pb.GetTakeRequest(take=take), timeout=self._timeout))
        except grpc.RpcError as e:
            raise CreaseError.from_rpc(e, what=f"take {take!r}") from None

    def take_frames(self, take: str) -> Take:
        """A take's frames as arrays: per actor ``(F, C, 3)`` controls and ``(F, B, 7)`` bone
        transforms, with every frame's seq, capture and arrival times."""
        return parse_take(self.take_bytes(take))

    def rooms(self) -> list[str]:
        """The rooms the server (or its cluster) lists (the HTTP ``/api/rooms``; private rooms are
        not listed): needs the client's ``http`` address."""
        import json

        return list(json.loads(self._http_get("/api/rooms", "the room list"))["rooms"])

    def _http_get(self, path: str, what: str) -> bytes:
        if not self.http:
            raise ValueError(f"{what} needs the server's HTTP address: Client(..., http='http://host:port')")
        url = f"{self.http}{path}"
        try:
            with urllib.request.urlopen(url, timeout=self._timeout) as r:
                return r.read()
        except urllib.error.HTTPError as e:
            body = e.read().decode("utf-8", "replace").strip()
            code = {404: "NOT_FOUND", 400: "INVALID_ARGUMENT", 409: "FAILED_PRECONDITION"}.get(e.code, f"HTTP_{e.code}")
            raise CreaseError(code, f"{what} ({url}): {body or e.reason}") from None
        except urllib.error.URLError as e:
            raise CreaseError("UNAVAILABLE", f"{what} ({url}): {e.reason}") from None

    def take_glb(self, take: str) -> bytes:
        """A take as a skinned, animated glTF binary (the server's ``/api/takes/ID/glb``): needs
        the client's ``http`` address."""
        return self._http_get(f"/api/takes/{urllib.request.quote(take)}/glb", f"take {take!r} as glTF")


def wait_ready(client: Client, timeout: float = 30.0) -> None:
    """Waits until the server answers ``ListModels`` (a server that is still starting)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            client.models()
            return
        except CreaseError as e:
            if e.code != "UNAVAILABLE" or time.monotonic() > deadline:
                raise
            time.sleep(0.2)


__all__ = [
    "Ack",
    "Client",
    "Model",
    "Room",
    "StoredModel",
    "Subscription",
    "TakeInfo",
    "wait_ready",
]
