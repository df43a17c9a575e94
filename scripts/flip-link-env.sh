# Sourced by scripts/build-firmware.sh and scripts/emu.sh: finds flip-link (scripts/setup.sh
# installs it) and puts ld.lld-22 on PATH as the `rust-lld` flip-link runs (flip-link 0.1.12
# hard-codes that name; Debian ships the linker as ld.lld-22). Usage: flip_link_env WHO DIR —
# sets FLIP_LINK and prepends DIR (which receives the rust-lld link) to PATH.
flip_link_env() {
    local who=$1 dir=$2
    if command -v flip-link >/dev/null 2>&1; then FLIP_LINK=$(command -v flip-link)
    elif [ -x "$HOME/.cargo/bin/flip-link" ]; then FLIP_LINK="$HOME/.cargo/bin/flip-link"
    else echo "$who: flip-link not found: run scripts/setup.sh (cargo install flip-link --locked)" >&2; exit 1; fi
    mkdir -p "$dir"
    ln -sf /usr/bin/ld.lld-22 "$dir/rust-lld"
    export PATH="$dir:$PATH"
}
