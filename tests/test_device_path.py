"""The device-path host build (the cpu-device backend): kernels/common.cuh compiled with -DCK_DEVICE_PATH=1
takes the CUDA code paths (CK_ON_GPU = 1) on the host; the loop and atomic macros keep CUDA's index space.

The kernel-vs-reference tests run on it through the ``kernel_backend`` fixture (tests/conftest.py); these
tests pin the mode itself: which branch is built, the cell-index decoding, the atomics, the cache entry and
the backend choice.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

import couplekit.backend as backend_mod
from couplekit.backend import get_backend
from couplekit.backend.host import HostModule, build_library
from couplekit.backend.sources import kernel_dir

PROBE = r"""
#include "common.cuh"

// out[0] = CK_ON_GPU of this build
KERNEL void probe_on_gpu(const long long n, int* RESTRICT out /* size: 1 */) {
    FOR_EACH(i, n) out[i] = CK_ON_GPU;
}

// visits[c] counts how often cell c is visited; xyz holds the (x, y, z) the loop gave it
KERNEL void probe_cells(const long long n, int* RESTRICT visits, int* RESTRICT xyz /* size: 3 * n */,
                        const int nx, const int ny, const int nz) {
    FOR_EACH_CELL(x, y, z, nx, ny, nz) {
        const long long c = x + (long long)nx * (y + (long long)ny * z);
        atomic_add(&visits[c], 1);
        xyz[c] = x;
        xyz[n + c] = y;
        xyz[2 * n + c] = z;
    }
}

// every item adds into a few shared slots, as a P2G does
KERNEL void probe_scatter(const long long n, const int* RESTRICT slot, float* RESTRICT acc, int* RESTRICT count) {
    FOR_EACH(i, n) {
        atomic_add(&acc[slot[i]], 1.f);
        atomic_add(&count[slot[i]], 1);
    }
}

// sum of 0..n-1 in double
KERNEL void probe_sum(const long long n, double* RESTRICT out /* size: 1 */) {
    REDUCE_SUM_BEGIN(i, n, acc) { acc += (double)i; }
    REDUCE_SUM_END(out, acc)
}
"""


@pytest.fixture(scope="module")
def probe_source(tmp_path_factory):
    """The probe kernels next to a copy of the portability header."""
    d = tmp_path_factory.mktemp("probe")
    shutil.copy(kernel_dir() / "common.cuh", d / "common.cuh")
    src = d / "probe.cu"
    src.write_text(PROBE)
    return src


@pytest.fixture(scope="module", params=[False, True], ids=["host", "device-path"])
def probe(request, probe_source, cpu_backend):
    """The probe module of either build on 2 OpenMP threads (so the atomics race); the process-wide thread
    count is put back afterwards (loading a module with ``threads`` sets it)."""
    before = HostModule(str(probe_source), device_path=request.param).num_threads()
    yield HostModule(str(probe_source), threads=2, device_path=request.param)
    HostModule(str(probe_source), threads=before, device_path=request.param)


def test_device_path_builds_the_cuda_branch(probe):
    out = np.full(1, -1, np.int32)
    probe.function("probe_on_gpu")(1, out)
    assert out[0] == (1 if probe.device_path else 0)


def test_cell_loop_visits_every_cell_once_with_its_coordinates(probe):
    nx, ny, nz = 5, 3, 4  # unequal extents: a swapped axis shows
    n = nx * ny * nz
    visits = np.zeros(n, np.int32)
    xyz = np.full((3, n), -1, np.int32)
    probe.function("probe_cells")(n, visits, xyz, np.int32(nx), np.int32(ny), np.int32(nz))
    assert np.all(visits == 1)
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    np.testing.assert_array_equal(xyz, np.stack([x.ravel(), y.ravel(), z.ravel()]))


def test_atomics_from_many_threads_lose_nothing(probe):
    n = 200_000
    slot = (np.arange(n) % 7).astype(np.int32)
    acc = np.zeros(7, np.float32)
    count = np.zeros(7, np.int32)
    probe.function("probe_scatter")(n, slot, acc, count)
    expected = np.bincount(slot, minlength=7)
    np.testing.assert_array_equal(count, expected)
    np.testing.assert_array_equal(acc, expected.astype(np.float32))  # < 2^24 per slot: exact in float32


def test_reduction_is_exact(probe):
    out = np.zeros(1, np.float64)
    probe.function("probe_sum")(10_001, out)
    assert out[0] == 10_000 * 10_001 / 2


def test_device_path_is_its_own_cache_entry(cpu_backend):
    src = kernel_dir() / "selfcheck.cu"
    host, device = build_library(src), build_library(src, device_path=True)
    assert host.library != device.library
    assert "-DCK_DEVICE_PATH=1" in device.command and "-DCK_DEVICE_PATH=1" not in host.command


def test_device_path_define_is_not_a_user_define(cpu_backend):
    with pytest.raises(ValueError, match="device_path=True"):
        build_library(kernel_dir() / "selfcheck.cu", {"CK_DEVICE_PATH": 1})


def test_cpu_device_backend_is_named_only(monkeypatch, cpu_device):
    assert cpu_device.name == "cpu-device" and cpu_device.has_kernels and cpu_device.gpu_code_paths
    assert cpu_device.xp is np
    assert cpu_device.module("selfcheck.cu").device_path
    assert not get_backend("cpu").gpu_code_paths
    monkeypatch.delenv("COUPLEKIT_BACKEND", raising=False)
    monkeypatch.setattr(backend_mod, "cuda_status", lambda: (False, "no GPU in this test"))
    assert get_backend("auto").name == "cpu"  # auto never picks the device path
    with pytest.raises(ValueError, match="cpu-device"):
        get_backend("gpu")  # the error lists it among the choices


def test_selfcheck_kernels_pass_on_the_device_path(cpu_device):
    from couplekit.selfcheck import run_selfcheck

    results = run_selfcheck(cpu_device)
    assert results and all(r.ok for r in results), [(r.name, r.error) for r in results]
