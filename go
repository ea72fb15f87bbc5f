#!/usr/bin/env bash
# Set-up-and-go for a fresh Debian machine (idempotent; fast when set-up is done).
#   ./go run   [SCENE] [OUTDIR]   build the sphere model of SCENE (default: cases/open_pit.toml)
#   ./go test  [PYTEST ARGS]      run the test suite
set -euo pipefail
cd "$(dirname "$0")"

say() { echo "[go] $*" >&2; }

setup() {
  local missing=() sudo=""
  command -v python3 >/dev/null || missing+=(python3)
  python3 -c 'import venv, ensurepip' 2>/dev/null || missing+=(python3-venv)
  command -v yade >/dev/null || missing+=(yade)
  command -v liggghts >/dev/null || missing+=(liggghts)
  command -v mpirun >/dev/null || missing+=(openmpi-bin)
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
  local stamp=".venv/.installed-$(cat pyproject.toml | sha1sum | cut -c1-12)"
  if [ ! -f "$stamp" ]; then
    say "installing the project and its Python dependencies into .venv"
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e ".[test,mpi]"
    rm -f .venv/.installed-*
    touch "$stamp"
  fi
}

cmd="${1:-}"
shift || true
case "$cmd" in
  run)
    setup
    scene="${1:-cases/open_pit.toml}"
    out="${2:-out/$(basename "${scene%.toml}")}"
    exec .venv/bin/sgim build "$scene" -o "$out"
    ;;
  test)
    setup
    exec .venv/bin/python -m pytest -q "$@"
    ;;
  *)
    echo "usage: ./go run [SCENE] [OUTDIR]   |   ./go test [PYTEST ARGS]" >&2
    exit 2
    ;;
esac
