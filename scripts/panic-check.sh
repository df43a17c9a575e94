#!/usr/bin/env bash
# The panic check: nothing reachable from the control loop's per-sample path may panic.
#
#   scripts/panic-check.sh                      # both boards' release ELFs
#   scripts/panic-check.sh nucleo-g474re
#   PANIC_CHECK_PLANT=1 scripts/panic-check.sh  # then also the planted defect must turn it red
#
# `board-model panic-check` decodes the image's Thumb code into a call graph (direct calls and
# tail calls) and follows it from the roots below; any path into core::panicking::*,
# core::panic*, unwrap/expect failures, slice/str index failures, RefCell borrow failures,
# defmt's panic or the panic handler prints its chain (root -> ... -> panic function) and fails.
# Indirect branches (blx rN) cannot be followed: they are counted and named. The roots are the
# firmware's per-sample work, kept out of line with #[inline(never)] (firmware/src/main.rs):
#   sample_step  a sample through Controller::on_sample onto the burst gate, the RF level and
#                the telemetry stream;
#   tick_step    the stale-sensor watchdog (Controller::on_tick) onto the gate;
#   deliver      the sampler's stamping and queueing of a batch.
# The executor, embassy's ADC ring buffer and the link task are outside the roots (docs/panic-check.md).
# Functions whose panics cannot happen by construction are listed, with the reason, in
# scripts/panic-check.allow: the check does not enter them and prints them.
#
# With PANIC_CHECK_PLANT=1 it also builds the F446 image with the feature plant-sample-unwrap
# (an .unwrap() in sample_step, scripts/build-firmware.sh leaves firmware/target/
# nucleo-f446re-plant.elf) and fails unless the check goes red on it through
# core::option::unwrap_failed.
#
# Needs firmware/target/<board>.elf (scripts/build-firmware.sh).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BOARDS=("$@")
[ "${#BOARDS[@]}" -eq 0 ] && BOARDS=(nucleo-f446re nucleo-g474re)
FW_DIR="${SAW_FIRMWARE_DIR:-$ROOT/firmware/target}"
ALLOW="$ROOT/scripts/panic-check.allow"
ROOTS=(--root saw_firmware::sample_step --root saw_firmware::tick_step --root saw_firmware::deliver)
# TOUCH_2D=1: the 2D images (<board>-2d.elf, TOUCH_2D=1 scripts/build-firmware.sh) and their
# per-frame path (firmware/src/touch2d.rs):
#   touch2d::on_event     the TIM3 CC1 interrupt: the plate pins, the ADC channel and start,
#                         at the frame boundary the DMA re-armed and the frame queued;
#   touch2d::frame_step   a frame through TouchSensor and Controller2d onto the burst gate;
#   touch2d::tick_step2d  the stale watchdog (Controller2d::on_tick) onto the gate.
# Without TOUCH_2D the 2D images are checked too when they are there (SKIPPED, saying so, when
# not); TOUCH_2D=1 checks only them and needs them.
SUFFIX=""
ROOTS_2D=(--root saw_firmware::touch2d::on_event --root saw_firmware::touch2d::frame_step --root saw_firmware::touch2d::tick_step2d)
if [ "${TOUCH_2D:-0}" = 1 ]; then
    SUFFIX="-2d"
    ROOTS=("${ROOTS_2D[@]}")
fi

# The model builds into the host workspace's target directory, as scripts/board-model.sh does;
# the planted firmware into firmware/target (build-firmware.sh's own default), never there.
BM_TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"
unset CARGO_TARGET_DIR
(cd "$ROOT/board-model" && CARGO_TARGET_DIR="$BM_TARGET" cargo build -q --release --bin board-model)
BM="$BM_TARGET/release/board-model"

fail=0
for b in "${BOARDS[@]}"; do
    elf="$FW_DIR/$b$SUFFIX.elf"
    [ -f "$elf" ] || { echo "panic-check: $elf is missing: run scripts/build-firmware.sh first" >&2; exit 1; }
    echo "== panic check: $b"
    "$BM" panic-check --elf "$elf" "${ROOTS[@]}" --allow-file "$ALLOW" || fail=1
    if [ "${TOUCH_2D:-0}" != 1 ]; then
        elf2="$FW_DIR/$b-2d.elf"
        if [ -f "$elf2" ]; then
            echo "== panic check: $b, the 2D image"
            "$BM" panic-check --elf "$elf2" "${ROOTS_2D[@]}" --allow-file "$ALLOW" || fail=1
        else
            echo "panic check: $b: the 2D image SKIPPED: no $elf2 (TOUCH_2D=1 scripts/build-firmware.sh)"
        fi
    fi
done

if [ "${PANIC_CHECK_PLANT:-0}" = 1 ]; then
    echo "== panic check: the planted unwrap (feature plant-sample-unwrap, nucleo-f446re) must fail it"
    PANIC_CHECK_PLANT=1 "$ROOT/scripts/build-firmware.sh" nucleo-f446re >/dev/null
    out=$("$BM" panic-check --elf "$ROOT/firmware/target/nucleo-f446re-plant.elf" "${ROOTS[@]}" --allow-file "$ALLOW") && rc=0 || rc=$?
    echo "$out" | grep -A3 "PANIC PATH" || true
    if [ "$rc" -eq 1 ] && grep -q "core::option::unwrap_failed" <<<"$out"; then
        echo "ok: the planted unwrap is caught (exit 1, a path into core::option::unwrap_failed)"
    else
        echo "panic-check: the planted unwrap was NOT caught (exit $rc)" >&2
        fail=1
    fi
fi
exit "$fail"
