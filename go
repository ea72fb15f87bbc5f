#!/usr/bin/env bash
# Set-up-and-go for a fresh Debian machine (idempotent; fast when set-up is done).
#   ./go run   [SCENE] [OUTDIR]   build the sphere model of SCENE (default: cases/scenes/open_pit.toml); a run
#                                 again replaces its earlier model there (sgim build --force: files added
#                                 by hand stay, a folder of other files is refused)
#   ./go test  [PYTEST ARGS]      run the test suite (without arguments: on both cores, see tests/conftest.py)
# The Python packages are the exact versions in requirements.lock; the project goes in on top of them.
#   ./go lock                     re-resolve pyproject.toml's ranges in a throwaway venv, rewrite requirements.lock
set -euo pipefail
cd "$(dirname "$0")"

LOCK=requirements.lock

say() { echo "[go] $*" >&2; }

# the Python version the lock was resolved for (its "# python: X.Y" line)
lock_python() { sed -n 's/^# python: *\([0-9][0-9.]*\).*/\1/p' "$LOCK" | head -n 1; }

lock_header() {  # $1 python X.Y, $2 platform
  cat <<EOF
# requirements.lock: the exact version of every Python package rockdem needs (pyproject.toml's
# dependencies and its test and mpi extras, transitive ones included). ./go installs these into .venv
# (pip install -r requirements.lock), then the project itself (pip install --no-deps -e .), so that
# every machine and CI compute with the same numpy, numba, llvmlite, scipy, vtk, ...
# pyproject.toml keeps the loose ranges for people who install rockdem as a library.
#
# Refresh (resolves pyproject.toml's ranges afresh in a throwaway venv and rewrites this file):
#     ./go lock
#
# python: $1
# platform: $2
EOF
}

setup() {
  local missing=() sudo=""
  command -v python3 >/dev/null || missing+=(python3)
  python3 -c 'import venv, ensurepip' 2>/dev/null || missing+=(python3-venv)
  command -v yade >/dev/null || missing+=(yade)
  command -v liggghts >/dev/null || missing+=(liggghts)
  command -v mpirun >/dev/null || missing+=(openmpi-bin)
  # off-screen pictures: VTK's EGL window on Mesa's software renderer, no X server needed (sgim/render.py)
  python3 -c 'import ctypes.util, sys; sys.exit(ctypes.util.find_library("EGL_mesa") is None)' 2>/dev/null \
    || missing+=(libegl1 libegl-mesa0 libgl1-mesa-dri)
  if ((${#missing[@]})); then
    [ "$(id -u)" = 0 ] || sudo=sudo
    say "installing Debian packages: ${missing[*]}"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
  if [ ! -x .venv/bin/python ]; then
    say "creating .venv"
    python3 -m venv .venv
  fi
  # a new lock or a new pyproject.toml installs again
  local stamp=".venv/.installed-$(cat pyproject.toml "$LOCK" | sha1sum | cut -c1-12)"
  if [ ! -f "$stamp" ]; then
    local have want
    have="$(.venv/bin/python -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
    want="$(lock_python)"
    if [ "$have" != "$want" ]; then
      say "note: $LOCK was resolved for python $want, .venv has python $have (./go lock resolves for this one)"
    fi
    say "installing the locked Python dependencies ($LOCK) and the project into .venv"
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -r "$LOCK"
    # packages an earlier lock had and this one has not
    .venv/bin/python - "$LOCK" <<'EOF'
import re, subprocess, sys

def name(line):
    return re.sub(r"[-_.]+", "-", re.split(r"==| @ ", line.strip())[0]).lower()

locked = {name(l) for l in open(sys.argv[1]) if l.strip() and not l.startswith("#")}
frozen = subprocess.run([sys.executable, "-m", "pip", "freeze", "--exclude-editable"], check=True,
                        capture_output=True, text=True).stdout.splitlines()
extra = [re.split(r"==| @ ", l)[0] for l in frozen if l.strip() and not l.startswith("#") and name(l) not in locked]
if extra:
    print(f"[go] removing packages that {sys.argv[1]} does not list: {' '.join(extra)}", file=sys.stderr)
    subprocess.run([sys.executable, "-m", "pip", "uninstall", "-q", "-y", *extra], check=True)
EOF
    .venv/bin/python -m pip install -q --no-deps -e .
    local broken
    if ! broken="$(.venv/bin/python -m pip check 2>&1)"; then
      echo "$broken" >&2
      say "the packages of $LOCK do not satisfy pyproject.toml: refresh it with ./go lock"
      exit 1
    fi
    rm -f .venv/.installed-*
    touch "$stamp"
  fi
}

lock() {
  python3 -c 'import venv, ensurepip' 2>/dev/null || { say "./go lock needs python3 with venv (python3-venv)"; exit 2; }
  local tmp out="$LOCK.tmp.$$"
  tmp="$(mktemp -d)"
  trap "rm -rf '$tmp' '$out'" EXIT
  say "resolving pyproject.toml's ranges in a throwaway venv ($tmp)"
  python3 -m venv "$tmp/venv"
  "$tmp/venv/bin/python" -m pip install -q --upgrade pip
  "$tmp/venv/bin/python" -m pip install -q -e ".[test,mpi]"
  local py plat
  py="$("$tmp/venv/bin/python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
  plat="$("$tmp/venv/bin/python" -c 'import sysconfig; print(sysconfig.get_platform())')"
  { lock_header "$py" "$plat"; "$tmp/venv/bin/python" -m pip freeze --exclude-editable; } > "$out"
  mv -f "$out" "$LOCK"
  say "wrote $LOCK: $(grep -c '==' "$LOCK") packages for python $py; the next ./go run or ./go test installs them"
}

cmd="${1:-}"
shift || true
case "$cmd" in
  run)
    setup
    scene="${1:-cases/scenes/open_pit.toml}"
    out="${2:-out/$(basename "${scene%.toml}")}"
    exec .venv/bin/sgim build "$scene" -o "$out" --force
    ;;
  test)
    setup
    if (($#)); then
      exec .venv/bin/python -m pytest -q "$@"
    fi
    # the whole suite: one worker per core, then the tests that need both cores to themselves (tests/conftest.py)
    rc=0
    .venv/bin/python -m pytest -q -n 2 -m "not serial" || rc=$?
    .venv/bin/python -m pytest -q -m serial || rc=$?
    exit "$rc"
    ;;
  lock)
    lock
    ;;
  *)
    echo "usage: ./go run [SCENE] [OUTDIR]   |   ./go test [PYTEST ARGS]   |   ./go lock (refresh $LOCK)" >&2
    exit 2
    ;;
esac
