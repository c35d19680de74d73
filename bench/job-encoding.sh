#!/usr/bin/env bash
# Issue 45: what a job's result costs kept as vertices vs as a palette (JobSpec.encoding). One
# embedded demo server (single process, no NATS, RAYON_NUM_THREADS=1, pinned to one core); a
# take of SECONDS of the demo room gives the control frames; the same frames run as a detail
# job in each encoding; printed: the job's time (submit to the end of `crease job watch`), the
# result's bytes as `crease job get --format codec` writes them: the header (topology or
# palette header, once), then bytes a frame.
#
#   bash bench/job-encoding.sh                 # SECONDS_OF_TAKE=10 LEVEL=detail
#
# Needs target/release/{crease,crease-server} and taskset.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release}
TAKE_SECONDS=${SECONDS_OF_TAKE:-10}
LEVEL=${LEVEL:-detail}
WORK=${WORK:-$(mktemp -d /tmp/crease-job-encoding.XXXXXX)}
export CREASE_ADMIN_TOKEN=bench-admin RAYON_NUM_THREADS=1
detail=()
[ "$LEVEL" = detail ] && detail=(--detail)
port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
grpc=$(port); http=$(port)
taskset -c 0 "$BIN/crease-server" --grpc "127.0.0.1:$grpc" --http "127.0.0.1:$http" \
    --admin-token bench-admin --takes "$WORK/takes" >"$WORK/server.log" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
for _ in $(seq 600); do curl -fs "http://127.0.0.1:$http/readyz" >/dev/null 2>&1 && break; sleep 0.1; done
url=http://127.0.0.1:$grpc
"$BIN/crease" take start --server "$url" --room demo >/dev/null
sleep "$TAKE_SECONDS"
take=$("$BIN/crease" take stop --server "$url" --room demo 2>/dev/null)
for encoding in vertices palette; do
    start=$(date +%s.%N)
    id=$("$BIN/crease" job submit --server "$url" --take "$take" "${detail[@]}" --encoding "$encoding" 2>/dev/null)
    "$BIN/crease" job watch "$id" --server "$url" >"$WORK/$encoding.watch"
    end=$(date +%s.%N)
    "$BIN/crease" job get "$id" --server "$url" --format codec --out "$WORK/$encoding.stream" >/dev/null
    frames=$(grep -o '[0-9]* of [0-9]* frames' "$WORK/$encoding.watch" | head -1 | cut -d' ' -f3)
    bytes=$(stat -c %s "$WORK/$encoding.stream")
    python3 - "$encoding" "$frames" "$WORK/$encoding.stream" "$start" "$end" <<'PY'
import os, struct, sys
enc, frames, path, t0, t1 = sys.argv[1], int(sys.argv[2]), sys.argv[3], float(sys.argv[4]), float(sys.argv[5])
size = os.path.getsize(path)
with open(path, "rb") as f:
    header = 4 + struct.unpack("<I", f.read(4))[0]   # the first message: topology or palette header
secs = t1 - t0
print(f"{enc:9s} {frames} frames in {secs:.1f} s ({frames / secs:.1f} frames/s); result {size} bytes: "
      f"header {header}, then {(size - header) / frames:.0f} bytes a frame")
PY
done
