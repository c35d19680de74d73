#!/usr/bin/env bash
# Issue 45's benchmark: one batch job of FRAMES demo-hand frames at LEVEL, submitted to a
# cluster of one replica, then of two (nats-server + `crease-server` processes, each replica
# pinned to its own core with taskset, RAYON_NUM_THREADS=1), timed from submit to the end of
# `crease job watch` (which returns when the last chunk is stored and counted); then a local
# `crease synth` on one core for the per-frame floor.
#
#   bash bench/job-cluster.sh                # FRAMES=100000 LEVEL=detail
#   FRAMES=20000 LEVEL=base bash bench/job-cluster.sh
#
# Needs target/release/{crease,crease-server} (cargo build --release --locked), nats-server,
# taskset, and the Python package's venv (target/crease-py, `bash tests/python/run.sh` makes
# it) to turn a take of the demo room into the control frames: 20 s of the demo animation
# recorded on the embedded demo server, played back and forth to FRAMES frames
# (CONTROLS=FILE uses a CSV of the demo hand's 15 control points instead). Results go into
# the NATS store under WORK (default a temporary folder; at the detail level ~130 KB a frame,
# deleted between the runs).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-100000}
LEVEL=${LEVEL:-detail}
BIN=${BIN:-target/release}
PY=${PY:-target/crease-py/bin/python3}
CACHE=${CACHE:-${CREASE_CACHE_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/crease}}
MODEL=$CACHE/demo-hand-v1.crease
WORK=${WORK:-$(mktemp -d /tmp/crease-job-bench.XXXXXX)}
ADMIN=bench-admin
export CREASE_ADMIN_TOKEN=$ADMIN
detail=()
[ "$LEVEL" = detail ] && detail=(--detail)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT

free_port() { "$PY" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
wait_http() { for _ in $(seq 600); do curl -fs "http://127.0.0.1:$1/readyz" >/dev/null 2>&1 && return; sleep 0.1; done; echo "no server on :$1" >&2; exit 1; }

# 1. The control frames.
CSV=$WORK/controls.csv
if [ -n "${CONTROLS:-}" ]; then
    cp "$CONTROLS" "$WORK/take.csv"
else
    grpc=$(free_port); http=$(free_port)
    "$BIN/crease-server" --cache "$CACHE" --grpc "127.0.0.1:$grpc" --http "127.0.0.1:$http" \
        --admin-token $ADMIN --takes "$WORK/takes" >"$WORK/demo.log" 2>&1 &
    pids+=($!); demo=$!
    wait_http "$http"
    "$BIN/crease" take start --server "http://127.0.0.1:$grpc" --room demo >/dev/null
    sleep 20
    take=$("$BIN/crease" take stop --server "http://127.0.0.1:$grpc" --room demo 2>/dev/null)
    "$PY" - "http://127.0.0.1:$grpc" "$take" "$WORK/take.csv" <<'EOF'
import sys, numpy as np, crease
client = crease.Client(sys.argv[1])
c = client.take_frames(sys.argv[2]).controls
np.savetxt(sys.argv[3], c.reshape(len(c), -1), delimiter=",", fmt="%.7g")
EOF
    kill "$demo"; wait "$demo" 2>/dev/null || true
fi
"$PY" - "$WORK/take.csv" "$CSV" "$FRAMES" <<'EOF'
import sys, numpy as np
c = np.loadtxt(sys.argv[1], delimiter=",", ndmin=2)
n = int(sys.argv[3])
loop = np.concatenate([c, c[-2:0:-1]]) if len(c) > 2 else c   # back and forth
idx = np.arange(n) % len(loop)
np.savetxt(sys.argv[2], loop[idx], delimiter=",", fmt="%.7g")
print(f"{n} control frames from a take of {len(c)} frames", file=sys.stderr)
EOF

# 2. The cluster runs.
mkdir -p "$WORK/models"
ln -sf "$MODEL" "$WORK/models/demo-hand.crease"
run() {
    local n=$1 nats store grpcs=() https=() k
    nats=$(free_port); store=$WORK/js-$n
    nats-server -js -a 127.0.0.1 -p "$nats" -sd "$store" >"$WORK/nats-$n.log" 2>&1 &
    local nats_pid=$!
    sleep 0.5
    local replica_pids=()
    for k in $(seq 0 $((n - 1))); do
        grpcs+=("$(free_port)"); https+=("$(free_port)")
        RAYON_NUM_THREADS=1 taskset -c "$k" "$BIN/crease-server" --models "$WORK/models" \
            --nats "nats://127.0.0.1:$nats" --replica-id "r$k" --admin-token $ADMIN \
            --grpc "127.0.0.1:${grpcs[$k]}" --http "127.0.0.1:${https[$k]}" \
            >"$WORK/replica-$n-$k.log" 2>&1 &
        replica_pids+=($!)
    done
    for k in $(seq 0 $((n - 1))); do wait_http "${https[$k]}"; done
    local t0 t1 job
    t0=$(date +%s.%N)
    job=$("$BIN/crease" job submit --server "http://127.0.0.1:${grpcs[0]}" --model demo-hand \
        --controls "$CSV" "${detail[@]}" --name "bench $n")
    "$BIN/crease" job watch --server "http://127.0.0.1:${grpcs[0]}" "$job" >"$WORK/watch-$n.log" 2>&1
    t1=$(date +%s.%N)
    "$BIN/crease" job list --server "http://127.0.0.1:${grpcs[0]}" | grep "$job"
    local secs
    secs=$("$PY" -c "print(f'{$t1 - $t0:.1f}')")
    echo "replicas=$n frames=$FRAMES level=$LEVEL seconds=$secs frames_per_s=$("$PY" -c "print(f'{$FRAMES / ($t1 - $t0):.1f}')")"
    for k in $(seq 0 $((n - 1))); do
        curl -s "http://127.0.0.1:${https[$k]}/metrics" | "$PY" -c '
import sys
m = {}
for line in sys.stdin:
    if line.startswith("#"): continue
    parts = line.split()
    if len(parts) == 2: m[parts[0]] = float(parts[1])
chunks = m.get("crease_cluster_job_chunks_total", 0)
busy = m.get("crease_job_chunk_seconds_sum", 0)
redelivered = m.get("crease_cluster_job_redeliveries_total", 0)
print(f"  replica r'"$k"': {chunks:.0f} chunks, {busy:.1f} s running them, redeliveries {redelivered:.0f}")
'
    done
    echo "$secs" >"$WORK/seconds-$n"
    for p in "${replica_pids[@]}"; do kill "$p"; done
    kill "$nats_pid"; wait 2>/dev/null || true
    du -sh "$store" | sed 's/^/  NATS store: /'
    rm -rf "$store"
}
run 1
run 2
"$PY" -c "print(f'two replicas / one: {float(open(\"$WORK/seconds-2\").read()) / float(open(\"$WORK/seconds-1\").read()):.3f}x')"

# 3. Local synthesis on one core (the per-frame floor; 200 frames, the meshes discarded).
head -200 "$CSV" >"$WORK/local.csv"
RAYON_NUM_THREADS=1 taskset -c 0 "$BIN/crease" synth --model "$MODEL" --controls "$WORK/local.csv" \
    "${detail[@]}" --out "$WORK/local-out" 2>&1 | tail -n 1
rm -rf "$WORK/local-out"
echo "work folder: $WORK"
