"""Real kernels on the cpu backend against NumPy, the kernel cache, and argument checking."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from couplekit.backend import KernelArgumentError, KernelBuildError
from couplekit.backend.host import HostModule
from couplekit.backend.sources import kernel_dir
from couplekit.selfcheck import reference_scatter, reference_stencil27, reference_sum, run_selfcheck


def test_selfcheck_cpu_matches_numpy(cpu_backend):
    # tolerances and their reasons are in run_selfcheck's docstring: float64 reduction 1e-12,
    # float32 atomic scatter of ~200 terms/target 1e-5, 27-term float32 stencil 2e-6
    results = run_selfcheck(cpu_backend)
    assert [r.name for r in results if not r.ok] == [], results


@pytest.mark.parametrize("n", [0, 1, 31, 1000, 100_003])
def test_reduction_sizes(cpu_backend, n):
    rng = np.random.default_rng(n)
    x = rng.standard_normal(n).astype(np.float32)
    out = np.array([1.5])  # the kernel adds to what is there
    cpu_backend.module("selfcheck.cu").function("sum_reduce")(n, x, out)
    # float64 accumulation of float32 data: only the order of additions differs from NumPy's
    assert out[0] == pytest.approx(1.5 + reference_sum(x), rel=1e-12, abs=1e-9)


def test_reduction_is_bitwise_reproducible(cpu_backend):
    x = np.random.default_rng(1).standard_normal(500_001).astype(np.float32)
    fn = cpu_backend.module("selfcheck.cu").function("sum_reduce")
    sums = []
    for _ in range(5):
        out = np.zeros(1)
        fn(x.size, x, out)
        sums.append(out[0])
    assert len(set(sums)) == 1, sums


def test_scatter_with_collisions(cpu_backend):
    rng = np.random.default_rng(2)
    idx = rng.integers(0, 7, 50_000).astype(np.int32)  # ~7000 hits per target: heavy contention
    val = rng.random(50_000, dtype=np.float32)
    out = np.zeros(7, dtype=np.float32)
    cpu_backend.module("selfcheck.cu").function("scatter_add")(idx.size, idx, val, out, 2.0)
    # float32 accumulation of ~7000 positive terms: relative error bound ~ 7000 * 6e-8 = 4e-4
    np.testing.assert_allclose(out, reference_scatter(idx, val, 7, 2.0), rtol=4e-4)


@pytest.mark.parametrize("shape", [(3, 3, 3), (5, 7, 11), (16, 16, 16)])
def test_periodic_stencil_shapes(cpu_backend, shape):
    field = np.random.default_rng(3).random(shape, dtype=np.float32)
    out = np.empty_like(field)
    nz, ny, nx = shape
    cpu_backend.module("selfcheck.cu").function("stencil27_periodic")(field.size, field, out, nx, ny, nz)
    # 27 float32 products of values in [0, 1): absolute error <= 27 * 6e-8
    np.testing.assert_allclose(out, reference_stencil27(field), atol=2e-6)


def test_stencil_keeps_constant_field(cpu_backend):
    field = np.full((4, 5, 6), 3.0, dtype=np.float32)
    out = np.zeros_like(field)
    cpu_backend.module("selfcheck.cu").function("stencil27_periodic")(field.size, field, out, 6, 5, 4)
    np.testing.assert_allclose(out, 3.0, rtol=1e-6)  # weights sum to 1 (float32 rounding of 27 weights)


# ------------------------------------------------------------------------------------------- cache


def _copy_kernel(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for name in ("selfcheck.cu", "common.cuh"):
        shutil.copy(kernel_dir() / name, src / name)
    return src


def test_second_build_is_cache_hit(private_cache, tmp_path):
    src = _copy_kernel(tmp_path)
    first = HostModule(str(src / "selfcheck.cu"))
    second = HostModule(str(src / "selfcheck.cu"))
    assert not first.build.cached and second.build.cached
    assert first.build.library == second.build.library
    assert len(list(private_cache.glob("*.so"))) == 1
    assert not list(private_cache.glob("*.tmp"))  # no temporary left behind


def test_editing_an_included_header_rebuilds(private_cache, tmp_path):
    src = _copy_kernel(tmp_path)
    first = HostModule(str(src / "selfcheck.cu"))
    with open(src / "common.cuh", "a") as fh:
        fh.write("\n// an edit that changes nothing but the text\n")
    second = HostModule(str(src / "selfcheck.cu"))
    assert not second.build.cached
    assert second.build.library != first.build.library


def test_defines_are_separate_cache_entries(private_cache, tmp_path):
    src = _copy_kernel(tmp_path)
    a = HostModule(str(src / "selfcheck.cu"), {"CK_TEST_FLAG": 1})
    b = HostModule(str(src / "selfcheck.cu"), {"CK_TEST_FLAG": 2})
    assert a.build.library != b.build.library
    assert "-DCK_TEST_FLAG=1" in a.build.command


def test_failed_build_shows_command_and_message(private_cache, tmp_path):
    src = _copy_kernel(tmp_path)
    bad = src / "broken.cu"
    bad.write_text(
        '#include "common.cuh"\nKERNEL void k(const long long n, float* x) { FOR_EACH(i, n) { x[i] = y; } }\n'
    )
    with pytest.raises(KernelBuildError) as info:
        HostModule(str(bad))
    msg = str(info.value)
    assert "command:" in msg and "broken.cu" in msg
    assert "error" in msg and "x[i] = y" in msg  # the compiler's own diagnostic, with the offending line
    assert not list(private_cache.glob("*.so"))


# ---------------------------------------------------------------------------------- argument checks


@pytest.fixture(scope="module")
def scatter(cpu_backend):
    return cpu_backend.module("selfcheck.cu").function("scatter_add")


def _good():
    return np.zeros(4, np.int32), np.ones(4, np.float32), np.zeros(4, np.float32)


def test_good_call_works(scatter):
    idx, val, out = _good()
    scatter(4, idx, val, out, 1.0)
    assert out[0] == 4.0


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda a: (a[0].astype(np.int64), a[1], a[2], 1.0), "must have dtype int32"),
        (lambda a: (a[0], a[1].astype(np.float64), a[2], 1.0), "must have dtype float32"),
        (lambda a: (a[0], a[1], np.zeros(8, np.float32)[::2], 1.0), "C-contiguous"),
        (lambda a: (a[0], a[1], a[2]), "takes n and 4 more arguments, got 3"),
        (lambda a: (a[0], a[1], a[2], 1.0, 2.0), "takes n and 4 more arguments, got 5"),
        (lambda a: (a[0], a[1], a[2], np.float64(1.0)), "must be a float32 scalar"),
        (lambda a: (a[0], a[1], a[2], "1.0"), "must be a number"),
        (lambda a: (list(a[0]), a[1], a[2], 1.0), "must be a numpy.ndarray"),
    ],
)
def test_bad_arguments_are_refused(scatter, mutate, message):
    with pytest.raises(KernelArgumentError, match=message):
        scatter(4, *mutate(_good()))


def test_read_only_output_refused(scatter):
    idx, val, out = _good()
    out.flags.writeable = False
    with pytest.raises(KernelArgumentError, match="written by the kernel"):
        scatter(4, idx, val, out, 1.0)


def test_float_for_int_parameter_refused(cpu_backend):
    fn = cpu_backend.module("selfcheck.cu").function("stencil27_periodic")
    a = np.zeros((2, 2, 2), np.float32)
    with pytest.raises(KernelArgumentError, match="integer parameter"):
        fn(8, a, a.copy(), 2.0, 2, 2)


def test_unknown_kernel_lists_available(cpu_backend):
    with pytest.raises(KeyError, match="sum_reduce"):
        cpu_backend.module("selfcheck.cu").function("nope")


def test_unknown_source_lists_available(cpu_backend):
    with pytest.raises(FileNotFoundError, match="selfcheck.cu"):
        cpu_backend.module("nope.cu")


def test_wrong_size_refused(scatter, cpu_backend):
    idx, val, out = _good()
    with pytest.raises(KernelArgumentError, match="has 4 elements; the kernel needs == n = 5"):
        scatter(5, idx, val, out, 1.0)
    stencil = cpu_backend.module("selfcheck.cu").function("stencil27_periodic")
    a = np.zeros((2, 3, 4), np.float32)
    with pytest.raises(KernelArgumentError, match="nx \\* ny \\* nz = 30"):
        stencil(24, a, a.copy(), 5, 3, 2)  # nx given as 5 for an x extent of 4


def test_signature_parser():
    from couplekit.backend.signature import parse_kernels

    src = """
    // KERNEL void in_a_comment(const long long n, float* x)
    /* KERNEL void also_a_comment(int x) */
    KERNEL void k(const long long n, const float* RESTRICT a /* size: 3 * (n + 1) */,
                  unsigned char* flags /* size >= nx */, const int nx, double s) {}
    """
    (sig,) = parse_kernels(src).values()
    assert [p.name for p in sig.params] == ["n", "a", "flags", "nx", "s"]
    a, flags = sig.params[1], sig.params[2]
    assert a.const and a.pointer and a.dtype == np.float32 and a.size == "3 * (n + 1)" and not a.size_at_least
    assert not flags.const and flags.dtype == np.uint8 and flags.size_at_least
    with pytest.raises(ValueError, match="first parameter"):
        parse_kernels("KERNEL void k(float* x) {}")
    with pytest.raises(ValueError, match="has type 'short'"):
        parse_kernels("KERNEL void k(const long long n, short x) {}")
    with pytest.raises(ValueError, match="may only use integer parameters"):
        parse_kernels("KERNEL void k(const long long n, float* x /* size: m */) {}")
