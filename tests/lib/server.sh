# Shared by tests/python/run.sh and tests/browser/run.sh (sourced, not run): stopping the demo
# server they start, and the EXIT trap that stops it and prints its log on failure. The caller
# sets `log` (the server's log file) and `server_pid` (once started).

server_pid=""

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
