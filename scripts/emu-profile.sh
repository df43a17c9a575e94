#!/usr/bin/env bash
# Where the instructions of one case go: builds the emulator image with EMU_PROFILE=<kind>/<traj>
# (firmware/emu replays only that one-region scene, see `profile` in its main.rs), runs it in
# QEMU one instruction per translation block with the execution trace on, and counts executed
# instructions per source line of saw-core (innermost inlined frame, addr2line) and per function.
#
#   scripts/emu-profile.sh grating-velocity/back-and-forth [top-N]
#
# Needs target/golden/golden.bin (scripts/emu.sh makes it). Output in target/emu-profile/<case>/.
# Counts include the scene load (once) and the harness loop; divide by the samples (5 000).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
CASE="${1:?usage: emu-profile.sh <kind>/<trajectory> [top-N]}"
TOP="${2:-40}"
OUT="$ROOT/target/emu-profile/${CASE//\//_}"
mkdir -p "$OUT"
EMU="$ROOT/firmware/emu"
TDIR="$EMU/target/profile"
ELF="$TDIR/thumbv7em-none-eabihf/release/saw-emu"
source "$ROOT/scripts/flip-link-env.sh"
flip_link_env emu-profile "$EMU/target/lld-22-as-rust-lld"
(cd "$EMU" && GOLDEN_DIR="$ROOT/target/golden" EMU_PROFILE="$CASE" DEFMT_LOG=info RUSTC=/usr/bin/rustc \
    RUSTC_BOOTSTRAP=1 CARGO_TARGET_DIR="$TDIR" CARGO_TARGET_THUMBV7EM_NONE_EABIHF_LINKER="$FLIP_LINK" \
    /usr/bin/cargo build -q --release -Zbuild-std=core)
timeout 600 qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -nographic \
    -semihosting-config enable=on,target=native -icount shift=0 -singlestep \
    -d exec,nochain -D "$OUT/trace.log" -kernel "$ELF" >"$OUT/raw.bin" </dev/null
DEFMT_PRINT=defmt-print; command -v defmt-print >/dev/null || DEFMT_PRINT="$HOME/.cargo/bin/defmt-print"
"$DEFMT_PRINT" -e "$ELF" <"$OUT/raw.bin" | grep PROFILE || true
# "Trace N: 0xhost [flags/pc/...]": one line per executed instruction with -singlestep.
sed -n 's|^Trace [0-9]*: 0x[0-9a-f]* \[[0-9a-f]*/\([0-9a-f]*\)/.*|\1|p' "$OUT/trace.log" \
    | sort | uniq -c | awk '{print $2, $1}' >"$OUT/pcs.txt"
rm -f "$OUT/trace.log"
ADDR2LINE=llvm-addr2line-22; command -v "$ADDR2LINE" >/dev/null || ADDR2LINE=llvm-addr2line
awk '{print "0x"$1}' "$OUT/pcs.txt" | "$ADDR2LINE" -e "$ELF" -f -C -i --output-style=JSON >"$OUT/lines.json"
python3 - "$OUT" "$TOP" <<'PY'
import json, sys, collections, os
out, top = sys.argv[1], int(sys.argv[2])
counts = [int(l.split()[1]) for l in open(os.path.join(out, "pcs.txt"))]
by_line, by_fn, total = collections.Counter(), collections.Counter(), 0
for c, l in zip(counts, open(os.path.join(out, "lines.json"))):
    frames = json.loads(l)["Symbol"]
    total += c
    inner = frames[0]
    f = inner["FileName"].split("/core/src/")[-1] if "/core/src/" in inner["FileName"] else os.path.basename(inner["FileName"])
    by_line[f"{f}:{inner['Line']} ({inner['FunctionName'].split('<')[0][-60:]})"] += c
    # every inlined frame gets the count once (inclusive)
    for fn in {fr["FunctionName"] for fr in frames}:
        by_fn[fn[-90:]] += c
print(f"total instructions traced: {total}")
print("\n== inclusive per function (inlined frames included)")
for k, v in by_fn.most_common(top):
    print(f"{v:>10} {k}")
print("\n== per source line (innermost frame)")
for k, v in by_line.most_common(top):
    print(f"{v:>10} {k}")
PY
