# Shared by tests/python/run.sh and tests/browser/run.sh (sourced, not run): installing the
# Debian packages they need, starting and stopping the demo server they start, and the EXIT
# trap that stops it and prints its log on failure. The caller sets `log` (the server's log
# file) and `server_pid` (once started).

server_pid=""

# Builds crease-server and crease in release into "$bin", unless CREASE_PREBUILT=1 says the
# caller built them: .ci/run does, since `cargo test --workspace --profile ci` has just left both
# binaries in target/ci (integration tests need them; CREASE_PROFILE=ci points "$bin" there). They differ from this build only in the
# dev-dependencies' features (the test meshes), which nothing here reaches; rebuilding them
# with the command line's features took 4 of the suite's 28 minutes.
build_binaries() {
    if [[ "${CREASE_PREBUILT:-}" == 1 && -x "$bin/crease-server" && -x "$bin/crease" ]]; then
        echo "== the binaries the release test build left (CREASE_PREBUILT=1)"
        ls -l "$bin/crease-server" "$bin/crease"
    else
        echo "== build (crease-server, crease)"
        cargo build --release --locked -p crease-demo -p crease-cli
        bin="${CARGO_TARGET_DIR:-target}/release"
    fi
}

# Stops the server with SIGTERM (it drains for up to 5 s); fails unless it exits 0.
stop_server() {
    [[ -n "$server_pid" ]] || return 0
    local pid=$server_pid code=0
    server_pid=""
    kill -TERM "$pid" 2>/dev/null || true
    for _ in $(seq 1 150); do
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.1
    done
    if kill -0 "$pid" 2>/dev/null; then
        echo "FAIL: crease-server (pid $pid) still running 15 s after SIGTERM: killing it" >&2
        kill -KILL "$pid" 2>/dev/null || true
        wait "$pid" 2>/dev/null || true
        return 1
    fi
    wait "$pid" 2>/dev/null || code=$?
    if [[ $code -ne 0 ]]; then
        echo "FAIL: crease-server exited with status $code on SIGTERM (expected 0)" >&2
        return 1
    fi
}

cleanup() {
    local status=$?
    set +e
    stop_server || { [[ $status -eq 0 ]] && status=1; }
    if [[ $status -ne 0 && -f "$log" ]]; then
        echo "== crease-server log ($log)" >&2
        cat "$log" >&2
    fi
    exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# Starts "$bin/crease-server" on its embedded demo on free loopback ports (extra arguments are
# passed on), logging to "$log", and waits up to $ready_timeout s (the first start trains the
# demo hand) for its address line. Sets server_pid, grpc_addr and http_addr; exits on failure.
start_demo_server() {
    echo "== start crease-server (demo)"
    mkdir -p "$(dirname "$log")"
    : >"$log"
    NO_COLOR=1 "$bin/crease-server" --grpc 127.0.0.1:0 --http 127.0.0.1:0 \
        --cache "$target/demo-cache" "$@" >>"$log" 2>&1 &
    server_pid=$!
    local start=$SECONDS line="" code elapsed
    while true; do
        line="$(grep -m1 '^crease-server: gRPC on ' "$log" || true)"
        [[ -n "$line" ]] && break
        if ! kill -0 "$server_pid" 2>/dev/null; then
            wait "$server_pid" && code=0 || code=$?
            server_pid=""
            echo "FAIL: crease-server exited (status $code) before it was listening" >&2
            exit 1
        fi
        elapsed=$((SECONDS - start))
        if ((elapsed >= ready_timeout)); then
            echo "FAIL: crease-server not listening after $ready_timeout s" >&2
            exit 1
        fi
        if ((elapsed > 0 && elapsed % 10 == 0)); then
            echo "waiting for crease-server: $elapsed s (the first start trains the demo hand) — $(tail -n1 "$log")"
            sleep 1
        else
            sleep 0.5
        fi
    done
    grpc_addr="$(sed -E 's/^crease-server: gRPC on ([^ ,]+), HTTP on ([^ ,]+).*/\1/' <<<"$line")"
    http_addr="$(sed -E 's/^crease-server: gRPC on ([^ ,]+), HTTP on ([^ ,]+).*/\2/' <<<"$line")"
    if [[ ! "$grpc_addr" =~ ^[0-9.]+:[0-9]+$ || ! "$http_addr" =~ ^[0-9.]+:[0-9]+$ ]]; then
        echo "FAIL: cannot parse the addresses from: $line" >&2
        exit 1
    fi
    echo "listening after $((SECONDS - start)) s: gRPC $grpc_addr, HTTP $http_addr (pid $server_pid)"
}

# apt-get install "$@" as root or through sudo; fails with a reason when neither is possible.
apt_install() {
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "FAIL: $* needed and there is no apt-get here: install it by hand" >&2
        exit 1
    fi
    local sudo=""
    if [[ $(id -u) -ne 0 ]]; then
        if ! command -v sudo >/dev/null 2>&1; then
            echo "FAIL: $* needed and this user cannot run apt-get (not root, no sudo)" >&2
            exit 1
        fi
        sudo="sudo"
    fi
    echo "apt-get install $*"
    $sudo apt-get update
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y "$@"
}
