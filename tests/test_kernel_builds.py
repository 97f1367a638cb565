"""Every kernel source builds for the GPU: nvcc for sm_80 and sm_90 without register spills, and NVRTC with
exactly the options the cuda backend passes. No GPU is needed for either."""

from __future__ import annotations

import pytest

from couplekit.backend.cuda import nvrtc_compile, nvrtc_options
from couplekit.backend.nvcc import build_variants, kernel_sources, nvcc_build, nvcc_path

SOURCES = kernel_sources()
CASES = [(src, variant) for src in SOURCES for variant in build_variants(src)]
IDS = [f"{src.name}{''.join(f'-{k}={v}' for k, v in variant.items())}" for src, variant in CASES]


def test_there_are_kernels():
    assert any(p.name == "selfcheck.cu" for p in SOURCES)


ARCHS = ["sm_80", "sm_90"]


@pytest.mark.parametrize("source, defines", CASES, ids=IDS)
def test_nvcc_builds_without_spills(source, defines):
    if nvcc_path() is None:
        pytest.skip("nvcc is not on the PATH: the sm_80/sm_90 build check cannot run on this machine")
    report = nvcc_build(source, ARCHS, defines)  # one nvcc call, ptxas reports each architecture
    for arch in ARCHS:
        assert report[arch], f"ptxas reported no kernels for {source.name} on {arch}"
        spills = {k: v for k, v in report[arch].items() if v.get("spill_store_bytes") or v.get("spill_load_bytes")}
        assert not spills, f"{source.name} spills registers on {arch}: {spills}"


@pytest.mark.parametrize("source, defines", CASES, ids=IDS)
def test_nvrtc_compiles_with_backend_options(source, defines):
    pytest.importorskip("cupy", reason="CuPy (couplekit[test]) provides the NVRTC binding")
    ptx = nvrtc_compile(source.name, defines, arch="80")
    # every kernel named in the source is an entry point of the PTX
    from couplekit.backend.signature import parse_kernels

    for name in parse_kernels(source.read_text(), source.name):
        assert f".entry {name}(" in ptx or f".entry {name} (" in ptx, f"{name} missing from the PTX"


def test_nvrtc_options_carry_defines():
    opts = nvrtc_options({"CK_B": 0, "CK_A": True})
    assert opts[-2:] == ("-DCK_A=1", "-DCK_B=0")  # sorted, bools as 0/1: one cache key per flag set
    assert "--std=c++17" in opts
