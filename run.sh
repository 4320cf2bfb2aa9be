#!/usr/bin/env bash
# The two fresh-machine commands:
#   ./run.sh demo   -> the main job (headless simulation, writes a report folder)
#   ./run.sh test   -> ruff + mypy + the whole pytest suite
# Both create ./.venv and install the project on first use (and again when pyproject.toml changes).
set -euo pipefail
cd "$(dirname "$0")"
VENV=.venv
STAMP="$VENV/.lapwrench-installed"
want=$(sha256sum pyproject.toml | cut -d' ' -f1)

setup() {
    if [ ! -x "$VENV/bin/python" ]; then
        python3.11 -m venv "$VENV" 2>/dev/null || python3 -m venv "$VENV"
    fi
    if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$want" ]; then
        echo "[lapwrench] installing into $VENV (first use) ..." >&2
        "$VENV/bin/python" -m pip install -q --upgrade pip >&2
        "$VENV/bin/python" -m pip install -q -e ".[dev]" >&2
        echo "$want" > "$STAMP"
    fi
    # Headless rendering (MuJoCo through EGL/Mesa): install the Debian libraries if absent.
    libs=$(ldconfig -p)
    if [[ "$libs" != *libEGL.so.1* || "$libs" != *libEGL_mesa* ]]; then
        if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
            echo "[lapwrench] installing EGL/Mesa for headless rendering ..." >&2
            (apt-get update -qq && apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri) >&2
        else
            echo "[lapwrench] warning: libEGL/Mesa missing; install libegl1 libegl-mesa0 libgl1-mesa-dri" >&2
        fi
    fi
}

cmd=${1:-}
shift || true
export MUJOCO_GL=${MUJOCO_GL:-egl}
case "$cmd" in
    demo)
        setup
        exec "$VENV/bin/lapwrench" demo "$@"
        ;;
    test)
        setup
        # the browser test of `lapwrench ui` drives Debian's headless Chromium (no browser download at run time)
        if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
            if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
                echo "[lapwrench] installing chromium + chromium-driver for the browser test ..." >&2
                (apt-get update -qq && apt-get install -y -qq chromium chromium-driver) >&2
            else
                echo "[lapwrench] warning: chromium/chromedriver missing; the browser test will be skipped" >&2
            fi
        fi
        "$VENV/bin/ruff" check src tests bench examples
        "$VENV/bin/python" -m mypy  # the package's type hints ([tool.mypy] in pyproject.toml)
        if [ $# -gt 0 ]; then
            exec "$VENV/bin/python" -m pytest -q "$@"
        fi
        # the whole suite in two phases: the tests that may share the machine on pytest-xdist workers (one
        # per core), then the "serial" ones (real time, franky-sim, the browser, Ray; tests/conftest.py) alone
        rc=0
        "$VENV/bin/python" -m pytest -q -n auto -m "not serial" || rc=$?
        "$VENV/bin/python" -m pytest -q -m serial || rc=$((rc ? rc : $?))
        exit "$rc"
        ;;
    setup)
        setup
        ;;
    *)
        echo "usage: ./run.sh demo [options] | ./run.sh test [pytest args] | ./run.sh setup" >&2
        exit 2
        ;;
esac
