#!/usr/bin/env bash
# Coverage-guided fuzzing (issue #16) of every decoder that takes bytes from outside, with
# cargo-fuzz (libFuzzer):
#
#   scripts/fuzz.sh                          # every target, 10^6 executions each
#   RUNS=10000000 scripts/fuzz.sh scene_struct   # one target, the figure docs/fuzzing.md reports
#   TIME=30 scripts/fuzz.sh                  # every target for 30 s each (CI: scripts/test.sh)
#   scripts/fuzz.sh --plant hysteresis       # build a planted panic in; fail unless it is found
#   scripts/fuzz.sh --plant lines --seed 3 scene_file
#
# Targets (fuzz/fuzz_targets/, bodies in saw_link::testing so the corpus replay runs the same
# code on stable): `link_bytes` — the host link's line through the frame receiver, or one
# frame's header and body into the decoder and the board's session over the real core;
# `scene_file` — a scene file's bytes through the reader and the board check, an accepted one
# written back and read again; `scene_struct` — the same reading of scene files built from the
# fuzzer's bytes as choices (tables, keys, array lengths, values), so the mutator changes a
# scene's shape rather than its characters. The experiment's inputs, bodies in
# saw_experiment::testing: `protocol` — a protocol file through the reader, an accepted one run
# by the runner (every trial answered, values it does not allow refused, half of it resumed);
# `analysis_csv` — a session or lab CSV through the analysis' reader and the analysis;
# `session_log` — a session log reopened as a resume does, its CSV read back and its protocol
# resumed. The plane's (issue #36), bodies in fuzz/bodies/plane.rs (included by path by the
# targets and by tests/tests/fuzz_corpus_2d.rs): `scene_file_2d` — a 2D scene file through the
# 2D reader and the board check, an accepted one written back and read again; `controller2d` —
# Controller2d over postcard-decoded configurations and arbitrary readings, frames, ticks and
# reloads, on-times against the caps and the line off on lifts and faults; `link_bytes_2d` —
# link_bytes' two doors into a 2D board's session over a real Controller2d, refusals changing
# nothing. New inputs that reach new code are kept in fuzz/corpus/<target>/ (or in $NEW_INPUTS
# when set, leaving the corpus as it is), which `cargo test -p saw-link --test fuzz_corpus`,
# `cargo test -p saw-experiment --test fuzz_corpus` and `cargo test -p saw-tests --test
# fuzz_corpus_2d` replay. A crash leaves its input in
# fuzz/artifacts/<target>/ and fails the script.
#
# --plant NAME builds saw-core's `fuzz-plant-NAME` panic into the reader (docs/fuzzing.md) and
# fuzzes one target (scene_struct unless named) from an empty corpus (scene_file: the shipped
# scenes) for at most $TIME seconds (60 unless set); it passes only when the fuzzer stops on
# that panic, and prints how long it took.
#
# Toolchain: Debian's rustc (/usr/bin/rustc, RUSTC_BOOTSTRAP=1 for cargo-fuzz's -Z flags) with
# `--sanitizer none`: libFuzzer's coverage is LLVM's sancov pass, which needs no sanitizer
# runtime, and every target is safe Rust, where a panic is the failure to find. SANITIZER=address
# uses the rustup nightly instead (it ships the ASan runtime).
set -euo pipefail
cd "$(dirname "$0")/../fuzz"

PLANT=""
SEED=""
TARGETS=()
while [ $# -gt 0 ]; do
    case "$1" in
        --plant) PLANT=${2:?--plant needs a name: hysteresis or lines}; shift 2 ;;
        --seed) SEED=${2:?--seed needs a number}; shift 2 ;;
        -*) echo "fuzz: unknown option $1" >&2; exit 2 ;;
        *) TARGETS+=("$1"); shift ;;
    esac
done
case "$PLANT" in ''|hysteresis|lines) ;; *) echo "fuzz: no plant '$PLANT' (hysteresis, lines)" >&2; exit 2 ;; esac

whole() { case "$2" in ''|*[!0-9]*) echo "$1: '$2' is not a whole number" >&2; exit 2 ;; esac; }
RUNS=${RUNS:-1000000}
whole RUNS "$RUNS"
[ -n "${TIME:-}" ] && whole TIME "$TIME"
[ -n "$SEED" ] && whole --seed "$SEED"

SANITIZER=${SANITIZER:-none}
if [ "$SANITIZER" = none ]; then
    # cargo-fuzz runs `cargo` from PATH: /usr/bin first so that it is Debian's too.
    CARGO=(env PATH="/usr/bin:$PATH" RUSTC=/usr/bin/rustc RUSTC_BOOTSTRAP=1 /usr/bin/cargo)
else
    if ! cargo +nightly --version >/dev/null 2>&1; then
        echo "fuzz: SANITIZER=$SANITIZER needs a nightly toolchain (rustup toolchain install nightly)" >&2
        exit 1
    fi
    CARGO=(cargo +nightly)
fi
if ! "${CARGO[@]}" fuzz --version >/dev/null 2>&1; then
    "${CARGO[@]}" install cargo-fuzz --locked
fi

FEATURES=()
[ -n "$PLANT" ] && FEATURES=(--features "plant-$PLANT")
mkdir -p ../target
build_start=$(date +%s)
"${CARGO[@]}" fuzz build -O --sanitizer "$SANITIZER" "${FEATURES[@]}" >../target/fuzz-build.log 2>&1 || {
    tail -n 30 ../target/fuzz-build.log >&2
    echo "fuzz: build failed (log: target/fuzz-build.log)" >&2
    exit 1
}
echo "fuzz: built every target in $(( $(date +%s) - build_start )) s (sanitizer $SANITIZER${PLANT:+, plant $PLANT})"

# libFuzzer's options for one run of target $1.
options() {
    local t=$1
    OPTS=(-max_len=4096 -print_final_stats=1)
    [ -f "$t.dict" ] && OPTS+=("-dict=$t.dict")
    [ -n "$SEED" ] && OPTS+=("-seed=$SEED")
    return 0
}

if [ -n "$PLANT" ]; then
    t=${TARGETS[0]:-scene_struct}
    limit=${TIME:-60}
    work=$(mktemp -d)
    trap 'rm -rf "$work"' EXIT
    mkdir -p "$work/corpus" "$work/crash"
    # A fresh corpus: the kept one was grown without the plant and may already hold an input
    # that sets it off, which would show nothing about finding it.
    [ "$t" = scene_file ] && cp ../scenes/*.toml "$work/corpus/"
    options "$t"
    log="../target/fuzz-plant-$PLANT-$t.log"
    echo "== fuzz: plant $PLANT, target $t, at most $limit s"
    start=$(date +%s%N)
    set +e
    "${CARGO[@]}" fuzz run -O --sanitizer "$SANITIZER" "${FEATURES[@]}" "$t" "$work/corpus" -- \
        "${OPTS[@]}" -max_total_time="$limit" -artifact_prefix="$work/crash/" >"$log" 2>&1
    rc=$?
    set -e
    ms=$(( ($(date +%s%N) - start) / 1000000 ))
    execs=$(grep -oE 'number_of_executed_units: [0-9]+' "$log" | grep -oE '[0-9]+$' || echo '?')
    # The plant's own panic, not another: an index out of bounds in the reader's sections.
    if [ "$rc" -ne 0 ] && grep -q 'index out of bounds' "$log" && grep -q 'core/src/scene_file/sections.rs' "$log"; then
        echo "fuzz: plant $PLANT found by $t in $ms ms, $execs executions (log: target/fuzz-plant-$PLANT-$t.log)"
        grep -m1 -A1 'panicked at' "$log" || true
        exit 0
    fi
    grep -E 'panicked at|ERROR' "$log" >&2 || true
    echo "fuzz: plant $PLANT NOT found by $t in $limit s ($execs executions, exit $rc; log: target/fuzz-plant-$PLANT-$t.log)" >&2
    exit 1
fi

[ "${#TARGETS[@]}" -eq 0 ] && TARGETS=(link_bytes scene_file scene_struct protocol analysis_csv session_log scene_file_2d controller2d link_bytes_2d)
for t in "${TARGETS[@]}"; do
    mkdir -p "corpus/$t"
    options "$t"
    dirs=("corpus/$t")
    if [ -n "${NEW_INPUTS:-}" ]; then
        # libFuzzer writes new inputs into the first directory only.
        mkdir -p "$NEW_INPUTS/$t"
        dirs=("$NEW_INPUTS/$t" "corpus/$t")
    fi
    if [ -n "${TIME:-}" ]; then
        OPTS+=("-max_total_time=$TIME")
        budget="$TIME s"
    else
        OPTS+=("-runs=$RUNS")
        budget="$RUNS executions"
    fi
    echo "== fuzz: $t, $budget"
    start=$(date +%s)
    log="../target/fuzz-$t.log"
    set +e
    "${CARGO[@]}" fuzz run -O --sanitizer "$SANITIZER" "$t" "${dirs[@]}" -- "${OPTS[@]}" >"$log" 2>&1
    rc=$?
    set -e
    grep -E "^(Done|stat::number_of_executed_units)|panicked at|ERROR" "$log" || true
    echo "fuzz: $t: $(grep -o 'Done [0-9]* runs' "$log" || echo 'stopped early'), $(( $(date +%s) - start )) s, exit $rc (log: target/fuzz-$t.log)"
    if [ "$rc" -ne 0 ]; then
        echo "fuzz: $t failed: the input is in fuzz/artifacts/$t/; replay it with scripts/fuzz.sh's toolchain: cargo fuzz run --sanitizer $SANITIZER $t fuzz/artifacts/$t/<file>" >&2
        exit 1
    fi
done
