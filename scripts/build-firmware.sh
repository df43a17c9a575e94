#!/usr/bin/env bash
# Build the firmware for every board (release) and check the flash budget.
#
#   scripts/build-firmware.sh            # both boards
#   scripts/build-firmware.sh nucleo-g474re
#
# Uses Debian's toolchain: /usr/bin/cargo + /usr/bin/rustc with RUSTC_BOOTSTRAP=1 so that
# `-Zbuild-std=core` rebuilds core for thumbv7em-none-eabihf from rust-web-src (Debian ships no
# prebuilt thumb target); links with flip-link (the linker firmware/.cargo/config.toml names:
# statics at the top of RAM, the stack below them, so an overflow faults instead of corrupting
# them), which runs `rust-lld` from PATH: here a link to ld.lld-22 in a directory put first on
# PATH, so the linker is the one setup.sh installs whatever else is on the machine. The Debian
# specifics are on this command line, not in firmware/.cargo/config.toml, which stays plain
# stable cargo for rustup users (`cargo run --release` there builds and flashes). ELFs are
# copied to firmware/target/<board>.elf.
#
# PANIC_CHECK_PLANT=1 builds with the feature `plant-sample-unwrap` (an unwrap on the sample
# path, for the panic check's own test) and leaves firmware/target/<board>-plant.elf instead.
# SELFTEST=1 builds with `selftest-delayed-pulse` (one delayed one-pulse at boot, for the board
# model's delayed-pulse check) and leaves firmware/target/<board>-selftest.elf; SELFTEST=plant
# adds the planted defect `plant-pulse-no-delay` (CCR = 1: the delay ignored) and leaves
# firmware/target/<board>-selftest-plant.elf, which that check must fail.
# Fails if a build fails or an image's flash (vector table + text + rodata + data) > 128 KiB:
# on the F446 that is sectors 0–4 (4 × 16 + 64 KiB, RM0390 §3.3 table 4), leaving sector 5 as a
# guard before the scene store's sectors 6–7; the G474's store sits in its last pages. The host
# link (postcard, the scene's serde code, CRC and COBS) took the image past the earlier 64 KiB.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FW="$ROOT/firmware"
TARGET=thumbv7em-none-eabihf
BUDGET="${FLASH_BUDGET_BYTES:-$((128 * 1024))}"  # override only to test the check
BUDGET_KIB=$(awk -v b="$BUDGET" 'BEGIN { printf "%g", b / 1024 }')
BOARDS=("$@")
[ "${#BOARDS[@]}" -eq 0 ] && BOARDS=(nucleo-f446re nucleo-g474re)

export RUSTC=/usr/bin/rustc
export RUSTC_BOOTSTRAP=1
CARGO=/usr/bin/cargo
BUILD_STD=-Zbuild-std=core
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$FW/target}"

# flip-link (scripts/setup.sh installs it) and the rust-lld it runs: ld.lld-22.
LLD_DIR="$CARGO_TARGET_DIR/lld-22-as-rust-lld"
source "$ROOT/scripts/flip-link-env.sh"
flip_link_env build-firmware "$LLD_DIR"
export CARGO_TARGET_THUMBV7EM_NONE_EABIHF_LINKER="$FLIP_LINK"
PLANT=()
SUFFIX=""
if [ "${PANIC_CHECK_PLANT:-0}" = 1 ]; then PLANT=(--features plant-sample-unwrap); SUFFIX="-plant"; fi
# DUAL_ADC=1 builds the F446 with the feature `dual-adc` (ADC1 + ADC2 interleaved on the wiper,
# issue #35) and leaves firmware/target/nucleo-f446re-dual.elf; the G474 has no such image.
# DUAL_ADC=128 builds the experiment `dual-adc-128` (the conversion budget's 128 conversions per
# sample, four triggers) into nucleo-f446re-dual128.elf.
case "${DUAL_ADC:-0}" in
    0) ;;
    1) PLANT+=(--features dual-adc); SUFFIX="$SUFFIX-dual" ;;
    128) PLANT+=(--features dual-adc-128); SUFFIX="$SUFFIX-dual128" ;;
    *) echo "build-firmware: DUAL_ADC is 0, 1 or 128, not '$DUAL_ADC'" >&2; exit 2 ;;
esac
# TOUCH_2D=1 builds the 2D image (feature `touch-2d`: the 4-wire overlay, Controller2d, the 2D
# scene saved in flash or SAW_SCENE_2D / scenes/2d-fig12.toml built in, the host link and the
# store; issue #36) and leaves firmware/target/<board>-2d.elf. TOUCH_2D=largest builds it with the largest 2D scene
# (board-model/scenes/2d-largest.toml: 8 windows of 16 vertices, 32 edges) into
# <board>-2d-largest.elf, for the board model's stack check. TOUCH_2D=plant builds the planted
# defect `plant-touch-no-settle` (conversions a quarter of the settling after the switch) into <board>-2d-plant.elf,
# which the board model's plate-timing check must fail. TOUCH_2D=plant-link builds the planted defect
# `plant-link2d-old-stamp` (records keep the old scene's stamp after a push) into
# <board>-2d-plant-link.elf, which board-model/tests/link2d.rs must fail.
# TOUCH_2D=link is TOUCH_2D=1 (the 2D image has run the link since 2026-11-30; it was an image of
# its own, at opt-level "z", before): <board>-2d.elf.
PROFILE=release
case "${TOUCH_2D:-0}" in
    0) ;;
    1|link) PLANT+=(--features touch-2d); SUFFIX="$SUFFIX-2d" ;;
    largest) PLANT+=(--features touch-2d); SUFFIX="$SUFFIX-2d-largest"
        export SAW_SCENE_2D=board-model/scenes/2d-largest.toml ;;
    plant) PLANT+=(--features plant-touch-no-settle); SUFFIX="$SUFFIX-2d-plant" ;;
    plant-link) PLANT+=(--features plant-link2d-old-stamp); SUFFIX="$SUFFIX-2d-plant-link" ;;
    *) echo "build-firmware: TOUCH_2D is 0, 1, link, largest, plant or plant-link, not '$TOUCH_2D'" >&2; exit 2 ;;
esac
case "${SELFTEST:-0}" in
    0) ;;
    1) PLANT+=(--features selftest-delayed-pulse); SUFFIX="$SUFFIX-selftest" ;;
    plant) PLANT+=(--features selftest-delayed-pulse,plant-pulse-no-delay); SUFFIX="$SUFFIX-selftest-plant" ;;
    *) echo "build-firmware: SELFTEST is 0, 1 or plant, not '$SELFTEST'" >&2; exit 2 ;;
esac

if command -v size >/dev/null 2>&1; then SIZE=size
elif command -v llvm-size-22 >/dev/null 2>&1; then SIZE=llvm-size-22
else SIZE=llvm-size; fi

# Sum the sizes of the named sections from `size -A` (SysV format: name size addr).
sections() { # elf, section names...
    local elf=$1; shift
    "$SIZE" -A "$elf" | awk -v want=" $* " '
        index(want, " " $1 " ") { s += $2 } END { print s + 0 }'
}

fail=0
summary=()
for board in "${BOARDS[@]}"; do
    case "$board" in
        nucleo-f446re) feat=(--features nucleo-f446re) ;;
        nucleo-g474re) feat=(--no-default-features --features nucleo-g474re) ;;
        *) echo "build-firmware: unknown board '$board'" >&2; exit 2 ;;
    esac
    feat+=("${PLANT[@]}")
    echo "==> $board: (cd firmware && PATH=$LLD_DIR:\$PATH RUSTC=$RUSTC RUSTC_BOOTSTRAP=1 CARGO_TARGET_THUMBV7EM_NONE_EABIHF_LINKER=$FLIP_LINK $CARGO build --profile $PROFILE $BUILD_STD ${feat[*]})"
    start=$(date +%s)
    (cd "$FW" && "$CARGO" build --profile "$PROFILE" "$BUILD_STD" "${feat[@]}")
    secs=$(( $(date +%s) - start ))
    elf="$CARGO_TARGET_DIR/$TARGET/$PROFILE/saw-firmware"
    cp "$elf" "$CARGO_TARGET_DIR/$board$SUFFIX.elf"
    flash=$(sections "$elf" .vector_table .text .rodata .data .gnu.sgstubs)
    ram=$(sections "$elf" .data .bss .uninit)
    pct=$(awk -v f="$flash" -v b="$BUDGET" 'BEGIN { printf "%.1f", 100 * f / b }')
    line="$board: flash $flash B ($pct % of $BUDGET_KIB KiB budget), ram $ram B (static; + stack), built in ${secs} s -> firmware/target/$board$SUFFIX.elf"
    echo "$line"
    "$SIZE" -A "$elf" | awk '$1 ~ /^\.(vector_table|text|rodata|data|bss|uninit)$/ { printf "    %-14s %8d\n", $1, $2 }'
    summary+=("$line")
    if [ "$flash" -gt "$BUDGET" ]; then
        echo "build-firmware: $board flash $flash B exceeds the $BUDGET_KIB KiB budget" >&2
        fail=1
    fi
done

echo
echo "== firmware sizes =="
printf '%s\n' "${summary[@]}"
exit "$fail"
