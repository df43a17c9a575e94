#!/usr/bin/env bash
# The Python module `sawlink` (python/, PyO3): makes a venv (target/venv, or $SAWLINK_VENV) with
# maturin and pytest, builds the abi3 wheel (`maturin build --profile wheel`, one wheel for CPython
# 3.8 and later, written to target/wheels/) and installs it into the venv. With --test, then
# builds host-sim (release) and runs python/tests/ with pytest against its virtual board.
# CARGO_TARGET_DIR moves target/ (the venv and the wheels with it).
# Idempotent: an existing venv and its tools are kept, and an unchanged crate is a cargo no-op.
#
#   ./scripts/python.sh            # build and install
#   ./scripts/python.sh --test     # … and run the tests
#   target/venv/bin/python -c 'import sawlink; print(sawlink.__version__)'
set -euo pipefail
cd "$(dirname "$0")/.."

TEST=0
case "${1:-}" in
    "") ;;
    --test) TEST=1 ;;
    *) echo "python.sh: unknown argument \`$1\`: the only one is --test" >&2; exit 2 ;;
esac

TARGET=${CARGO_TARGET_DIR:-target}
VENV=${SAWLINK_VENV:-$TARGET/venv}
PYTHON=${PYTHON:-python3}
start=$(date +%s)

if [ ! -x "$VENV/bin/python" ]; then
    echo "python.sh: making the venv $VENV with $("$PYTHON" --version)"
    "$PYTHON" -m venv "$VENV"
fi
# pip only when a tool is missing: a no-op run stays offline and quick.
if ! "$VENV/bin/maturin" --version >/dev/null 2>&1 || ! "$VENV/bin/python" -c 'import pytest' 2>/dev/null; then
    "$VENV/bin/python" -m pip install --quiet "maturin>=1.5,<2" "pytest>=7"
fi

# The wheel: optimised (the `wheel` profile: release without debug info), stripped
# (pyproject.toml), into target/wheels.
rm -f "$TARGET"/wheels/sawlink-*.whl
"$VENV/bin/maturin" build --profile wheel --quiet -m python/Cargo.toml -o "$TARGET/wheels" \
    --interpreter "$VENV/bin/python"
wheel=$(ls "$TARGET"/wheels/sawlink-*.whl)
"$VENV/bin/python" -m pip install --quiet --force-reinstall --no-deps "$wheel"
echo "python.sh: installed $(basename "$wheel") into $VENV ($(( $(date +%s) - start )) s so far)"

if [ "$TEST" = 1 ]; then
    cargo build --release -p host-sim
    host_sim=$(cd "$TARGET" && pwd)/release/host-sim
    SAWLINK_HOST_SIM="$host_sim" "$VENV/bin/python" -m pytest -q python/tests
    echo "python.sh: built and tested in $(( $(date +%s) - start )) s"
fi
