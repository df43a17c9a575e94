#!/usr/bin/env bash
# Runs every test: installs what is missing (no-op when present), the host workspace's tests
# (core, boards, host simulation, scenario tests), both boards' firmware release builds with
# their flash/RAM sizes checked against the 64 KiB budget, the core on an emulated Cortex-M4F
# (scripts/emu.sh), the firmware images on the board model (scripts/board-model.sh, which also
# measures the stack against what flip-link leaves it), the panic check of the per-sample path
# with its planted defect (scripts/panic-check.sh), and the cargo-mutants mutants of the core
# lines changed since the last landing (scripts/mutants-ci.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
echo "== host tests"
cargo test --workspace
echo "== firmware builds"
./scripts/build-firmware.sh
echo "== panic check of the per-sample path (and its planted unwrap)"
PANIC_CHECK_PLANT=1 ./scripts/panic-check.sh
./scripts/emu.sh
./scripts/board-model.sh
echo "== mutants of the core lines changed since the last landing (.ci/mutants-base)"
./scripts/mutants-ci.sh
