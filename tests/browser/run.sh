#!/usr/bin/env bash
# The browser viewer (web/) in a real headless Chromium, end to end: builds crease-server and the
# crease CLI, starts the server on its embedded demo (free ports, a random publish token for room
# demo), then runs tests/browser/viewer.test.mjs and tests/browser/palette.test.mjs (palette
# streams on the GPU against `crease decode-stream`; playwright-core driving Debian's
# /usr/bin/chromium) and tests/browser/webxr.test.mjs (WebXR hands in room `hands`, through
# Meta's WebXR emulator iwer) against it, tests/browser/actors.test.mjs and webxr-hands.test.mjs
# (rooms of actors, issue 38: two named hands, a drag of one, both tracked hands at once),
# tests/browser/camera.test.mjs (the webcam source, issue 46: MediaPipe Hands on our own
# rendered hands), tests/browser/report.test.mjs (the --report pages of
# crease eval and crease train, written here), and tests/browser/takes.test.mjs (a take of room
# demo: the viewer's takes list and player, GLTFLoader on its skinned glTF export).
# Called by .ci/run; runs alone from anywhere:
#   bash tests/browser/run.sh
# Uses ${CARGO_TARGET_DIR:-target} for the build, the demo cache (demo-cache/, trained once,
# ~25 s), the server log (browser-test/server.log) and the screenshots (browser-test/*.png).
# Installs chromium, and nodejs + npm, with apt-get when they are missing (as root or via sudo).
# Never downloads a browser of its own (no `npx playwright install`).
set -euo pipefail
cd "$(dirname "$0")/../.."

target="${CARGO_TARGET_DIR:-target}"
# CREASE_PREBUILT=1: the binaries a test build of cargo profile $CREASE_PROFILE (.ci/run: ci) left.
bin="$target/${CREASE_PROFILE:-release}"
work="$target/browser-test"
log="$work/server.log"
chromium_bin="/usr/bin/chromium"

ready_timeout=180

# apt_install, start_demo_server, stop_server, the EXIT trap (stops the server, prints its
# log on failure).
source tests/lib/server.sh

echo "== chromium, node"
if [[ ! -x "$chromium_bin" ]]; then
    echo "$chromium_bin is missing"
    apt_install chromium
fi
# The Debian wrapper script prints a harmless shell warning on some machines: keep the version.
"$chromium_bin" --version 2>/dev/null | head -n1
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    echo "node or npm is missing"
    apt_install nodejs npm
fi
echo "node $(node --version), npm $(npm --version 2>/dev/null)"
if (($(node -p 'process.versions.node.split(".")[0]') < 20)); then
    echo "warning: playwright-core 1.65 wants Node.js 20 or newer" >&2
fi

echo "== npm ci (web/, tests/browser/)"
(cd web && npm ci --no-audit --no-fund)
(cd tests/browser && npm ci --no-audit --no-fund)

build_binaries

token="browser-$(od -An -N12 -tx1 /dev/urandom | tr -d ' \n')"
admin="admin-$(od -An -N12 -tx1 /dev/urandom | tr -d ' \n')"
# A fresh takes folder for this run's take (before the server starts: it is the server's folder).
rm -rf "$work/takes"
start_demo_server --demo-token "$token" --admin-token "$admin" --takes "$work/takes"

# Every test runs even when an earlier one fails; the script fails if any did.
failed=0
echo "== viewer in headless chromium"
CREASE_HTTP="$http_addr" CREASE_TOKEN="$token" CREASE_SHOTS="$work" CHROMIUM="$chromium_bin" \
    node tests/browser/viewer.test.mjs || failed=1

echo "== palette streams in headless chromium"
CREASE_HTTP="$http_addr" CREASE_TOKEN="$token" CREASE_SHOTS="$work" CHROMIUM="$chromium_bin" \
    CREASE_BIN="$bin/crease" node tests/browser/palette.test.mjs || failed=1

# WebXR hands through Meta's emulator (iwer): the encoding the viewer picks here (palette,
# drawn by GPU passes inside the XR session), then vertex frames.
for encoding in "" vertices; do
    echo "== WebXR hands in headless chromium (iwer${encoding:+, $encoding frames})"
    CREASE_HTTP="$http_addr" CREASE_TOKEN="$token" CREASE_SHOTS="$work${encoding:+/$encoding}" CHROMIUM="$chromium_bin" \
        CREASE_XR_ENCODING="$encoding" node tests/browser/webxr.test.mjs || failed=1
done

# Issue 38: rooms of actors. The demo's room `performer` drawn as two named hands, and room `duo`
# (opened here: two actors nobody animates, keyframe beta) where a drag moves one hand alone.
echo "== rooms of actors in headless chromium"
if duo_token="$("$bin/crease" room open --room duo --actors tests/browser/duo-actors.toml --beta 3 \
    --server "http://$grpc_addr" --admin-token "$admin" 2>/dev/null)"; then
    CREASE_HTTP="$http_addr" CREASE_DUO_TOKEN="$duo_token" CREASE_SHOTS="$work" CHROMIUM="$chromium_bin" \
        node tests/browser/actors.test.mjs || failed=1
else
    echo "FAIL: crease room open --room duo --actors tests/browser/duo-actors.toml"
    failed=1
fi

# Issue 38: both hands at once into the demo's room `both-hands` (two actors, the left on the
# mirrored model), in both encodings.
for encoding in "" vertices; do
    echo "== WebXR, both hands, in headless chromium (iwer${encoding:+, $encoding frames})"
    CREASE_HTTP="$http_addr" CREASE_TOKEN="$token" CREASE_SHOTS="$work${encoding:+/$encoding}" CHROMIUM="$chromium_bin" \
        CREASE_XR_ENCODING="$encoding" node tests/browser/webxr-hands.test.mjs || failed=1
done

# Issue 46: the webcam source closed through our own rendered hands (MediaPipe Hands in the
# page): both hands in the demo's room `camera`, then one hand in a one-actor room opened here.
echo "== the camera (MediaPipe Hands) in headless chromium"
if ! solo_token="$("$bin/crease" room open --room camera-solo --model demo-hand --map bench/mocap/mediapipe-back.toml --mediapipe \
    --server "http://$grpc_addr" --admin-token "$admin" 2>/dev/null)"; then
    echo "FAIL: crease room open --room camera-solo --model demo-hand --map bench/mocap/mediapipe-back.toml --mediapipe"
    failed=1
    solo_token=""
fi
CREASE_HTTP="$http_addr" CREASE_TOKEN="$token" CREASE_BIN="$bin/crease" CREASE_CAMERA_SOLO_TOKEN="$solo_token" \
    CREASE_SHOTS="$work" CHROMIUM="$chromium_bin" node tests/browser/camera.test.mjs || failed=1

# Issue 22: the --report pages of crease eval (horse split, generated hand) and crease train,
# each beside its --json output, opened by report.test.mjs (pictures load and are not blank,
# table numbers equal --json).
echo "== training and evaluation reports in headless chromium"
reports="$work/report-horse,$work/report-hand,$work/report-horse-train"
for r in ${reports//,/ }; do rm -rf "$r" && mkdir -p "$r"; done
small=(--bones 20 --methods global,local)
if [[ -f ../shared/data/horse/reference.obj ]]; then
    "$bin/crease" eval --examples bench/horse/train.toml --test bench/horse/test.toml "${small[@]}" --select \
        --json --report "$work/report-horse" >"$work/report-horse/stdout.json" || failed=1
    "$bin/crease" train --examples bench/horse/train.toml --bones 20 --select --out "$work/report-horse-train/horse.crease" \
        --json --report "$work/report-horse-train" >"$work/report-horse-train/stdout.json" || failed=1
else
    echo "skipped the horse reports: ../shared/data/horse is missing"
    reports="$work/report-hand"
fi
"$bin/crease" eval --hands extrapolation --hand-test 6 "${small[@]}" --loo \
    --json --report "$work/report-hand" >"$work/report-hand/stdout.json" || failed=1
CREASE_REPORTS="$reports" CREASE_SHOTS="$work" CHROMIUM="$chromium_bin" \
    node tests/browser/report.test.mjs || failed=1

# Issue 22: a take of room demo (the server animates it), exported by `crease take export` and
# by the server (byte-identical), then takes.test.mjs: the viewer's takes list, its player in a
# private replay room, and three.js's GLTFLoader on the export.
echo "== takes in headless chromium"
# Issue 38: beside it, a take of room performer (the demo's two hands, one room of actors),
# recorded at the same time; its export holds a skinned mesh per hand.
if take="$("$bin/crease" take start --room demo --name browser --server "http://$grpc_addr" --admin-token "$admin")" &&
    actors_take="$("$bin/crease" take start --room performer --name browser-hands --server "http://$grpc_addr" --admin-token "$admin")"; then
    sleep 8
    "$bin/crease" take stop --room demo --server "http://$grpc_addr" --admin-token "$admin" >/dev/null || failed=1
    "$bin/crease" take stop --room performer --server "http://$grpc_addr" --admin-token "$admin" >/dev/null || failed=1
    "$bin/crease" take export "$actors_take" --server "http://$grpc_addr" --model "$target/demo-cache/demo-hand-v1.crease" \
        --out "$work/take-hands.glb" || failed=1
    "$bin/crease" take export "$take" --server "http://$grpc_addr" --model "$target/demo-cache/demo-hand-v1.crease" \
        --out "$work/take.glb" || failed=1
    node -e 'fetch(process.argv[1]).then(async (r) => { if (!r.ok) throw new Error(`${r.status} ${await r.text()}`); require("fs").writeFileSync(process.argv[2], Buffer.from(await r.arrayBuffer())); }).catch((e) => { console.error(`GET ${process.argv[1]}: ${e.message}`); process.exit(1); })' \
        "http://$http_addr/api/takes/$take/glb" "$work/take-server.glb" || failed=1
    node -e 'fetch(process.argv[1]).then(async (r) => { if (!r.ok) throw new Error(`${r.status} ${await r.text()}`); require("fs").writeFileSync(process.argv[2], Buffer.from(await r.arrayBuffer())); }).catch((e) => { console.error(`GET ${process.argv[1]}: ${e.message}`); process.exit(1); })' \
        "http://$http_addr/api/takes/$actors_take/glb" "$work/take-hands-server.glb" || failed=1
    for pair in "take $take" "take-hands $actors_take"; do
        set -- $pair
        if cmp -s "$work/$1.glb" "$work/$1-server.glb"; then
            echo "ok   crease take export and GET /api/takes/$2/glb write the same bytes"
        else
            echo "FAIL crease take export and GET /api/takes/$2/glb differ"
            failed=1
        fi
    done
    # Issue 45: the take as a batch job on this server (no NATS: jobs in its process), then
    # listed by the viewer's jobs section.
    job=""
    if job="$("$bin/crease" job submit --take "$take" --name browser --server "http://$grpc_addr" --admin-token "$admin")" &&
        "$bin/crease" job watch "$job" --server "http://$grpc_addr" >/dev/null; then
        echo "ok   crease job submit --take $take ran as job $job"
    else
        echo "FAIL crease job submit --take $take"
        failed=1
    fi
    CREASE_HTTP="$http_addr" CREASE_TAKE="$take" CREASE_JOB="$job" CREASE_ACTORS_TAKE="$actors_take" CREASE_SHOTS="$work" CHROMIUM="$chromium_bin" \
        node tests/browser/takes.test.mjs || failed=1
else
    failed=1
fi

echo "== stop crease-server"
stop_server
echo "crease-server stopped cleanly on SIGTERM"
exit "$failed"
