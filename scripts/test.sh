#!/usr/bin/env bash
# Runs every test: installs what is missing (no-op when present), the host workspace's tests
# (core, boards, host simulation, scenario tests), both boards' firmware release builds with
# their flash/RAM sizes checked against the 64 KiB budget, the core on an emulated Cortex-M4F
# (scripts/emu.sh), the firmware images on the board model (scripts/board-model.sh), a soak of
# 10^7 samples with faults and scene events (host-sim soak, docs/soak.md), and the
# cargo-mutants mutants of the core lines changed since the last landing (scripts/mutants-ci.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
echo "== host tests"
cargo test --workspace
echo "== firmware builds"
./scripts/build-firmware.sh
./scripts/emu.sh
./scripts/board-model.sh
echo "== soak: 10^7 samples (16.7 min of use) with faults and scene events (docs/soak.md)"
cargo run --release -p host-sim -- soak --samples 10000000 --seed 1
echo "== mutants of the core lines changed since the last landing (.ci/mutants-base)"
./scripts/mutants-ci.sh
