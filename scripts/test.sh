#!/usr/bin/env bash
# Set up ./.venv with the test extra and run the test suite (long validations marked `slow` are left to
# the benchmarks; pass -m slow to run them). Extra arguments go to pytest. The tests run on every core
# (pytest-xdist, -n auto; give -n 0 for one process), each process on one OpenMP thread unless
# OMP_NUM_THREADS says otherwise.
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "test"
cd "$ROOT"
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
python -m pytest -m "not slow" -n auto "$@"
