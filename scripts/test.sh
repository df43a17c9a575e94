#!/usr/bin/env bash
# Runs every test: installs what is missing (no-op when present), the host workspace's tests
# (core, boards, host simulation, scenario tests), the Python module's pytest against the
# virtual board (scripts/python.sh --test), the fuzz targets for a short budget each and a
# planted parser panic the fuzzer must find (scripts/fuzz.sh), both boards' firmware release
# builds with their flash/RAM sizes checked against the budget, the panic check of the
# per-sample path with its planted defect (scripts/panic-check.sh), the core on an emulated
# Cortex-M4F (scripts/emu.sh), the firmware images on the board model (scripts/board-model.sh,
# which also measures the stack against what flip-link leaves it, and runs the self-test images'
# delayed one-pulse), a soak of 10^7 samples with
# faults and scene events (host-sim soak, docs/soak.md), and the cargo-mutants mutants of the
# core lines changed since the last landing (scripts/mutants-ci.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
# Each step's start is printed with the seconds since this script began, so a CI log shows
# where its time goes (CI's budget is 45 min on a fresh machine).
t0=$(date +%s)
step() { echo "== [$(( $(date +%s) - t0 )) s] $*"; }
./scripts/setup.sh
step "host tests"
cargo test --workspace
step "python"
./scripts/python.sh --test
step "fuzz: every target 10 s, then a planted panic that must be found (docs/fuzzing.md)"
# New inputs go to a scratch directory: CI reads the kept corpus and leaves it as it is. 15 s
# each: the fuzz workspace's build from scratch takes most of the step's ~2.5 min share of CI
# (docs/fuzzing.md, "In CI").
NEW_INPUTS=$(mktemp -d) TIME=10 ./scripts/fuzz.sh
TIME=60 ./scripts/fuzz.sh --plant lines
step "firmware builds"
./scripts/build-firmware.sh
# The self-test images for the board model's delayed-pulse check (firmware/src/selftest.rs).
SELFTEST=1 ./scripts/build-firmware.sh
# The F446 image with ADC1 + ADC2 interleaved on the wiper (feature dual-adc, issue #35) for the
# board model's dual-adc check.
DUAL_ADC=1 ./scripts/build-firmware.sh nucleo-f446re
step "panic check of the per-sample path (and its planted unwrap)"
PANIC_CHECK_PLANT=1 ./scripts/panic-check.sh
step "core on the emulated Cortex-M4F (scripts/emu.sh)"
./scripts/emu.sh
step "firmware images on the board model (scripts/board-model.sh)"
./scripts/board-model.sh
step "soak: 10^7 samples (16.7 min of use) with faults and scene events (docs/soak.md)"
cargo run --release -p host-sim -- soak --samples 10000000 --seed 1
step "mutants of the core lines changed since the last landing (.ci/mutants-base)"
./scripts/mutants-ci.sh
step "all tests passed"
