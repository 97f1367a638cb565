"""The cuda backend: kernel sources compiled by NVRTC through ``cupy.RawModule`` and launched by CuPy."""

from __future__ import annotations

import numpy as np

from .errors import KernelBuildError
from .host import define_flags
from .signature import Signature, check_args, parse_kernels
from .sources import expanded_source, kernel_path

BLOCK_SIZE = 256
# enough blocks to fill any current GPU several times over; grid-stride loops cover the rest
MAX_BLOCKS = 65535 * 4

# no --use_fast_math: GPU results should stay close to the host build and the NumPy reference
NVRTC_BASE_OPTIONS = ("--std=c++17", "-DCK_NVRTC=1")


def nvrtc_options(defines: dict | None = None) -> tuple[str, ...]:
    """The exact NVRTC options the cuda backend compiles with (the NVRTC test uses this too)."""
    return (*NVRTC_BASE_OPTIONS, *define_flags(defines))


def nvrtc_source(name: str) -> str:
    """The text NVRTC compiles for kernel source ``name``: local headers pasted in."""
    return expanded_source(kernel_path(name))


# what cupy.RawModule adds to the user's options when it calls NVRTC (CuPy 13/14, compiler.py)
CUPY_ADDED_OPTIONS = ("--device-as-default-execution-space",)


def nvrtc_compile(name: str, defines: dict | None = None, arch: str = "80") -> str:
    """Compile ``name`` to PTX with NVRTC for ``compute_<arch>``; no GPU is needed. Returns the PTX.

    Uses the same source text and options as :class:`CudaModule` (plus those CuPy adds itself), through
    CuPy's NVRTC binding directly: CuPy's own compile helper asks the CUDA runtime for the device's
    architecture, which fails on a machine without a GPU.
    """
    from cupy.cuda import nvrtc

    options = (*nvrtc_options(defines), *CUPY_ADDED_OPTIONS, f"--gpu-architecture=compute_{arch}")
    prog = nvrtc.createProgram(nvrtc_source(name), name, [], [])
    try:
        try:
            nvrtc.compileProgram(prog, list(options))
        except nvrtc.NVRTCError as exc:
            log = nvrtc.getProgramLog(prog)
            raise KernelBuildError(f"NVRTC failed on {name} with options {options}: {exc}\n{log}") from exc
        ptx = nvrtc.getPTX(prog)
    finally:
        nvrtc.destroyProgram(prog)
    return ptx.decode() if isinstance(ptx, bytes) else ptx


class CudaFunction:
    """A kernel of a CUDA module, called as ``fn(n, *args)`` with CuPy arrays and NumPy scalars."""

    def __init__(self, kernel, sig: Signature):
        import cupy

        self._kernel = kernel
        self._cupy = cupy
        self.signature = sig

    def __call__(self, n: int, *args) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise TypeError(f"{self.signature.name}: n must be a non-negative integer, got {n!r}")
        checked = check_args(self.signature, n, args, self._cupy.ndarray, "cupy.ndarray")
        if n == 0:
            return
        blocks = min((int(n) + BLOCK_SIZE - 1) // BLOCK_SIZE, MAX_BLOCKS)
        self._kernel((blocks,), (BLOCK_SIZE,), (np.int64(n), *checked))


class CudaModule:
    """One kernel source compiled by NVRTC with one set of defines."""

    def __init__(self, name: str, defines: dict | None = None):
        import cupy

        self.source = kernel_path(name)
        self.defines = dict(defines or {})
        code = nvrtc_source(name)
        self.signatures = parse_kernels(self.source.read_text(), self.source.name, self.defines)
        self._module = cupy.RawModule(code=code, options=nvrtc_options(self.defines))
        self._functions: dict[str, CudaFunction] = {}

    def function(self, name: str) -> CudaFunction:
        """The kernel ``name``; a KeyError listing the available kernels if there is none."""
        if name not in self._functions:
            if name not in self.signatures:
                raise KeyError(f"{self.source.name} has no kernel {name!r} (has: {', '.join(self.signatures)})")
            try:
                kernel = self._module.get_function(name)
            except Exception as exc:  # NVRTC errors surface on first use
                raise KernelBuildError(f"compiling {self.source.name} for the GPU failed:\n{exc}") from exc
            self._functions[name] = CudaFunction(kernel, self.signatures[name])
        return self._functions[name]
