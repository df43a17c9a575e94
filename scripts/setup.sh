#!/usr/bin/env bash
# Idempotent toolchain installer for a fresh Debian machine (run as root; CI has no stdin).
#
# Installs Debian's Rust toolchain (rustc-web/cargo-web + rust-web-src for `-Zbuild-std=core`
# on thumbv7em-none-eabihf — rustup targets are not needed), the lld-22 linker, QEMU for Arm,
# libfontconfig1-dev (host-side plotting) and, for the board model (board-model/, test-only, GPL),
# libunicorn-dev with libclang-dev (bindgen), and Chromium with chromedriver for the web panel's
# browser test (saw/tests/browser.rs), and g++ for libFuzzer (libfuzzer-sys builds it from C++
# source). apt is skipped entirely when everything is present. Then the cargo-installed tools:
# defmt-print, cargo-fuzz (the fuzz targets, scripts/fuzz.sh) and flip-link.
set -euo pipefail

PACKAGES=(rustc-web cargo-web rust-web-src lld-22 qemu-system-arm libfontconfig1-dev libunicorn-dev libclang-dev chromium chromium-driver g++)

export DEBIAN_FRONTEND=noninteractive

installed() {
    # dpkg-query prints "install ok installed" for a fully installed package.
    [ "$(dpkg-query -W -f='${Status}' "$1" 2>/dev/null || true)" = "install ok installed" ]
}

missing=()
for p in "${PACKAGES[@]}"; do
    if installed "$p"; then
        echo "setup: $p already installed ($(dpkg-query -W -f='${Version}' "$p"))"
    else
        missing+=("$p")
    fi
done

if [ "${#missing[@]}" -eq 0 ]; then
    echo "setup: all ${#PACKAGES[@]} packages present, apt not run"
else
    if [ "$(id -u)" -ne 0 ]; then
        echo "setup: need root to install: ${missing[*]}" >&2
        exit 1
    fi
    echo "setup: installing ${missing[*]}"
    apt-get update
    apt-get install -y "${missing[@]}" </dev/null
    for p in "${missing[@]}"; do
        installed "$p" || { echo "setup: $p failed to install" >&2; exit 1; }
        echo "setup: installed $p ($(dpkg-query -W -f='${Version}' "$p"))"
    done
fi

# defmt-print decodes the emulator image's defmt logs (scripts/emu.sh); skipped when present.
if defmt-print --version >/dev/null 2>&1 || "$HOME/.cargo/bin/defmt-print" --version >/dev/null 2>&1; then
    echo "setup: defmt-print already installed"
else
    echo "setup: installing defmt-print (cargo install --locked)"
    RUSTC=/usr/bin/rustc /usr/bin/cargo install defmt-print --locked
fi

# cargo-fuzz runs the fuzz targets on Debian's rustc (scripts/fuzz.sh, CI's fuzz step); skipped
# when present. cargo finds it in ~/.cargo/bin.
if cargo-fuzz --version >/dev/null 2>&1 || "$HOME/.cargo/bin/cargo-fuzz" --version >/dev/null 2>&1; then
    echo "setup: cargo-fuzz already installed"
else
    echo "setup: installing cargo-fuzz (cargo install --locked)"
    RUSTC=/usr/bin/rustc /usr/bin/cargo install cargo-fuzz --locked
fi

# flip-link links the firmware images (firmware/.cargo/config.toml: the stack below the statics,
# so an overflow faults instead of corrupting them); skipped when present. RUSTC names Debian's
# compiler: under rustup, flip-link's own rust-toolchain.toml would ask for a toolchain that
# may not be installed.
# (flip-link has no --version: it would hand the flag to the linker.)
if command -v flip-link >/dev/null 2>&1 || [ -x "$HOME/.cargo/bin/flip-link" ]; then
    echo "setup: flip-link already installed"
else
    echo "setup: installing flip-link (cargo install --locked)"
    RUSTC=/usr/bin/rustc /usr/bin/cargo install flip-link --locked
fi

# What the firmware build will use.
for tool in /usr/bin/rustc /usr/bin/cargo /usr/bin/ld.lld-22 /usr/bin/qemu-system-arm; do
    if [ -x "$tool" ]; then
        echo "setup: $tool -> $("$tool" --version 2>/dev/null | head -n1)"
    else
        echo "setup: warning: $tool not found" >&2
    fi
done

# The Python module `sawlink` (python/, docs/link.md "From Python"): a venv in target/venv with
# maturin and pytest, the abi3 wheel built and installed into it. Idempotent: the venv and its
# tools are kept, and an unchanged crate is a cargo no-op (a few seconds to repackage).
"$(dirname "$0")/python.sh"
