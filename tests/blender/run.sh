#!/usr/bin/env bash
# The Blender add-on (clients/blender/crease_live, issue 39) headless, end to end: installs
# Blender from Debian's packages (and Xvfb, for the screenshot), the crease Python package for
# Blender's own Python (`pip install --target`, clients/blender/README.md), starts crease-server
# on its embedded demo (free ports, an admin token, a takes folder), then
#   blender -b --factory-startup --python tests/blender/test_addon.py
# (the add-on enables; Watch puts room demo on a mesh whose vertices equal the Python client's
# decode of the same frames, vertex and palette streams; Record makes shape keys equal to the
# frames; the live hand rendered with Workbench; a take imports as a skinned armature
# animation), and under Xvfb tests/blender/screenshot.py (Blender's window with the panel and
# the live hand: the README's picture). Called by .ci/run; runs alone from anywhere:
#   bash tests/blender/run.sh
# Uses ${CARGO_TARGET_DIR:-target} for the build, the package (blender-site/), the demo cache,
# the server log and the pictures (blender-test/).
set -euo pipefail
cd "$(dirname "$0")/../.."

target="${CARGO_TARGET_DIR:-target}"
# CREASE_PREBUILT=1: the binaries a test build of cargo profile $CREASE_PROFILE (.ci/run: ci) left.
bin="$target/${CREASE_PROFILE:-release}"
work="$target/blender-test"
log="$work/server.log"
site="$target/blender-site"
ready_timeout=180

source tests/lib/server.sh

echo "== blender (Debian's) and xvfb"
if ! command -v blender >/dev/null 2>&1; then
    apt_install blender
fi
if ! command -v xvfb-run >/dev/null 2>&1; then
    apt_install xvfb xauth
fi
blender --version | head -n 1

# The package must be built for Blender's Python: the same minor version as python3 here
# (Debian's blender links Debian's libpython3; NumPy and grpcio are binary wheels).
blender_py="$(blender -b --factory-startup --python-expr 'import sys; print("PYVERSION", "%d.%d" % sys.version_info[:2])' 2>/dev/null | sed -n 's/^PYVERSION //p')"
here_py="$(python3 -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
echo "Blender's Python $blender_py, python3 $here_py"
if [[ "$blender_py" != "$here_py" ]]; then
    echo "FAIL: Blender's Python is $blender_py, python3 is $here_py: install python$blender_py and use it for the --target install (clients/blender/README.md)" >&2
    exit 1
fi

echo "== the crease package for Blender's Python (pip install --target $site)"
venv="$target/crease-py"
if [[ ! -x "$venv/bin/python" ]]; then
    python3 -m venv "$venv"
fi
rm -rf "$site"
"$venv/bin/python" -m pip install --disable-pip-version-check --no-input -q --target "$site" \
    -r clients/python/requirements-lock.txt ./clients/python

build_binaries
mkdir -p "$work"
rm -rf "$work/takes" "$work"/*.png "$work/live.blend"
admin_token="blender-test-admin"
start_demo_server --takes "$work/takes" --admin-token "$admin_token"

export CREASE_BLENDER_SITE="$(cd "$site" && pwd)" CREASE_GRPC="$grpc_addr" CREASE_HTTP="$http_addr"
export CREASE_ADMIN_TOKEN="$admin_token" CREASE_OUT="$(cd "$work" && pwd)"

echo "== blender -b: tests/blender/test_addon.py"
blender -b --factory-startup --python-exit-code 1 --python tests/blender/test_addon.py 2>&1 \
    | grep -v -e '^EGL Error' -e '^Managed to successfully fallback' -e '^$'
[[ ${PIPESTATUS[0]} -eq 0 ]] || { echo "FAIL: the Blender add-on test" >&2; exit 1; }

echo "== Blender's window under Xvfb: tests/blender/screenshot.py"
timeout 180 xvfb-run -a -s "-screen 0 1280x800x24" blender --factory-startup --enable-event-simulate \
    "$work/live.blend" --python tests/blender/screenshot.py 2>&1 | grep '^blender:' || true
if [[ ! -s "$work/blender-panel.png" ]]; then
    echo "FAIL: no screenshot at $work/blender-panel.png" >&2
    exit 1
fi
ls -l "$work"/*.png

echo "== stop crease-server"
stop_server
echo "crease-server stopped cleanly on SIGTERM"
