#!/usr/bin/env bash
# The GPU check: everything couplekit can only show on a machine with a CUDA GPU, in one time-bounded run
# (< 9 minutes on an H100 / H200), its results as files in one folder.
#
#   scripts/gpu_check.sh [--out DIR] [--dry-run]
#
# (the nvcc build checks need no GPU: tests/test_kernel_builds.py, benchmarks/kernel_build_report.py)
# Steps (each under its own time limit, `timeout`):
#   info        couplekit info --selfcheck --backend cuda        (NVRTC builds, self-check vs NumPy)
#   kernels     the kernel-vs-reference tests with COUPLEKIT_TEST_BACKEND=cuda (tests/conftest.py)
#   solvers     the solver- and simulation-vs-reference tests on the cuda backend
#               (tests/test_solvers_on_backend.py, tests/test_simulation_on_backend.py: every scheduler, emission)
#   memcheck    compute-sanitizer memcheck over a few steps of the small scenes (scripts/gpu_memcheck.py)
#   throughput  fluid at 256^3 cells, sand at 1, 4, 16 M particles (benchmarks/gpu_throughput.py)
#   fig13       couplekit run examples/fig13_sand_drop_beaker_small.toml --backend cuda (the outputs that need
#               PyVista are switched off with --set where it is not installed)
# Before the steps: couplekit is installed editable (pip, no network) where the Python that runs it cannot
# import couplekit.schedulers (a bare checkout: kernels/ and schedulers/ are mapped into the package by setup.py);
# nvidia-smi's view of the GPU goes to gpu.log.
# Results: DIR (default gpu_check_results/<UTC date-time>/): <step>.log per step, the tests' JUnit XML,
# gpu_throughput.json, fig13/ (the run's output), summary.json (every step's status, seconds, limit).
# Exit status: 0 when every step passed, 1 when one failed or ran out of time, 2 for a usage error.
# --dry-run prints the steps (commands and limits) and runs nothing.
set -u

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${PYTHON:-python}"
OUT=""
DRY=0
while [ $# -gt 0 ]; do
    case "$1" in
        --out) OUT="${2:?--out needs a folder}"; shift 2 ;;
        --dry-run) DRY=1; shift ;;
        -h|--help) sed -n '2,20p' "$0"; exit 0 ;;
        *) echo "gpu_check.sh: unknown argument '$1' (use --out DIR, --dry-run)" >&2; exit 2 ;;
    esac
done
[ -n "$OUT" ] || OUT="$ROOT/gpu_check_results/$(date -u +%Y%m%d-%H%M%S)"

# every test file with kernel-vs-reference tests on the kernel_backend fixture (tests/conftest.py: on cuda the
# tests' NumPy states are copied to the device and back around each launch)
KERNEL_TESTS="tests/fluid/test_lbm_kernels.py tests/fluid/test_phasefield_kernels.py tests/fluid/test_filter_wall_rule.py tests/fluid/test_fp16_storage.py tests/fluid/test_odd_ramp.py::test_collide_stream_with_ramp_matches_reference tests/fluid/test_odd_ramp.py::test_ramp_weights_need_their_build tests/sand/test_kernels_vs_reference.py tests/sand/test_g2p_batched.py tests/sand/test_svd.py tests/coupling/test_coupling_kernels.py"
SOLVER_TESTS="tests/test_solvers_on_backend.py tests/test_simulation_on_backend.py"
# without PyVista (a GPU image may lack VTK) the run writes what needs no PyVista: diagnostics, PLY, checkpoints
NO_PYVISTA="--set outputs.vtk=false --set outputs.surface=false --set outputs.preview=false"
# 4 test processes where pytest-xdist is installed: NVRTC builds of the kernel variants take most of the time
PYTEST="$PY -m pytest -q -rs -p no:cacheprovider \$($PY -c 'import xdist' 2>/dev/null && echo '-n 4')"

# name|limit in seconds|command (run from the repository root); limits sum to 510 s < 9 minutes
STEPS=(
    "info|60|$PY -m couplekit info --selfcheck --backend cuda"
    "kernels|120|COUPLEKIT_TEST_BACKEND=cuda $PYTEST $KERNEL_TESTS --junitxml=\"\$OUT/kernels.xml\""
    "solvers|90|COUPLEKIT_TEST_BACKEND=cuda $PYTEST $SOLVER_TESTS --junitxml=\"\$OUT/solvers.xml\""
    "memcheck|60|compute-sanitizer --tool memcheck --error-exitcode 9 $PY scripts/gpu_memcheck.py"
    "throughput|120|$PY benchmarks/gpu_throughput.py --cells 256 --particles 1 4 16 --out \"\$OUT/gpu_throughput.json\""
    "fig13|60|$PY -m couplekit run examples/fig13_sand_drop_beaker_small.toml --backend cuda --out \"\$OUT/fig13\" --no-progress \$($PY -c 'import pyvista' 2>/dev/null || echo \"$NO_PYVISTA\")"
)

if [ "$DRY" = 1 ]; then
    echo "gpu_check.sh --dry-run: results would go to $OUT"
    for s in "${STEPS[@]}"; do
        IFS='|' read -r name limit cmd <<<"$s"
        printf 'step %-10s limit %4ss: %s\n' "$name" "$limit" "$cmd"
    done
    exit 0
fi

mkdir -p "$OUT" || { echo "gpu_check.sh: cannot create $OUT" >&2; exit 2; }
cd "$ROOT" || exit 2
export OUT
{ nvidia-smi; nvidia-smi -q -d CLOCK,MEMORY; } >"$OUT/gpu.log" 2>&1
if ! "$PY" -c 'import couplekit.schedulers, couplekit.kernels' 2>/dev/null; then
    echo "== installing couplekit (editable, no network) into $("$PY" -c 'import sys; print(sys.prefix)')"
    "$PY" -m pip install -q --no-deps --no-build-isolation --no-index -e "$ROOT" >"$OUT/install.log" 2>&1 \
        || { echo "gpu_check.sh: installing couplekit failed (log $OUT/install.log)" >&2; tail -n 20 "$OUT/install.log" >&2; exit 1; }
fi
failed=0
json="["
for s in "${STEPS[@]}"; do
    IFS='|' read -r name limit cmd <<<"$s"
    echo "== $name (limit ${limit} s): $cmd"
    t0=$(date +%s)
    timeout --kill-after=10 "$limit" bash -c "$cmd" >"$OUT/$name.log" 2>&1
    rc=$?
    dt=$(( $(date +%s) - t0 ))
    if [ "$rc" = 0 ]; then status=passed
    elif [ "$rc" = 124 ] || [ "$rc" = 137 ]; then status=timed_out; failed=1
    else status=failed; failed=1
    fi
    echo "   $status in ${dt} s (exit $rc); log $OUT/$name.log"
    [ "$status" = passed ] || tail -n 15 "$OUT/$name.log" | sed 's/^/   | /'
    json="$json{\"step\": \"$name\", \"status\": \"$status\", \"exit\": $rc, \"seconds\": $dt, \"limit_s\": $limit, \"log\": \"$name.log\"},"
done
json="${json%,}]"
printf '{"date_utc": "%s", "host": "%s", "passed": %s, "steps": %s}\n' "$(date -u +%FT%TZ)" "$(hostname)" \
    "$([ $failed = 0 ] && echo true || echo false)" "$json" >"$OUT/summary.json"
echo "== summary ($OUT/summary.json)"
grep -o '"step": "[a-z0-9]*", "status": "[a-z_]*"' "$OUT/summary.json" | sed 's/"step": //; s/, "status": / /; s/"//g; s/^/   /'
exit $failed
