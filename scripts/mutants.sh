#!/usr/bin/env bash
# Mutation testing of the portable core and the board definitions with cargo-mutants: each
# plausible one-line bug in core/src or boards/src, then the whole workspace test suite; a mutant
# the suite does not catch "survives". The full run is not part of CI (about 1 640 mutants, a
# few hours on 2 cores); CI runs scripts/mutants-ci.sh on the lines a change touches. See
# docs/mutants.md for the results and the reasons survivors are left.
#
#   scripts/mutants.sh                                   # every mutant in core/ and boards/
#   scripts/mutants.sh --file core/src/gate.rs           # one file (any cargo-mutants flags pass through)
#   scripts/mutants.sh --in-diff <(git diff origin/main) # only lines a change touches
#
# Installs cargo-mutants (crates.io) when missing. Results in mutants.out/.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! cargo mutants --version >/dev/null 2>&1; then
    cargo install cargo-mutants --locked
fi
# Mutants come from core/ and boards/; the tests are every package's (with `-p`, cargo-mutants
# would test only the mutated package) but the `saw` command's, whose end-to-end tests drive the
# virtual board in real time and exercise the link, not the core.
TESTS=(--test-package saw-core --test-package saw-boards --test-package saw-link
       --test-package saw-store --test-package host-sim --test-package saw-tests)
case " $* " in
    *" --file "*|*" -f "*|*" --in-diff "*|*" -D "*) exec cargo mutants "${TESTS[@]}" --gitignore true "$@" ;;
    *) exec cargo mutants "${TESTS[@]}" --gitignore true --file 'core/src/**/*.rs' --file 'boards/src/*.rs' "$@" ;;
esac
