#!/usr/bin/env bash
# CI's mutation check (issue #10): the mutants of the lines in core/src and boards/src changed
# since the last landing (the commit in .ci/mutants-base, moved forward at each landing), each
# tested against the whole workspace suite. A missed mutant fails CI: add the test that catches
# it, or, when it is equivalent, an exclude_re with its reason in .cargo/mutants.toml.
#
#   scripts/mutants-ci.sh              # what CI runs (scripts/test.sh calls it)
#   MUTANTS_MAX=400 scripts/mutants-ci.sh
#
# MUTANTS_MAX (default 6: 8 took ~10 min of CI's 45 on 2 cores at stop 44, with the rest at 35 min) bounds the
# mutants tested, to keep CI under its budget: a larger change is tested on an evenly spread
# sample of that size, and the script says so (the full run, scripts/mutants.sh, covers the rest).
set -euo pipefail
cd "$(dirname "$0")/.."
max=${MUTANTS_MAX:-6}
case "$max" in
    ''|*[!0-9]*) echo "MUTANTS_MAX: '$max' is not a whole number of mutants (1 or more)" >&2; exit 2 ;;
esac
if [ "$max" -lt 1 ]; then
    echo "MUTANTS_MAX: $max is below 1 mutant" >&2
    exit 2
fi
base=$(tr -d '[:space:]' < .ci/mutants-base)
if ! git cat-file -e "$base^{commit}" 2>/dev/null; then
    echo "mutants: base $base (.ci/mutants-base) is not in this clone's history; testing the last commit's changes instead"
    base=$(git rev-parse HEAD~1 2>/dev/null || true)
    if [ -z "$base" ]; then
        echo "mutants: no earlier commit either; nothing to compare against"
        exit 0
    fi
fi
# Every package's tests but the `saw` command's: its end-to-end tests drive the virtual board in
# real time (seconds each) and exercise the link, not the core's arithmetic, which the core,
# host-sim and scenario tests cover.
TESTS=(--test-package saw-core --test-package saw-boards --test-package saw-link
       --test-package saw-store --test-package host-sim --test-package saw-tests)
mkdir -p target/mutants-ci
diff=target/mutants-ci/core.diff
git diff "$base" -- core/src boards/src > "$diff"
if [ ! -s "$diff" ]; then
    echo "mutants: core/src and boards/src unchanged since $(git rev-parse --short "$base") (the last full run): nothing to test"
    exit 0
fi
if ! cargo mutants --version >/dev/null 2>&1; then
    cargo install cargo-mutants --locked
fi
n=$(cargo mutants "${TESTS[@]}" --in-diff "$diff" --list | wc -l)
shard=()
if [ "$n" -gt "$max" ]; then
    k=$(( (n + max - 1) / max ))
    echo "mutants: $n mutants in the lines changed since $(git rev-parse --short "$base"); testing every ${k}th ($((n / k)) or so, MUTANTS_MAX=$max)"
    shard=(--shard "0/$k" --sharding round-robin)
else
    echo "mutants: $n mutants in the lines changed since $(git rev-parse --short "$base")"
fi
rc=0
# --gitignore true: each of the -j 2 build copies leaves out what git ignores, every nested
# target/ (fuzz/target, firmware/target and board-model/target hold gigabytes after CI's earlier
# steps; copying them filled the CI machine's disk at stop 39).
cargo mutants "${TESTS[@]}" --in-diff "$diff" "${shard[@]}" -j 2 --timeout 120 --gitignore true \
    -o target/mutants-ci || rc=$?
case $rc in
    0) echo "mutants: every mutant caught" ;;
    2) echo "mutants: missed (no test fails on these):"; cat target/mutants-ci/mutants.out/missed.txt; exit 1 ;;
    # A mutant that makes the suite hang (an endless loop) did not pass it.
    3) echo "mutants: caught, some by timeout:"; cat target/mutants-ci/mutants.out/timeout.txt ;;
    *) echo "mutants: cargo-mutants failed (exit $rc)"; exit 1 ;;
esac
