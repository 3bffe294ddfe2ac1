#!/usr/bin/env bash
# One entry point for a fresh machine: set everything up, then run the demo or the tests.
#   bash scripts/dev.sh demo   # set up + the main job (examples/demo.py)
#   bash scripts/dev.sh test   # set up + every test (Rust core, CLI, Python, stubs, the wheel on the oldest/newest Python)
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3}
export PYO3_PYTHON=$("$PY" -c 'import sys; print(sys.executable)')
export MPLBACKEND=Agg

setup() {
  command -v cargo >/dev/null || { echo "dev.sh: cargo not found: install the Rust toolchain (rustup) first" >&2; exit 1; }
  "$PY" -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
  # stale extension modules in the source tree would shadow the fresh build
  rm -f python/popup/_core*.so python/popup/_core*.pyd
  # editable install: builds popup._core in release (pyproject: [tool.maturin] profile)
  "$PY" -m pip install --quiet --disable-pip-version-check --no-build-isolation -e .
}

case "${1:-}" in
  demo)
    setup
    "$PY" examples/diagnose_demo.py
    ;;
  test)
    setup
    # the test-release profile (Cargo.toml): release optimisation, a quicker build
    if cargo nextest --version >/dev/null 2>&1; then
      cargo nextest run --cargo-profile test-release --workspace --exclude popup-py --no-fail-fast
    else
      cargo test --profile test-release --workspace --exclude popup-py
    fi
    # one worker per core, each test file on one worker (its module fixtures built once)
    "$PY" -m pytest -q -n auto --dist loadfile
    # the wheel on the oldest and newest Python on the machine, from a plain pip install
    bash scripts/check_pythons.sh
    ;;
  *)
    echo "usage: bash scripts/dev.sh demo|test" >&2
    exit 2
    ;;
esac
