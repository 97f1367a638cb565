#!/usr/bin/env bash
# Set up ./.venv and run the demo: report the backend and tools, build the kernels for this machine and
# check them against NumPy.
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" ""
cd "$ROOT"
couplekit info --selfcheck
