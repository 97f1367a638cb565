#!/usr/bin/env bash
# The GPU check: everything couplekit can only show on a machine with a CUDA GPU, in one time-bounded run
# (< 8 minutes on an H100 / H200), its results as files in one folder.
#
#   scripts/gpu_check.sh [--out DIR] [--dry-run]
#
# (the nvcc build checks need no GPU: tests/test_kernel_builds.py, benchmarks/kernel_build_report.py)
# Steps (each under its own time limit, `timeout`):
#   info        couplekit info --selfcheck --backend cuda        (NVRTC builds, self-check vs NumPy)
#   kernels     the kernel-vs-reference tests with COUPLEKIT_TEST_BACKEND=cuda (tests/conftest.py)
#   solvers     the solver-vs-reference tests on the cuda backend (tests/test_solvers_on_backend.py)
#   throughput  fluid at 256^3 cells, sand at 1, 4, 16 M particles (benchmarks/gpu_throughput.py)
#   fig13       couplekit run examples/fig13_sand_drop_beaker_small.toml --backend cuda
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

KERNEL_TESTS="tests/fluid/test_lbm_kernels.py tests/fluid/test_phasefield_kernels.py tests/sand/test_kernels_vs_reference.py tests/sand/test_g2p_batched.py tests/sand/test_svd.py tests/coupling/test_coupling_kernels.py"
SOLVER_TESTS="tests/test_solvers_on_backend.py"

# name|limit in seconds|command (run from the repository root); limits sum to 450 s < 8 minutes
STEPS=(
    "info|60|$PY -m couplekit info --selfcheck --backend cuda"
    "kernels|120|COUPLEKIT_TEST_BACKEND=cuda $PY -m pytest -q -p no:cacheprovider $KERNEL_TESTS --junitxml=\"\$OUT/kernels.xml\""
    "solvers|60|COUPLEKIT_TEST_BACKEND=cuda $PY -m pytest -q -p no:cacheprovider $SOLVER_TESTS --junitxml=\"\$OUT/solvers.xml\""
    "throughput|150|$PY benchmarks/gpu_throughput.py --cells 256 --particles 1 4 16 --out \"\$OUT/gpu_throughput.json\""
    "fig13|60|$PY -m couplekit run examples/fig13_sand_drop_beaker_small.toml --backend cuda --out \"\$OUT/fig13\""
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
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"
export OUT
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
