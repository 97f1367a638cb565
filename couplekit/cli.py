"""The ``couplekit`` command line.

``couplekit info [--selfcheck] [--backend B]``: version, backend chosen and why, host compiler, nvcc,
CuPy/GPU status, kernel cache; ``--selfcheck`` also builds and runs the self-check kernels against NumPy.
"""

from __future__ import annotations

import argparse
import sys
import time

from . import __version__
from .backend import BackendUnavailableError, KernelBuildError, cuda_status, get_backend, host_tools


def _cmd_info(args: argparse.Namespace) -> int:
    print(f"couplekit {__version__}")
    try:
        backend = get_backend(args.backend, threads=args.threads)
    except (BackendUnavailableError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(backend.describe())
    ok, why = cuda_status()
    print(f"cuda: {'available' if ok else 'unavailable'} ({why})")
    for key, value in host_tools().items():
        print(f"{key}: {value}")
    if not args.selfcheck:
        return 0
    if not backend.has_kernels:
        print("selfcheck: the numpy backend compiles no kernels; nothing to check")
        return 0
    from .selfcheck import run_selfcheck

    t0 = time.perf_counter()
    try:
        results = run_selfcheck(backend)
    except KernelBuildError as exc:
        print(f"selfcheck: kernel build failed\n{exc}", file=sys.stderr)
        return 1
    for r in results:
        print(
            f"selfcheck {'ok  ' if r.ok else 'FAIL'} {r.name}: rel. error {r.error:.2e} (tolerance {r.tolerance:.0e})"
        )
    if backend.name == "cpu":
        threads = backend.module("selfcheck.cu").num_threads()
        print(f"selfcheck: host kernels ran on {threads} OpenMP thread(s) in {time.perf_counter() - t0:.2f} s")
    return 0 if all(r.ok for r in results) else 1


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``couplekit`` command."""
    parser = argparse.ArgumentParser(prog="couplekit", description=__doc__.split("\n")[0])
    parser.add_argument("--version", action="version", version=f"couplekit {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    info = sub.add_parser("info", help="backend, compilers, GPU and cache; --selfcheck runs the kernels")
    info.add_argument("--backend", default="auto", help="auto (default), cuda, cpu or numpy")
    info.add_argument("--threads", type=int, default=None, help="OpenMP threads of the cpu backend")
    info.add_argument("--selfcheck", action="store_true", help="build and run the self-check kernels")
    info.set_defaults(func=_cmd_info)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``couplekit`` command."""
    args = build_parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
