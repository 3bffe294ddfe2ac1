#!/usr/bin/env bash
# The tests kept out of CI (`@pytest.mark.slow`): every effect against the whole library,
# pairs, the swap and screen steps, the disturbance on MuJoCo's data, the fuzz budgets.
# About 1 hour of CPU; prints each test's time.
#   bash benchmarks/slow_tests.sh            # all slow tests, one worker per core
#   bash benchmarks/slow_tests.sh -k backlash  # extra pytest arguments
set -euo pipefail
cd "$(dirname "$0")/.."
export MPLBACKEND=Agg
python -m pytest -m slow -n auto --dist loadfile -p no:cacheprovider --durations=0 -q "$@"
