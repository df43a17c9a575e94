#!/usr/bin/env bash
# The real firmware images on the board model (board-model/: Unicorn + STM32 peripheral models,
# GPL-2.0-or-later, test-only — nothing that ships links it).
#
#   scripts/board-model.sh                 # both boards; ELFs from scripts/build-firmware.sh
#   scripts/board-model.sh nucleo-g474re
#
# 1. the model's own tests (peripheral models against the reference manuals, the NVIC, the
#    machine), and its tests on the firmware images (faults, panic path, findings of issue #9);
# 2. `board-model check` per board: boot log, clock tree, 15 MHz carrier from registers and
#    edges, 10 000 samples/s, the closed loop against host-sim, duty/on-time caps, sensor-to-gate
#    latency, rail fault, watchdog reset, RF level (DAC on PA4), the host link and saves, 2 m/s
#    strokes with an open wiper, and the deepest stack over all of those runs (the region below
#    the initial SP is painted before reset) against what flip-link reserves: fails under 1 KiB
#    of headroom. JSON summaries in target/board-model/<board>.json;
# 3. `board-model delayed-pulse` per board on firmware/target/<board>-selftest.elf (issue #17's
#    delayed one-pulse fired at boot by the self-test image: rise arr + 1 − ccr ticks after CEN,
#    high ccr ticks, docs/board-model.md); skipped, saying so, when that image is missing
#    (`SELFTEST=1 scripts/build-firmware.sh` builds it; scripts/test.sh does);
# 3b. on the NUCLEO-F446RE, issue #35's dual interleaved image (firmware/target/
#    nucleo-f446re-dual.elf, `DUAL_ADC=1 scripts/build-firmware.sh nucleo-f446re`): every `check`
#    above, then `board-model dual-adc` (ADC2 the plan's delay after ADC1, 16 pairs per trigger,
#    10 kHz, the position's scale at rest, latency, open and shorted wiper); skipped, saying so,
#    when that image is missing;
# 4. `saw` against the images through `board-model serve` (board-model/tests/serve.rs, both boards:
#    hello, every scene pushed and read back, refusals, a save that must erase — the F446's
#    128 KiB sector — with a power cycle into it, a 1 kHz stream) and the panel's save on the
#    F446 image (saw/tests/ui.rs); builds the debug `saw`;
# 5. a summary per board: flash, static RAM, stack reserved, deepest, headroom.
# The tests of step 1 include tests/touch2d.rs, issue #36's 2D images (firmware/target/
# <board>-2d.elf and <board>-2d-largest.elf, both boards): plate switching at the designed times,
# lift-off, sensor-to-gate latency, edge pulses, the closed loop against host-sim, the stack with
# the largest 2D scene (docs/board-model.md, "The 2D image"); this script builds those images
# first when they are missing (TOUCH_2D=1 / TOUCH_2D=largest scripts/build-firmware.sh); and
# tests/link2d.rs, the 2D image's host link and store (the same <board>-2d.elf, both boards):
# push and read back, refusals, windows moved live, x and y in the stream, a save and power cuts
# in it.
# Needs firmware/target/<board>.elf (scripts/build-firmware.sh) and defmt-print (scripts/setup.sh).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="$ROOT/target/board-model"
mkdir -p "$OUT"
BOARDS=("$@")
[ "${#BOARDS[@]}" -eq 0 ] && BOARDS=(nucleo-f446re nucleo-g474re)
export SAW_FIRMWARE_DIR="${SAW_FIRMWARE_DIR:-$ROOT/firmware/target}"
for b in "${BOARDS[@]}"; do
    [ -f "$SAW_FIRMWARE_DIR/$b.elf" ] || { echo "board-model: $SAW_FIRMWARE_DIR/$b.elf is missing: run scripts/build-firmware.sh first" >&2; exit 1; }
done
# The model shares the host workspace's target directory (host-sim and its dependencies are
# built once), unless CARGO_TARGET_DIR names another.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
for kind in 1 largest; do
    suffix=-2d; [ "$kind" = largest ] && suffix=-2d-largest
    for b in nucleo-f446re nucleo-g474re; do
        if [ ! -f "$SAW_FIRMWARE_DIR/$b$suffix.elf" ]; then
            echo "== board model: building the 2D image $b$suffix.elf (TOUCH_2D=$kind)"
            TOUCH_2D=$kind CARGO_TARGET_DIR="$ROOT/firmware/target" "$ROOT/scripts/build-firmware.sh" "$b" >/dev/null
            [ "$SAW_FIRMWARE_DIR" = "$ROOT/firmware/target" ] || cp "$ROOT/firmware/target/$b$suffix.elf" "$SAW_FIRMWARE_DIR/"
        fi
    done
done
cd "$ROOT/board-model"
echo "== board model: tests"
cargo test --release
cargo build --release --bin board-model
fail=0
for b in "${BOARDS[@]}"; do
    echo "== board model: $b"
    "$CARGO_TARGET_DIR/release/board-model" check --board "$b" --elf "$SAW_FIRMWARE_DIR/$b.elf" \
        --json-file "$OUT/$b.json" || fail=1
    st="$SAW_FIRMWARE_DIR/$b-selftest.elf"
    if [ -f "$st" ]; then
        "$CARGO_TARGET_DIR/release/board-model" delayed-pulse --board "$b" --elf "$st" || fail=1
    else
        echo "board model: $b: delayed-pulse check SKIPPED: no $st (SELFTEST=1 scripts/build-firmware.sh)"
    fi
    dual="$SAW_FIRMWARE_DIR/$b-dual.elf"
    if [ "$b" = nucleo-f446re ]; then
        if [ -f "$dual" ]; then
            "$CARGO_TARGET_DIR/release/board-model" check --board "$b" --elf "$dual" \
                --json-file "$OUT/$b-dual.json" || fail=1
            "$CARGO_TARGET_DIR/release/board-model" dual-adc --board "$b" --elf "$dual" || fail=1
        else
            echo "board model: $b: dual-adc check SKIPPED: no $dual (DUAL_ADC=1 scripts/build-firmware.sh nucleo-f446re)"
        fi
    fi
done

# saw against the images, served by the model behind a pty: the tests the plain `cargo test`
# above ignores (they need the saw binary), for the boards named. The debug saw, built with its
# tests (scripts/test.sh's `cargo test --workspace` has built most of it), only moves bytes.
echo "== board model: saw against the images (board-model serve)"
cargo test -p saw --manifest-path "$ROOT/Cargo.toml" --test ui --no-run
if [[ " ${BOARDS[*]} " == *" nucleo-f446re "* ]]; then
    # The panel's save on the F446 image, erasing a sector (saw/tests/ui.rs).
    SAW_BOARD_MODEL_BIN="$CARGO_TARGET_DIR/release/board-model" \
        SAW_F446_ELF="$SAW_FIRMWARE_DIR/nucleo-f446re.elf" \
        cargo test -p saw --manifest-path "$ROOT/Cargo.toml" --test ui -- --ignored \
        the_panels_save_on_the_f446_image || fail=1
fi
filters=()
for b in "${BOARDS[@]}"; do
    case "$b" in
        nucleo-f446re) filters+=(f446_) ;;
        nucleo-g474re) filters+=(g474_) ;;
    esac
done
SAW_BIN="$CARGO_TARGET_DIR/debug/saw" cargo test --release --test serve -- --ignored "${filters[@]}" || fail=1

if command -v size >/dev/null 2>&1; then SIZE=size; else SIZE=llvm-size-22; fi
echo
echo "== firmware: flash, static RAM and stack (deepest over every board-model run above)"
for b in "${BOARDS[@]}"; do
    flash=$("$SIZE" -A "$SAW_FIRMWARE_DIR/$b.elf" | awk '$1 ~ /^\.(vector_table|text|rodata|data|gnu\.sgstubs)$/ { s += $2 } END { print s + 0 }')
    python3 - "$OUT/$b.json" "$b" "$flash" <<'PY' || fail=1
import json, sys
path, board, flash = sys.argv[1], sys.argv[2], int(sys.argv[3])
s = json.load(open(path)).get("stack")
if not s:
    sys.exit(f"{board}: no stack measurement in {path}")
r = s["region"]
reserved, deepest = r["top"] - r["bottom"], r["top"] - s["lowest"]
print(f"{board}: flash {flash} B, static RAM {r['static_bytes']} B, stack reserved {reserved} B "
      f"({'below the statics: flip-link' if r['flipped'] else 'above the statics'}), "
      f"deepest {deepest} B, headroom {reserved - deepest} B")
PY
done
exit "$fail"
