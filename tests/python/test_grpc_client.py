#!/usr/bin/env python3
"""A gRPC client that is not ours: drives a running crease-server from Python's grpcio.

No code is generated from proto/crease/v1/crease.proto: the service, its methods and every
message class come from the server's reflection at run time, through grpcio-reflection's own
client (ProtoReflectionDescriptorDatabase, grpc.reflection.v1alpha) behind a protobuf
DescriptorPool, message classes from message_factory.GetMessageClass. grpc.reflection.v1 is
cross-checked by hand (its messages are v1alpha's on the wire). Only grpc.health.v1 uses the
stubs that ship with grpcio-health-checking.

Checks, in order: reflection (v1alpha and v1) lists crease.v1.Crease and grpc.health.v1.Health
and serves the same file for it; ListModels has
demo-hand; GetModel(demo-hand) has vertices, 15 named control points and a proper bounds box;
health is SERVING for "" and for crease.v1.Crease; Subscribe(room demo, LEVEL_BASE) starts with a
Topology that matches the model, then frames arrive (strictly increasing seq, core::codec frames
whose header is checked byte by byte); GetModel on an unknown model is NOT_FOUND.

Usage: test_grpc_client.py --grpc 127.0.0.1:50051
Exit status: 0 all checks passed, 1 a check failed (the message says which), 2 bad arguments.
"""

import argparse
import collections
import math
import struct
import sys
import time

import google.protobuf as protobuf
import grpc
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from grpc_health.v1 import health_pb2, health_pb2_grpc

# v1alpha's messages, also used for v1: the two protocols differ only in the service name.
from grpc_reflection.v1alpha import reflection_pb2
from grpc_reflection.v1alpha.proto_reflection_descriptor_database import ProtoReflectionDescriptorDatabase

SERVICE = "crease.v1.Crease"
HEALTH_SERVICE = "grpc.health.v1.Health"
MODEL = "demo-hand"
ROOM = "demo"
CONTROL_POINTS = 15

# core/src/codec/frame.rs and the layout table in core/src/codec/mod.rs (version 1):
# magic, version, kind, flags, vertex size, bits, 3 reserved, vertex count, seq, base seq,
# min (3 x f32), step (3 x f32), payload length. Little-endian, 52 bytes.
FRAME_MAGIC = b"CRSF"
FRAME_VERSION = 1
FRAME_HEADER = struct.Struct("<4sBBBBB3sIII3f3fI")
assert FRAME_HEADER.size == 52
VERTEX_SIZE = 8
MESHOPT_VERTEX_V1 = 0xA1
KIND_KEY, KIND_DELTA = 0, 1


class Failure(Exception):
    """A check that did not hold."""


def check(cond, message):
    if not cond:
        raise Failure(message)


def ok(message):
    print(f"ok   {message}", flush=True)


class DefaultTimeout(
    grpc.UnaryUnaryClientInterceptor, grpc.UnaryStreamClientInterceptor, grpc.StreamStreamClientInterceptor
):
    """Gives every call without a deadline one (grpcio-reflection's client sets none)."""

    def __init__(self, timeout):
        self.timeout = timeout

    def _details(self, d):
        if d.timeout is not None:
            return d
        return _CallDetails(d.method, self.timeout, d.metadata, d.credentials, d.wait_for_ready, d.compression)

    def intercept_unary_unary(self, continuation, details, request):
        return continuation(self._details(details), request)

    def intercept_unary_stream(self, continuation, details, request):
        return continuation(self._details(details), request)

    def intercept_stream_stream(self, continuation, details, requests):
        return continuation(self._details(details), requests)


class _CallDetails(
    collections.namedtuple("_CallDetails", "method timeout metadata credentials wait_for_ready compression"),
    grpc.ClientCallDetails,
):
    pass


class RawReflection:
    """The reflection protocol by hand, for a version grpcio-reflection has no client for (v1)."""

    def __init__(self, channel, service, timeout):
        self.service = service
        self.timeout = timeout
        self._rpc = channel.stream_stream(
            f"/{service}/ServerReflectionInfo",
            request_serializer=reflection_pb2.ServerReflectionRequest.SerializeToString,
            response_deserializer=reflection_pb2.ServerReflectionResponse.FromString,
        )

    def _one(self, request):
        responses = list(self._rpc(iter([request]), timeout=self.timeout))
        check(len(responses) == 1, f"{self.service}: {len(responses)} responses to one request")
        res = responses[0]
        if res.WhichOneof("message_response") == "error_response":
            err = res.error_response
            raise Failure(f"{self.service}: error {err.error_code} for {request}: {err.error_message}")
        return res

    def list_services(self):
        res = self._one(reflection_pb2.ServerReflectionRequest(list_services=""))
        return [s.name for s in res.list_services_response.service]

    def file_containing_symbol(self, symbol):
        res = self._one(reflection_pb2.ServerReflectionRequest(file_containing_symbol=symbol))
        raws = res.file_descriptor_response.file_descriptor_proto
        check(len(raws) > 0, f"{self.service}: no file for {symbol}")
        return descriptor_pb2.FileDescriptorProto.FromString(raws[0])


class Crease:
    """crease.v1.Crease built from reflection: message classes and callables per method."""

    def __init__(self, channel, pool):
        self.pool = pool
        self.service = pool.FindServiceByName(SERVICE)
        self.messages = {}
        self.methods = {}
        for m in self.service.methods:
            req = self.message(m.input_type.full_name)
            res = self.message(m.output_type.full_name)
            path = f"/{self.service.full_name}/{m.name}"
            kind = {
                (False, False): channel.unary_unary,
                (False, True): channel.unary_stream,
                (True, False): channel.stream_unary,
                (True, True): channel.stream_stream,
            }[(m.client_streaming, m.server_streaming)]
            self.methods[m.name] = (
                m,
                kind(path, request_serializer=req.SerializeToString, response_deserializer=res.FromString),
            )

    def message(self, full_name):
        if full_name not in self.messages:
            desc = self.pool.FindMessageTypeByName(full_name)
            self.messages[full_name] = message_factory.GetMessageClass(desc)
        return self.messages[full_name]

    def method(self, name, client_streaming, server_streaming):
        check(name in self.methods, f"{SERVICE} has no method {name} (has {sorted(self.methods)})")
        m, rpc = self.methods[name]
        check(
            (m.client_streaming, m.server_streaming) == (client_streaming, server_streaming),
            f"{name}: streaming (client, server) = {(m.client_streaming, m.server_streaming)}, "
            f"expected {(client_streaming, server_streaming)}",
        )
        return self.message(m.input_type.full_name), rpc

    def enum_value(self, enum, value):
        return self.pool.FindEnumTypeByName(enum).values_by_name[value].number


def vec(v):
    return (v.x, v.y, v.z)


def check_box(box, what):
    lo, hi = vec(box.min), vec(box.max)
    check(all(math.isfinite(c) for c in lo + hi), f"{what}: not finite: {lo} .. {hi}")
    check(all(a < b for a, b in zip(lo, hi)), f"{what}: min {lo} is not below max {hi}")
    return lo, hi


def parse_frame(data, what):
    check(len(data) >= FRAME_HEADER.size, f"{what}: {len(data)} bytes, shorter than the 52-byte header")
    (magic, version, kind, flags, vsize, bits, _reserved, count, seq, base, *rest) = FRAME_HEADER.unpack_from(data)
    mn, step, payload_len = rest[0:3], rest[3:6], rest[6]
    check(magic == FRAME_MAGIC, f"{what}: magic {magic!r}, expected {FRAME_MAGIC!r}")
    check(version == FRAME_VERSION, f"{what}: format version {version}, expected {FRAME_VERSION}")
    check(kind in (KIND_KEY, KIND_DELTA), f"{what}: kind {kind}, expected 0 (key) or 1 (delta)")
    check(vsize == VERTEX_SIZE, f"{what}: vertex size {vsize}, expected {VERTEX_SIZE}")
    check(
        len(data) == FRAME_HEADER.size + payload_len,
        f"{what}: {len(data)} bytes, header says 52 + {payload_len}",
    )
    check(payload_len > 0 and data[FRAME_HEADER.size] == MESHOPT_VERTEX_V1, f"{what}: payload is not meshopt vertex codec v1")
    check(all(math.isfinite(c) for c in mn), f"{what}: box min not finite: {mn}")
    check(all(math.isfinite(c) and c > 0 for c in step), f"{what}: step not finite and positive: {step}")
    return {"kind": kind, "flags": flags, "bits": bits, "count": count, "seq": seq, "base": base}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grpc", required=True, metavar="HOST:PORT", help="the server's gRPC address")
    ap.add_argument("--timeout", type=float, default=10.0, help="seconds per unary call and to connect")
    ap.add_argument("--frames", type=int, default=30, help="frames to read from Subscribe (at least 10)")
    ap.add_argument("--window", type=float, default=5.0, help="seconds they must arrive in after the topology")
    args = ap.parse_args()
    if args.frames < 10:
        ap.error("--frames must be at least 10")
    target = args.grpc.removeprefix("http://")

    print(f"grpcio {grpc.__version__}, protobuf {protobuf.__version__}; server {target}", flush=True)
    # 64 MiB covers a detail-level topology of a big model; the demo's messages are far smaller.
    channel = grpc.insecure_channel(target, options=[("grpc.max_receive_message_length", 64 << 20)])
    try:
        try:
            grpc.channel_ready_future(channel).result(timeout=args.timeout)
        except grpc.FutureTimeoutError:
            raise Failure(f"could not connect to {target} within {args.timeout} s") from None
        run(channel, args)
    except Failure as e:
        print(f"FAIL {e}", file=sys.stderr, flush=True)
        return 1
    except grpc.RpcError as e:
        print(f"FAIL unexpected gRPC error {e.code().name}: {e.details()}", file=sys.stderr, flush=True)
        return 1
    finally:
        channel.close()
    print("python grpcio client: all checks passed", flush=True)
    return 0


def run(channel, args):
    t = args.timeout

    # Reflection, the stock client: grpcio-reflection's descriptor database (it speaks
    # grpc.reflection.v1alpha) behind a DescriptorPool that fetches files by symbol on demand.
    db = ProtoReflectionDescriptorDatabase(grpc.intercept_channel(channel, DefaultTimeout(t)))
    services = db.get_services()
    for s in (SERVICE, HEALTH_SERVICE):
        check(s in services, f"reflection (v1alpha) lists {services}, not {s}")
    ok(f"reflection v1alpha (grpcio-reflection's client) lists {', '.join(sorted(services))}")
    pool = descriptor_pool.DescriptorPool(db)
    crease = Crease(channel, pool)
    fdp = db.FindFileContainingSymbol(SERVICE)
    ok(f"{SERVICE} from {fdp.name} by symbol: {len(crease.methods)} methods ({', '.join(crease.methods)})")

    # The same through grpc.reflection.v1 (what grpcurl and newer tools speak).
    v1 = RawReflection(channel, "grpc.reflection.v1.ServerReflection", t)
    services_v1 = v1.list_services()
    # Each version lists itself among the services (tonic-reflection), not the other one.
    others = lambda names: sorted(n for n in names if not n.startswith("grpc.reflection."))
    check(others(services_v1) == others(services), f"reflection v1 lists {services_v1}, v1alpha {services}")
    check(v1.file_containing_symbol(SERVICE) == fdp, f"reflection v1 and v1alpha disagree on {fdp.name}")
    ok(f"reflection v1: the same services and the same {fdp.name}")

    # ListModels.
    req, list_models = crease.method("ListModels", False, False)
    names = [m.name for m in list_models(req(), timeout=t).models]
    check(MODEL in names, f"ListModels: {names}, no {MODEL}")
    ok(f"ListModels: {names}")

    # GetModel.
    req, get_model = crease.method("GetModel", False, False)
    info = get_model(req(model=MODEL), timeout=t)
    check(info.name == MODEL, f"GetModel({MODEL}) answered model {info.name!r}")
    check(info.base_vertices > 0, f"GetModel: base_vertices = {info.base_vertices}")
    check(info.base_triangles > 0, f"GetModel: base_triangles = {info.base_triangles}")
    cps = info.control_points
    check(len(cps) == CONTROL_POINTS, f"GetModel: {len(cps)} control points, expected {CONTROL_POINTS}")
    check([c.id for c in cps] == list(range(len(cps))), f"GetModel: control point ids {[c.id for c in cps]}")
    for c in cps:
        check(c.name != "", f"GetModel: control point {c.id} has no name")
        check(c.vertex < info.base_vertices, f"GetModel: control point {c.name} on vertex {c.vertex} of {info.base_vertices}")
    check(info.HasField("bounds"), "GetModel: no bounds")
    lo, hi = check_box(info.bounds, "GetModel bounds")
    ok(
        f"GetModel({MODEL}): {info.base_vertices} vertices, {info.base_triangles} triangles, "
        f"{len(cps)} control points ({', '.join(c.name for c in cps[:3])}, ...), "
        f"bounds {tuple(round(c, 3) for c in lo)} .. {tuple(round(c, 3) for c in hi)}"
    )

    # Health.
    health = health_pb2_grpc.HealthStub(channel)
    for s in ("", SERVICE):
        status = health.Check(health_pb2.HealthCheckRequest(service=s), timeout=t).status
        check(
            status == health_pb2.HealthCheckResponse.SERVING,
            f"health({s!r}): {health_pb2.HealthCheckResponse.ServingStatus.Name(status)}, expected SERVING",
        )
    ok(f'grpc.health.v1: SERVING for "" and "{SERVICE}"')

    # Subscribe: topology, then frames.
    req, subscribe = crease.method("Subscribe", False, True)
    base = crease.enum_value("crease.v1.Level", "LEVEL_BASE")
    call = subscribe(req(room=ROOM, level=base), timeout=args.window + t)
    frames = []
    try:
        stream = iter(call)
        first = next(stream, None)
        check(first is not None, "Subscribe: the stream ended before its first message")
        check(first.WhichOneof("body") == "topology", f"Subscribe: first message is {first.WhichOneof('body')}, not topology")
        topo = first.topology
        check(topo.model == MODEL, f"topology: model {topo.model!r}, expected {MODEL}")
        check(topo.level == base, f"topology: level {topo.level}, expected LEVEL_BASE ({base})")
        n = topo.vertex_count
        check(n == info.base_vertices, f"topology: vertex_count {n} != GetModel base_vertices {info.base_vertices}")
        check(
            topo.triangle_count == info.base_triangles,
            f"topology: triangle_count {topo.triangle_count} != GetModel base_triangles {info.base_triangles}",
        )
        check(len(topo.indices) > 0, "topology: no indices")
        check(1 <= topo.bits <= 16, f"topology: bits {topo.bits}")
        check_box(topo.quantization, "topology quantization")
        order = list(topo.vertex_order)
        check(not order or sorted(order) == list(range(n)), "topology: vertex_order is not a permutation of the vertices")
        ok(
            f"Subscribe({ROOM}, LEVEL_BASE) topology: {n} vertices, {topo.triangle_count} triangles, "
            f"{len(topo.indices)} index bytes, {topo.bits} bits, vertex_order {'given' if order else 'empty'}"
        )

        start = time.monotonic()
        prev = None
        for msg in stream:
            check(msg.WhichOneof("body") == "frame", f"Subscribe: message {len(frames) + 2} is {msg.WhichOneof('body')}, not frame")
            f = msg.frame
            what = f"frame {len(frames)} (seq {f.seq})"
            check(len(f.data) > 0, f"{what}: empty data")
            h = parse_frame(f.data, what)
            check(h["count"] == n, f"{what}: header vertex count {h['count']} != topology vertex_count {n}")
            check(h["bits"] == topo.bits, f"{what}: header bits {h['bits']} != topology bits {topo.bits}")
            if prev is None:
                check(h["kind"] == KIND_KEY, f"{what}: the first frame of a subscription is a delta, not a keyframe")
            else:
                check(f.seq > prev[0].seq, f"{what}: seq does not increase (previous {prev[0].seq})")
            if h["kind"] == KIND_KEY:
                check(h["base"] == h["seq"], f"{what}: keyframe {h['seq']} names base {h['base']}")
            else:
                # Latest-wins fan-out hands this subscriber a keyframe whenever the shared delta
                # does not apply to what it already has, so every delta is decodable.
                check(h["base"] == prev[1]["seq"], f"{what}: delta on codec frame {h['base']}, but this stream's previous frame is {prev[1]['seq']}")
            frames.append((f, h))
            prev = (f, h)
            if len(frames) == args.frames:
                break
        elapsed = time.monotonic() - start
    except grpc.RpcError as e:
        raise Failure(f"Subscribe: {e.code().name} ({e.details()}) after {len(frames)} frames") from None
    finally:
        call.cancel()
    check(len(frames) == args.frames, f"Subscribe: the stream ended after {len(frames)} of {args.frames} frames")
    check(elapsed <= args.window, f"Subscribe: {args.frames} frames took {elapsed:.2f} s, more than {args.window} s")
    keys = [len(f.data) for f, h in frames if h["kind"] == KIND_KEY]
    deltas = [len(f.data) for f, h in frames if h["kind"] == KIND_DELTA]
    sizes = f"{len(keys)} keyframes ({sum(keys) / max(len(keys), 1):.0f} bytes)"
    sizes += f", {len(deltas)} deltas ({sum(deltas) / max(len(deltas), 1):.0f} bytes)"
    skipped = sum(f.skipped for f, _ in frames)
    ok(
        f"Subscribe: {len(frames)} frames in {elapsed:.2f} s ({len(frames) / max(elapsed, 1e-9):.1f}/s), "
        f"seq {frames[0][0].seq}..{frames[-1][0].seq}, {sizes}, "
        f"{skipped} skipped; headers: magic CRSF, {n} vertices"
    )

    # GetModel on an unknown model.
    unknown = "no-such-model-from-python"
    try:
        get_model(crease.message("crease.v1.GetModelRequest")(model=unknown), timeout=t)
    except grpc.RpcError as e:
        check(e.code() == grpc.StatusCode.NOT_FOUND, f"GetModel({unknown}): {e.code().name}, expected NOT_FOUND")
        ok(f"GetModel({unknown}): NOT_FOUND ({e.details()})")
    else:
        raise Failure(f"GetModel({unknown}) succeeded, expected NOT_FOUND")


if __name__ == "__main__":
    sys.exit(main())
