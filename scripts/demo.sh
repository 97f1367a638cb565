#!/usr/bin/env bash
# Set up ./.venv and run the demo: report the backend and check the kernels against NumPy, then run the
# small sand-drop scene (examples/sand_drop_small.toml), writing ParaView files, PLY particles, PNG previews,
# diagnostics and a checkpoint into runs/sand_drop (replacing the outputs of an earlier demo run). The sweep extra
# (Dask, pyarrow) is installed too, so `couplekit sweep` works after the demo.
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "sweep"
cd "$ROOT"
couplekit info --selfcheck
couplekit run examples/sand_drop_small.toml --out runs/sand_drop --overwrite "$@"
echo "== outputs in runs/sand_drop: open runs/sand_drop/particles.pvd in ParaView; previews: runs/sand_drop/preview_*.png"
