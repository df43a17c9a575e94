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
# Also printed: per sample, each stage of `Controller::on_sample` (the frame just inside it, by
# on_sample's line) and the functions it calls that stay calls. ASM=<name> (a substring of a
# function's symbol, e.g. ASM=step_hybrid) writes that function's disassembly with each
# instruction's executions per sample to target/emu-profile/<case>/asm.txt.
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
"$DEFMT_PRINT" -e "$ELF" <"$OUT/raw.bin" | grep PROFILE | tee "$OUT/profile.txt" || true
# "Trace N: 0xhost [flags/pc/...]": one line per executed instruction with -singlestep.
sed -n 's|^Trace [0-9]*: 0x[0-9a-f]* \[[0-9a-f]*/\([0-9a-f]*\)/.*|\1|p' "$OUT/trace.log" \
    | sort | uniq -c | awk '{print $2, $1}' >"$OUT/pcs.txt"
rm -f "$OUT/trace.log"
ADDR2LINE=llvm-addr2line-22; command -v "$ADDR2LINE" >/dev/null || ADDR2LINE=llvm-addr2line
awk '{print "0x"$1}' "$OUT/pcs.txt" | "$ADDR2LINE" -e "$ELF" -f -C -i --output-style=JSON >"$OUT/lines.json"
OBJDUMP=llvm-objdump-22; command -v "$OBJDUMP" >/dev/null || OBJDUMP=llvm-objdump
if [ -n "${ASM:-}" ]; then
    "$OBJDUMP" -d --no-show-raw-insn -C "$ELF" >"$OUT/disasm.txt"
fi
python3 - "$OUT" "$TOP" "${ASM:-}" <<'PY'
import json, sys, collections, os, re
out, top, asm = sys.argv[1], int(sys.argv[2]), sys.argv[3]
prof = open(os.path.join(out, "profile.txt")).read() if os.path.exists(os.path.join(out, "profile.txt")) else ""
m = re.search(r"n=(\d+)", prof)
n = int(m.group(1)) if m else 5000
pcs = [(int(a, 16), int(c)) for a, c in (l.split() for l in open(os.path.join(out, "pcs.txt")))]
by_line, by_fn, stages, total = collections.Counter(), collections.Counter(), collections.Counter(), 0
for (_, c), l in zip(pcs, open(os.path.join(out, "lines.json"))):
    frames = json.loads(l)["Symbol"]
    total += c
    inner = frames[0]
    f = inner["FileName"].split("/core/src/")[-1] if "/core/src/" in inner["FileName"] else os.path.basename(inner["FileName"])
    by_line[f"{f}:{inner['Line']} ({inner['FunctionName'].split('<')[0][-60:]})"] += c
    # every inlined frame gets the count once (inclusive)
    names = [fr["FunctionName"] for fr in frames]
    for fn in set(names):
        by_fn[fn[-90:]] += c
    # Per sample, by stage: an instruction inlined into on_sample counts for the frame just
    # inside it (on_sample's own line when it is on_sample's); one outside it, for the function
    # it is in.
    inside = [i for i, nm in enumerate(names) if nm.endswith("::on_sample")]
    if not inside:
        stages["(call) " + names[-1][-70:]] += c
        continue
    i = inside[0]
    where = f"on_sample:{frames[i]['Line']}"
    stages[(names[i - 1].split("::")[-1][:40] + " @ " if i else "") + where] += c
print(f"total instructions traced: {total}")
print("\n== inclusive per function (inlined frames included)")
for k, v in by_fn.most_common(top):
    print(f"{v:>10} {k}")
print("\n== per source line (innermost frame)")
for k, v in by_line.most_common(top):
    print(f"{v:>10} {k}")
print(f"\n== per sample ({n} samples), by stage of on_sample; calls it makes by name")
for k, v in stages.most_common(top):
    print(f"{v / n:>10.2f} {k}")
if asm:
    per_pc = dict(pcs)
    lines = open(os.path.join(out, "disasm.txt")).read().split("\n")
    heads = [i for i, l in enumerate(lines) if l.endswith(">:") and asm in l]
    if not heads:
        sys.exit(f"ASM={asm}: no function of that name in the image")
    with open(os.path.join(out, "asm.txt"), "w") as f:
        for h in heads:
            total = 0.0
            body = []
            for l in lines[h + 1:]:
                mm = re.match(r"\s*([0-9a-f]+):\s*(.*)", l)
                if not l.strip():
                    break
                if not mm:
                    continue
                per = per_pc.get(int(mm.group(1), 16), 0) / n
                total += per
                body.append(f"{per:8.2f} {mm.group(1)} {mm.group(2)}")
            name = lines[h].rstrip(":")
            f.write(f"{name}: {total:.1f} per sample\n" + "\n".join(body) + "\n\n")
            print(f"\n{name}: {total:.1f} instructions per sample -> {out}/asm.txt")
PY
