# Shared by scripts/demo.sh and scripts/test.sh: make ./.venv (Python >= 3.11) and install couplekit into it.
# Usage: source scripts/_setup.sh EXTRAS    (EXTRAS: "" or "test", ...)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${PYTHON:-python3}"
VENV="${COUPLEKIT_VENV:-$ROOT/.venv}"
if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    echo "couplekit needs Python >= 3.11; '$PY' is $("$PY" --version 2>&1 || echo missing). Set PYTHON=/path/to/python3.11" >&2
    exit 1
fi
if ! command -v "${CXX:-g++}" >/dev/null 2>&1 && ! command -v c++ >/dev/null 2>&1; then
    echo "warning: no C++ compiler found: the cpu backend is unavailable and only the NumPy reference will run" >&2
fi
# PNG previews render off-screen through EGL (Mesa's software rasteriser is enough; no GPU, no X server)
if ! ldconfig -p 2>/dev/null | grep -q "libEGL.so.1"; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "== installing the EGL/GL libraries for off-screen PNG previews (apt-get)"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libegl1 libegl-mesa0 libgl1 >/dev/null
    else
        echo "warning: libEGL not found: PNG previews will be skipped (install libegl1 libegl-mesa0 libgl1)" >&2
    fi
fi
if [ ! -x "$VENV/bin/python" ]; then
    echo "== creating virtual environment $VENV"
    "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
extras="${1:-}"
spec="$ROOT"
[ -n "$extras" ] && spec="$ROOT[$extras]"
echo "== installing couplekit${extras:+[$extras]} (editable) into $VENV"
"$VENV/bin/python" -m pip install -q -e "$spec"
export PATH="$VENV/bin:$PATH"
