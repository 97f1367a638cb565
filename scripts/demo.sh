#!/usr/bin/env bash
# Set up ./.venv and run the demo: report the backend and check the kernels against NumPy, then run the
# small sand-drop scene (examples/sand_drop_small.toml), writing ParaView files, PLY particles, PNG previews,
# diagnostics and a checkpoint into runs/sand_drop.
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" ""
cd "$ROOT"
couplekit info --selfcheck
couplekit run examples/sand_drop_small.toml --out runs/sand_drop "$@"
echo "== outputs in runs/sand_drop: open runs/sand_drop/particles.pvd in ParaView; previews: runs/sand_drop/preview_*.png"
