#!/usr/bin/env bash
# Coverage-guided fuzzing (issue #16) of every decoder that takes bytes from outside, with
# cargo-fuzz (libFuzzer, AddressSanitizer) on the nightly toolchain:
#
#   scripts/fuzz.sh                    # both targets, 10^6 executions each
#   RUNS=10000000 scripts/fuzz.sh      # the figure docs/fuzzing.md reports
#   scripts/fuzz.sh scene_file         # one target
#
# Targets (fuzz/fuzz_targets/, bodies in saw_link::testing so the corpus replay runs the same
# code on stable): `link_bytes` — the host link's line through the frame receiver, or one
# frame's header and body into the decoder and the board's session over the real core;
# `scene_file` — a scene file through the reader and the board check, an accepted one written
# back and read again. New inputs that reach new code are kept in fuzz/corpus/<target>/, which
# `cargo test -p saw-link --test fuzz_corpus` replays. A crash leaves its input in
# fuzz/artifacts/<target>/ and fails the script.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
RUNS=${RUNS:-1000000}
case "$RUNS" in ''|*[!0-9]*) echo "RUNS: '$RUNS' is not a whole number of executions" >&2; exit 2 ;; esac
TARGETS=("$@")
[ "${#TARGETS[@]}" -eq 0 ] && TARGETS=(link_bytes scene_file)
if ! cargo +nightly --version >/dev/null 2>&1; then
    echo "fuzz: needs a nightly toolchain (rustup toolchain install nightly)" >&2; exit 1
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --locked
fi
for t in "${TARGETS[@]}"; do
    mkdir -p "corpus/$t"
    echo "== fuzz: $t, $RUNS executions"
    start=$(date +%s)
    log="../target/fuzz-$t.log"
    mkdir -p ../target
    set +e
    dict=()
    [ -f "$t.dict" ] && dict=(-dict="$t.dict")
    cargo +nightly fuzz run -O "$t" "corpus/$t" -- -runs="$RUNS" -max_len=4096 -print_final_stats=1 "${dict[@]}" > "$log" 2>&1
    rc=$?
    set -e
    grep -E "^(Done|stat::number_of_executed_units)|panicked at|ERROR" "$log" || true
    echo "fuzz: $t: $(grep -o 'Done [0-9]* runs' "$log" || echo 'stopped early'), $(( $(date +%s) - start )) s, exit $rc (log: target/fuzz-$t.log)"
    if [ "$rc" -ne 0 ]; then
        echo "fuzz: $t failed: the input is in fuzz/artifacts/$t/; replay it with cargo fuzz run $t fuzz/artifacts/$t/<file>" >&2
        exit 1
    fi
done
