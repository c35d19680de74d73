#!/usr/bin/env bash
# A gRPC client that is not ours, end to end: builds crease-server and crease, starts the server
# on its embedded demo (free ports), checks `crease watch` on room demo, then runs
# tests/python/test_grpc_client.py (grpcio + grpcio-reflection from PyPI, pinned in
# requirements.txt) against it; then the crease Python package (issue 39): `pip install
# ./clients/python` into a fresh venv (its dependencies pinned by
# clients/python/requirements-lock.txt), its unit tests (the codec and palette test vectors) and
# clients/python/tests/test_server.py against the same server, with a glove13 hand trained here
# and the Qualisys recording retargeted onto it (../shared/data; without it the README example's
# test skips). Called by .ci/run; runs alone from anywhere:
#   bash tests/python/run.sh
# Uses ${CARGO_TARGET_DIR:-target} for the build, the venv (pyenv/), the demo cache
# (demo-cache/, trained once, ~25 s) and the server log (python-test/server.log).
# Installs python3 + venv with apt-get when they are missing (fresh Debian, as root or via sudo).
set -euo pipefail
cd "$(dirname "$0")/../.."

target="${CARGO_TARGET_DIR:-target}"
# CREASE_PREBUILT=1: the binaries a test build of cargo profile $CREASE_PROFILE (.ci/run: ci) left.
bin="$target/${CREASE_PROFILE:-release}"
venv="$target/pyenv"
req="tests/python/requirements.txt"
work="$target/python-test"
log="$work/server.log"

ready_timeout=180

# apt_install, start_demo_server, stop_server, the EXIT trap (stops the server, prints its
# log on failure).
source tests/lib/server.sh

echo "== python (venv)"
# Debian splits venv's ensurepip into python3-venv: `python3 -m venv` without it makes no venv.
if ! command -v python3 >/dev/null 2>&1 || ! python3 -c 'import venv, ensurepip' >/dev/null 2>&1; then
    echo "python3 with venv is missing"
    apt_install python3 python3-venv python3-pip
fi
python3 --version

# Reuse the venv while requirements.txt and the interpreter are unchanged.
stamp="$( (cat "$req"; python3 --version) | sha256sum | cut -d' ' -f1)"
if [[ -x "$venv/bin/python" && -f "$venv/.requirements.sha256" ]] \
    && [[ "$(cat "$venv/.requirements.sha256")" == "$stamp" ]] \
    && "$venv/bin/python" -c 'import grpc, grpc_reflection, grpc_health' >/dev/null 2>&1; then
    echo "reusing $venv"
else
    echo "creating $venv"
    rm -rf "$venv"
    python3 -m venv "$venv"
    "$venv/bin/python" -m pip install --disable-pip-version-check --no-input -q -r "$req"
    echo "$stamp" >"$venv/.requirements.sha256"
fi
"$venv/bin/python" -m pip freeze --disable-pip-version-check | tr '\n' ' '
echo

build_binaries

admin_token="python-test-admin"
rm -rf "$work/models" "$work/takes" "$work/package"
mkdir -p "$work/models" "$work/takes" "$work/package"
start_demo_server --models "$work/models" --demo --takes "$work/takes" --admin-token "$admin_token"

echo "== crease watch --room demo"
watch_out="$(timeout 120 "$bin/crease" watch --server "http://$grpc_addr" --room demo --frames 30)" || {
    code=$?
    echo "$watch_out"
    echo "FAIL: crease watch exited with status $code" >&2
    exit 1
}
echo "$watch_out"
if ! grep -q '^30 frames in ' <<<"$watch_out"; then
    echo "FAIL: crease watch did not print '30 frames in ...'" >&2
    exit 1
fi

echo "== python grpcio client"
"$venv/bin/python" tests/python/test_grpc_client.py --grpc "$grpc_addr"

echo "== the crease Python package: pip install ./clients/python into a fresh venv"
pkg_venv="$target/crease-py"
rm -rf "$pkg_venv"
python3 -m venv "$pkg_venv"
"$pkg_venv/bin/python" -m pip install --disable-pip-version-check --no-input -q -r clients/python/requirements-lock.txt
"$pkg_venv/bin/python" -m pip install --disable-pip-version-check --no-input -q ./clients/python
"$pkg_venv/bin/python" -c 'import crease, crease.v1.crease_pb2 as pb; print("crease", crease.__version__, "stubs:", pb.DESCRIPTOR.name)'

work_abs="$(cd "$work" && pwd)"
bin_abs="$(cd "$bin" && pwd)"
echo "== a glove13 hand (crease handgen + train), uploaded by the tests"
"$bin/crease" handgen --train 14 --test 1 --base-only --out "$work/package/hg" >/dev/null
"$bin/crease" train --examples "$work/package/hg/train-glove13.toml" --bones 30 --method local \
    --no-detail --out "$work/package/glove13.crease" | tail -n 1
export CREASE_GLOVE_MODEL="$work_abs/package/glove13.crease"
data="../shared/data/mocap/qualisys-hand-glove-recording.tsv"
if [[ -f "$data" ]]; then
    echo "== the Qualisys recording retargeted onto it (crease retarget)"
    "$bin/crease" retarget --tsv "$data" --map bench/mocap/qualisys-glove13.toml \
        --model "$work/package/glove13.crease" --out "$work/package/qualisys.csv" | tail -n 1
    export CREASE_QUALISYS_CSV="$work_abs/package/qualisys.csv"
else
    echo "skipping the README example's test: $data is absent (../shared/data)"
fi

echo "== the crease Python package's tests (clients/python/tests)"
CREASE_GRPC="$grpc_addr" CREASE_HTTP="$http_addr" CREASE_ADMIN_TOKEN="$admin_token" \
    CREASE_CLI="$bin_abs/crease" CREASE_WORK="$work_abs/package/work" \
    "$pkg_venv/bin/python" -m unittest discover -s clients/python/tests -v

echo "== stop crease-server"
stop_server
echo "crease-server stopped cleanly on SIGTERM"
