"""The package's exceptions: every error from a server carries its gRPC code and message."""

from __future__ import annotations

import grpc

from .v1 import crease_pb2 as pb

_DETAILS_KEY = "grpc-status-details-bin"


class CreaseError(Exception):
    """An error from a crease server (or on the way to it).

    Attributes:
        code: the gRPC status code's name, e.g. ``"NOT_FOUND"``, ``"INVALID_ARGUMENT"``,
            ``"UNAUTHENTICATED"``, ``"UNAVAILABLE"`` (no server there).
        message: the server's message, which names the field that was wrong.
        frame: for a batch (``synthesize``) or a publish, the index of the refused frame in
            what was sent; None otherwise.
    """

    def __init__(self, code: str, message: str, frame: int | None = None) -> None:
        self.code = code
        self.message = message
        self.frame = frame
        where = f"frame {frame}: " if frame is not None else ""
        super().__init__(f"{where}{message} ({code})")

    @classmethod
    def from_rpc(cls, e: grpc.RpcError, first: int = 0, what: str = "") -> "CreaseError":
        """A ``grpc.RpcError`` as a CreaseError; a batch's refused frame (the status details'
        ``FrameError.frame``) renumbered by ``first``, and ``what`` the call, prefixed."""
        code = e.code().name if hasattr(e, "code") and e.code() is not None else "UNKNOWN"
        message = e.details() if hasattr(e, "details") and e.details() else str(e)
        frame = None
        trailing = e.trailing_metadata() if hasattr(e, "trailing_metadata") else None
        for key, value in trailing or ():
            if key == _DETAILS_KEY and isinstance(value, bytes):
                try:
                    detail = pb.FrameError.FromString(value)
                except Exception:  # noqa: BLE001 - details of another shape: keep the message
                    continue
                if detail.HasField("frame"):
                    frame = first + detail.frame
                    message = f"frames[{frame}].{detail.message}"
        if what:
            message = f"{what}: {message}"
        return cls(code, message, frame)


class FrameRejected(CreaseError):
    """A published control frame the room refused (its ack carried an error): the room kept its
    previous state. ``seq`` is the frame's sequence number."""

    def __init__(self, code: str, message: str, frame: int, seq: int) -> None:
        super().__init__(code, message, frame)
        self.seq = seq


def code_name(code: int) -> str:
    """A google.rpc.Code integer (as in ``FrameError.code``) as its name."""
    for c in grpc.StatusCode:
        if c.value[0] == code:
            return c.name
    return f"CODE_{code}"
