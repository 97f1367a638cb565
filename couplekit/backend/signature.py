"""Kernel signatures read from the source, and the argument checks done before every launch.

A C kernel reads raw pointers: an array of the wrong dtype, a strided view or a missing argument would be
read as garbage. Every call is therefore checked against the signature parsed from the ``.cu`` file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .errors import KernelArgumentError

# C type (after dropping const / RESTRICT) -> NumPy dtype
C_TYPES: dict[str, np.dtype] = {
    "float": np.dtype(np.float32),
    "double": np.dtype(np.float64),
    "int": np.dtype(np.int32),
    "unsigned int": np.dtype(np.uint32),
    "long long": np.dtype(np.int64),
    "unsigned char": np.dtype(np.uint8),
    "signed char": np.dtype(np.int8),
}

_KERNEL = re.compile(r"\bKERNEL\s+void\s+(\w+)\s*\(([^)]*)\)", re.DOTALL)
_QUALIFIERS = re.compile(r"\b(const|RESTRICT|__restrict__|volatile)\b")


@dataclass(frozen=True)
class Param:
    """One kernel parameter: its name, its NumPy dtype, whether it is a pointer and whether it is written."""

    name: str
    dtype: np.dtype
    pointer: bool
    const: bool

    def describe(self) -> str:
        ctype = next(k for k, v in C_TYPES.items() if v == self.dtype)
        return f"{'const ' if self.const else ''}{ctype}{'*' if self.pointer else ''} {self.name}"


@dataclass(frozen=True)
class Signature:
    """A kernel's name and parameters; the first parameter is always the work-item count ``n``."""

    name: str
    params: tuple[Param, ...]
    source: str

    def describe(self) -> str:
        return f"{self.name}({', '.join(p.describe() for p in self.params)})"


def _strip_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.DOTALL)
    return re.sub(r"//[^\n]*", " ", text)


def _parse_param(text: str, kernel: str, source: str) -> Param:
    const = bool(re.search(r"\bconst\b", text.split("*")[0]))
    pointer = "*" in text
    words = _QUALIFIERS.sub(" ", text.replace("*", " ")).split()
    if len(words) < 2:
        raise ValueError(f"{source}: kernel {kernel}: cannot read parameter {text.strip()!r}")
    name, ctype = words[-1], " ".join(words[:-1])
    if ctype not in C_TYPES:
        raise ValueError(
            f"{source}: kernel {kernel}: parameter {name!r} has type {ctype!r}; kernels may take "
            f"{', '.join(C_TYPES)} (as scalars or pointers)"
        )
    return Param(name, C_TYPES[ctype], pointer, const)


def parse_kernels(text: str, source: str = "<source>") -> dict[str, Signature]:
    """Every ``KERNEL void name(...)`` in ``text`` (headers pasted in or not), by name."""
    sigs: dict[str, Signature] = {}
    for m in _KERNEL.finditer(_strip_comments(text)):
        name, body = m.group(1), m.group(2)
        params = tuple(_parse_param(p, name, source) for p in body.split(",") if p.strip())
        if not params or params[0].pointer or params[0].dtype != np.int64:
            raise ValueError(f"{source}: kernel {name} must take `const long long n` as its first parameter")
        sigs[name] = Signature(name, params, source)
    return sigs


def check_args(sig: Signature, args: tuple, array_type: type, array_kind: str) -> list:
    """Check ``args`` (without ``n``) against ``sig``; return them with Python scalars cast to the C type.

    Arrays must be ``array_type`` (numpy.ndarray or cupy.ndarray), of the exact dtype, C-contiguous, and
    writeable when the kernel writes them. Scalars must be NumPy scalars of the exact dtype, or Python
    numbers that convert without loss of kind (int for integer parameters, int/float for float ones).
    """
    expected = sig.params[1:]
    if len(args) != len(expected):
        raise KernelArgumentError(
            f"{sig.name} takes n and {len(expected)} more arguments, got {len(args)}: {sig.describe()}"
        )
    out = []
    for i, (p, a) in enumerate(zip(expected, args, strict=True), start=2):
        where = f"{sig.name}: argument {i} ({p.describe()})"
        if p.pointer:
            if not isinstance(a, array_type):
                raise KernelArgumentError(f"{where} must be a {array_kind}, got {type(a).__name__}")
            if a.dtype != p.dtype:
                raise KernelArgumentError(
                    f"{where} must have dtype {p.dtype}, got {a.dtype}; use .astype({p.dtype.name})"
                )
            if not a.flags.c_contiguous:
                raise KernelArgumentError(f"{where} must be C-contiguous; pass an ascontiguousarray copy")
            if not p.const and not a.flags.writeable:
                raise KernelArgumentError(f"{where} is written by the kernel but the array is read-only")
            out.append(a)
        else:
            out.append(_scalar(a, p, where))
    return out


def _scalar(a, p: Param, where: str):
    if isinstance(a, np.generic):
        if a.dtype != p.dtype:
            raise KernelArgumentError(
                f"{where} must be a {p.dtype} scalar, got {a.dtype}; wrap it as np.{p.dtype.name}(...)"
            )
        return a
    if isinstance(a, bool) or not isinstance(a, (int, float)):
        raise KernelArgumentError(f"{where} must be a number, got {type(a).__name__}")
    if p.dtype.kind in "iu":
        if not isinstance(a, int):
            raise KernelArgumentError(f"{where} is an integer parameter, got float {a!r}")
        info = np.iinfo(p.dtype)
        if not info.min <= a <= info.max:
            raise KernelArgumentError(f"{where}: {a} does not fit in {p.dtype}")
    return p.dtype.type(a)
