#!/usr/bin/env bash
# Runs every fuzz target for MINUTES minutes each, JOBS at a time (issue 21).
#
#   bash fuzz/run.sh [MINUTES] [JOBS] [TARGET...]     (defaults: 10 minutes, 1 job, all targets)
#
# Needs the nightly toolchain and cargo-fuzz (`cargo +nightly install cargo-fuzz`). Seeds come
# from fuzz/seed.py (../shared/data, the test vectors and fixtures); each target's corpus grows
# in fuzz/corpus/TARGET, findings land in fuzz/artifacts/TARGET, logs in fuzz/out/TARGET.log.
# Limits: 2 GiB of RSS, no single allocation over 256 MiB (a huge allocation from a small input
# is a finding), 10 s per input (a hang). The table at the end (also fuzz/out/summary.md) is
# what RELIABILITY.md records: executions, coverage (edges) and features, corpus size, findings.
set -euo pipefail
cd "$(dirname "$0")"
MINUTES=${1:-10}
JOBS=${2:-1}
shift $(( $# > 2 ? 2 : $# ))
if ! cargo +nightly --version >/dev/null 2>&1; then
    echo "fuzz/run.sh: no nightly toolchain (rustup toolchain list): nothing run" >&2
    exit 2
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    echo "fuzz/run.sh: cargo-fuzz is missing: cargo +nightly install cargo-fuzz" >&2
    exit 2
fi
# Model and rig seeds from the release build's own writer, on a 48-vertex tube (a model of a
# few KB): built when `crease` is there (`cargo build --release -p crease-cli`).
CREASE=../target/release/crease
MODELS=../target/fuzz-models
if [ -x "$CREASE" ] && [ ! -f "$MODELS/tube.crease" ]; then
    python3 - "$MODELS/tube" <<'PY'
import math, os, sys
out = sys.argv[1]
os.makedirs(out, exist_ok=True)
rings, around = 8, 6
faces = []
for r in range(rings - 1):
    for a in range(around):
        i0, i1 = r * around + a + 1, r * around + (a + 1) % around + 1
        faces += [f"f {i0} {i1} {i1 + around}", f"f {i0} {i1 + around} {i0 + around}"]
for k in range(5):
    ang, lines = 0.25 * k, []
    for r in range(rings):
        for a in range(around):
            phi = 2 * math.pi * a / around
            x, y, z = math.cos(phi), math.sin(phi), float(r)
            if z > 3.5:
                y, z = y * math.cos(ang) - (z - 3.5) * math.sin(ang), 3.5 + y * math.sin(ang) + (z - 3.5) * math.cos(ang)
            lines.append(f"v {x} {y} {z}")
    open(f"{out}/pose{k}.obj", "w").write("\n".join(lines + faces) + "\n")
PY
    "$CREASE" train --examples "$MODELS/tube" --bones 3 --max-influences 2 --control-points 0,45,42 \
        --no-detail --out "$MODELS/tube.crease" >/dev/null 2>&1 || echo "fuzz/run.sh: no model seed (crease train failed)" >&2
    "$CREASE" fit --examples "$MODELS/tube" --bones 3 --out "$MODELS/tube.rig" >/dev/null 2>&1 || echo "fuzz/run.sh: no rig seed (crease fit failed)" >&2
fi
python3 seed.py >/dev/null
cargo +nightly fuzz build
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(cargo +nightly fuzz list)
fi
mkdir -p out
export MINUTES
run_one() {
    local t=$1 max_len=4096
    case $t in
        mesh_obj|mesh_ply) max_len=65536 ;;
        mesh_gltf|mesh_stream) max_len=131072 ;;
        model_file) max_len=524288 ;;
        mocap_c3d) max_len=1048576 ;;
        mocap_tsv) max_len=32768 ;;
    esac
    mkdir -p "corpus/$t" "artifacts/$t"
    echo "fuzz: $t for $MINUTES min (max_len $max_len)" >&2
    local rc=0
    cargo +nightly fuzz run "$t" "corpus/$t" "seeds/$t" -- \
        -max_total_time=$((MINUTES * 60)) -rss_limit_mb=2048 -malloc_limit_mb=256 \
        -timeout=10 -max_len=$max_len -print_final_stats=1 \
        > "out/$t.log" 2>&1 || rc=$?
    local execs cov ft corp findings
    execs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "out/$t.log" | tail -1 | awk '{print $2}')
    cov=$(grep -o 'cov: [0-9]*' "out/$t.log" | tail -1 | awk '{print $2}')
    ft=$(grep -o 'ft: [0-9]*' "out/$t.log" | tail -1 | awk '{print $2}')
    corp=$(ls "corpus/$t" | wc -l)
    findings=$(ls "artifacts/$t" | grep -E '^(crash|timeout|oom|leak|slow-unit)-' | tr '\n' ' ' || true)
    printf '| %s | %s | %s | %s | %s | %s | %s |\n' "$t" "$MINUTES" "${execs:-?}" "${cov:-?}" "${ft:-?}" \
        "$corp" "${findings:-none}$( [ "$rc" != 0 ] && echo " (rc $rc)")" >> out/summary.rows
}
export -f run_one
rm -f out/summary.rows
printf '%s\n' "${targets[@]}" | xargs -P "$JOBS" -I{} bash -c 'run_one {}'
{
    echo "| target | minutes | executions | coverage (edges) | features | corpus | findings |"
    echo "|---|---|---|---|---|---|---|"
    sort out/summary.rows
} | tee out/summary.md
