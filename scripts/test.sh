#!/usr/bin/env bash
# Runs every test: installs what is missing (no-op when present), the host workspace's tests
# (core, boards, host simulation, scenario tests), the fuzz targets for a short budget each and a
# planted parser panic the fuzzer must find (scripts/fuzz.sh), both boards' firmware release
# builds with their flash/RAM sizes checked against the 64 KiB budget, the core on an emulated
# Cortex-M4F (scripts/emu.sh), the firmware images on the board model (scripts/board-model.sh),
# and the cargo-mutants mutants of the core lines changed since the last landing
# (scripts/mutants-ci.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
echo "== host tests"
cargo test --workspace
echo "== fuzz: every target 15 s, then a planted panic that must be found (docs/fuzzing.md)"
# New inputs go to a scratch directory: CI reads the kept corpus and leaves it as it is. 15 s
# each: the fuzz workspace's build from scratch takes most of the step's ~2.5 min share of CI
# (docs/fuzzing.md, "In CI").
NEW_INPUTS=$(mktemp -d) TIME=15 ./scripts/fuzz.sh
TIME=60 ./scripts/fuzz.sh --plant lines
echo "== firmware builds"
./scripts/build-firmware.sh
./scripts/emu.sh
./scripts/board-model.sh
echo "== mutants of the core lines changed since the last landing (.ci/mutants-base)"
./scripts/mutants-ci.sh
