"""crease's Python client: publish control frames as NumPy arrays into a crease server's rooms,
read the predicted meshes back as ``(V, 3)`` float32 arrays, synthesise batches, read takes and
manage models.

    import crease
    with crease.Client("http://127.0.0.1:50051", token="ADMIN") as c:
        model = c.model("demo-hand")
        meshes = c.synthesize("demo-hand", controls)        # (F, C, 3) -> (F, V, 3)

Modules: ``client`` (the gRPC API), ``stream`` (mesh streams to arrays), ``codec`` (crease's frame
codec), ``palette`` (palette streams skinned on the CPU), ``loop`` (the Loop subdivision a palette
header is rebuilt with), ``takes`` (take files), ``errors``.
The gRPC stubs (``crease.v1``) are generated from the repository's proto/ when the package is
built.
"""

from .client import Ack, Client, JobInfo, Model, Room, StoredModel, Subscription, TakeInfo, wait_ready
from .codec import CodecError
from .controls import read_controls_csv
from .errors import CreaseError, FrameRejected
from .stream import MeshStream, StreamError, Topology, decode_messages, read_capture
from .takes import Take, TakeError, parse_take

__version__ = "0.3.0"

__all__ = [
    "Ack",
    "Client",
    "CodecError",
    "CreaseError",
    "FrameRejected",
    "JobInfo",
    "MeshStream",
    "Model",
    "Room",
    "StoredModel",
    "StreamError",
    "Subscription",
    "Take",
    "TakeError",
    "TakeInfo",
    "Topology",
    "decode_messages",
    "parse_take",
    "read_capture",
    "read_controls_csv",
    "wait_ready",
]
