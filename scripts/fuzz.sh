#!/usr/bin/env bash
# Long fuzz run (issue 19): the Rust property targets and the Python hypothesis targets
# with large budgets; prints the inputs tried per target and any failure found.
#   scripts/fuzz.sh [CASES]     (default 20000 per Rust target, CASES/10 per Python target)
set -euo pipefail
cd "$(dirname "$0")/.."
CASES="${1:-20000}"
echo "== Rust (proptest): ${CASES} cases per target"
PROPTEST_CASES="$CASES" cargo test --release -p popup-core --test issue_19_fuzz -- --nocapture 2>&1 | tail -n 12
echo "== Python (hypothesis): $((CASES / 10)) examples per target"
POPUP_FUZZ_EXAMPLES="$((CASES / 10))" python -m pytest -m slow tests/test_fuzz_runs.py tests/test_fuzz_api.py \
  -p no:cacheprovider --hypothesis-show-statistics 2>&1 | grep -E "::|passing|failing|passed|failed|Error" || true
