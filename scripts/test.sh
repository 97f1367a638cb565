#!/usr/bin/env bash
# Set up ./.venv with the test extra and run the test suite (long validations marked `slow` are left to
# the benchmarks; pass -m slow to run them). Extra arguments go to pytest.
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "test"
cd "$ROOT"
python -m pytest -m "not slow" "$@"
