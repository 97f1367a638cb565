"""Kernel signatures read from the source, and the argument checks done before every launch.

A C kernel reads raw pointers: an array of the wrong dtype, a strided view or a missing argument would be
read as garbage. Every call is therefore checked against the signature parsed from the ``.cu`` file.
"""

from __future__ import annotations

import ast
import functools
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
    "unsigned short": np.dtype(np.uint16),
}

STORE_TYPE = "ck_store_t"
"""The populations' storage type (kernels/common.cuh): float, or IEEE binary16 when the module is built with
``CK_STORAGE_FP16=1`` (``unsigned short`` bits on CUDA, ``_Float16`` on the host). Pointer parameters of this
type take a float32 array, or a float16 one (numpy's float16 is binary16) in an fp16 module."""


def store_dtype(defines: dict | None) -> np.dtype:
    """NumPy dtype of ``ck_store_t`` under ``defines``."""
    fp16 = int((defines or {}).get("CK_STORAGE_FP16", 0) or 0)
    return np.dtype(np.float16 if fp16 else np.float32)


_KERNEL = re.compile(r"\bKERNEL\s+void\s+(\w+)\s*\(")
_SIZE = re.compile(r"/\*\s*size\s*(:|>=)\s*(.+?)\s*\*/", re.DOTALL)
_QUALIFIERS = re.compile(r"\b(const|RESTRICT|__restrict__|volatile)\b")


@dataclass(frozen=True)
class Param:
    """One kernel parameter: its name, its NumPy dtype, whether it is a pointer and whether it is written."""

    name: str
    dtype: np.dtype
    pointer: bool
    const: bool
    size: str | None = None  # `/* size: EXPR */` (exact element count) or `/* size >= EXPR */` annotation
    size_at_least: bool = False
    ctype: str | None = None  # the C type as written, when it is not the C_TYPES name of dtype (ck_store_t)

    def describe(self) -> str:
        ctype = self.ctype or next(k for k, v in C_TYPES.items() if v == self.dtype)
        if self.ctype:
            ctype = f"{ctype} [{self.dtype}]"
        return f"{'const ' if self.const else ''}{ctype}{'*' if self.pointer else ''} {self.name}"


@dataclass(frozen=True, eq=False)
class Signature:
    """A kernel's name and parameters; the first parameter is always the work-item count ``n``."""

    name: str
    params: tuple[Param, ...]
    source: str

    @functools.cached_property
    def has_sizes(self) -> bool:
        """Whether any parameter carries a size annotation."""
        return any(p.size for p in self.params)

    def describe(self) -> str:
        return f"{self.name}({', '.join(p.describe() for p in self.params)})"


def _strip_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.DOTALL)
    return re.sub(r"//[^\n]*", " ", text)


def _parameter_list(text: str, start: int) -> str:
    """The text between the '(' ending at ``start`` and its matching ')', skipping comments."""
    depth, i = 1, start
    while i < len(text):
        if text.startswith("/*", i):
            i = text.index("*/", i) + 2
            continue
        if text.startswith("//", i):
            i = text.index("\n", i)
            continue
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        if depth == 0:
            return text[start:i]
        i += 1
    raise ValueError("unbalanced parentheses in a kernel signature")


def _split_params(body: str) -> list[str]:
    """Split a parameter list at top-level commas (commas inside comments stay)."""
    parts, depth, current, i = [], 0, [], 0
    while i < len(body):
        if body.startswith("/*", i):
            j = body.index("*/", i) + 2
            current.append(body[i:j])
            i = j
            continue
        ch = body[i]
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if ch == "," and depth == 0:
            parts.append("".join(current))
            current = []
        else:
            current.append(ch)
        i += 1
    parts.append("".join(current))
    return [p for p in parts if _strip_comments(p).strip()]


def _parse_param(text: str, kernel: str, source: str, defines: dict | None = None) -> Param:
    size = _SIZE.search(text)
    text = _strip_comments(text)
    const = bool(re.search(r"\bconst\b", text.split("*")[0]))
    pointer = "*" in text
    words = _QUALIFIERS.sub(" ", text.replace("*", " ")).split()
    if len(words) < 2:
        raise ValueError(f"{source}: kernel {kernel}: cannot read parameter {text.strip()!r}")
    name, ctype = words[-1], " ".join(words[:-1])
    if ctype == STORE_TYPE:
        if not pointer:
            raise ValueError(f"{source}: kernel {kernel}: {STORE_TYPE} parameter {name!r} must be a pointer")
        dtype = store_dtype(defines)
    elif ctype in C_TYPES:
        dtype = C_TYPES[ctype]
    else:
        raise ValueError(
            f"{source}: kernel {kernel}: parameter {name!r} has type {ctype!r}; kernels may take "
            f"{', '.join(C_TYPES)} (as scalars or pointers) and {STORE_TYPE} pointers"
        )
    if size and not pointer:
        raise ValueError(f"{source}: kernel {kernel}: size annotation on scalar parameter {name!r}")
    return Param(
        name,
        dtype,
        pointer,
        const,
        size=size.group(2) if size else None,
        size_at_least=bool(size and size.group(1) == ">="),
        ctype=STORE_TYPE if ctype == STORE_TYPE else None,
    )


def parse_kernels(text: str, source: str = "<source>", defines: dict | None = None) -> dict[str, Signature]:
    """Every ``KERNEL void name(...)`` in ``text`` (headers pasted in or not), by name.

    ``defines``: the module's preprocessor flags; they decide the dtype of ``ck_store_t`` pointers
    (:func:`store_dtype`: float16 with ``CK_STORAGE_FP16=1``, else float32).

    A pointer parameter may carry a size annotation, checked at every call:
    ``const float* x /* size: 27 * n */`` (exactly that many elements) or ``/* size >= nx * ny */`` (at
    least). The expression may use ``n``, the kernel's integer scalar parameters, integers, ``+ - * / ( )``.
    """
    sigs: dict[str, Signature] = {}
    # comments blanked out position for position: kernels are found in code only, while the parameter
    # lists are read from the original text, where the size annotations are
    blanked = re.sub(r"/\*.*?\*/|//[^\n]*", lambda c: re.sub(r"[^\n]", " ", c.group(0)), text, flags=re.DOTALL)
    for m in _KERNEL.finditer(blanked):
        name = m.group(1)
        params = tuple(_parse_param(p, name, source, defines) for p in _split_params(_parameter_list(text, m.end())))
        if not params or params[0].pointer or params[0].dtype != np.int64:
            raise ValueError(f"{source}: kernel {name} must take `const long long n` as its first parameter")
        for p in params:
            if p.size:
                _check_size_expression(p.size, params, name, source)
        sigs[name] = Signature(name, params, source)
    return sigs


_ALLOWED_NODES = (
    ast.Expression,
    ast.BinOp,
    ast.Add,
    ast.Sub,
    ast.Mult,
    ast.Div,
    ast.FloorDiv,
    ast.Name,
    ast.Load,
    ast.Constant,
)


def _check_size_expression(expr: str, params: tuple[Param, ...], kernel: str, source: str) -> None:
    ints = {p.name for p in params if not p.pointer and p.dtype.kind in "iu"}
    tree = ast.parse(expr, mode="eval")
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED_NODES) or (isinstance(node, ast.Name) and node.id not in ints):
            raise ValueError(f"{source}: kernel {kernel}: size annotation {expr!r} may only use integer parameters")


@functools.cache
def _size_code(expr: str):
    """``expr`` compiled once; its names were checked by :func:`_check_size_expression` at parse time."""
    return compile(ast.parse(expr.replace("/", "//"), mode="eval"), "<size>", "eval")


def _eval_size(expr: str, values: dict[str, int]) -> int:
    return int(eval(_size_code(expr), {"__builtins__": {}}, values))


def check_args(sig: Signature, n: int, args: tuple, array_type: type, array_kind: str) -> list:
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
        if p.pointer:
            # the common case costs four attribute checks; messages are only built on failure
            if not (
                isinstance(a, array_type)
                and a.dtype == p.dtype
                and a.flags.c_contiguous
                # cupy.ndarray.flags has no `writeable` (device arrays are always writable)
                and (p.const or getattr(a.flags, "writeable", True))
            ):
                _array_error(sig, i, p, a, array_type, array_kind)
            out.append(a)
        elif type(a) is p.dtype.type:
            out.append(a)
        else:
            out.append(_scalar(a, p, f"{sig.name}: argument {i} ({p.describe()})"))
    if sig.has_sizes:
        values = {"n": int(n)}
        values.update(
            {p.name: int(a) for p, a in zip(expected, out, strict=True) if not p.pointer and p.dtype.kind in "iu"}
        )
        for i, (p, a) in enumerate(zip(expected, out, strict=True), start=2):
            if p.size:
                want = _eval_size(p.size, values)
                if a.size < want or (not p.size_at_least and a.size != want):
                    relation = ">=" if p.size_at_least else "=="
                    raise KernelArgumentError(
                        f"{sig.name}: argument {i} ({p.describe()}) has {a.size} elements; the kernel needs "
                        f"{relation} {p.size} = {want} (shape {tuple(a.shape)})"
                    )
    return out


def _array_error(sig: Signature, i: int, p: Param, a, array_type: type, array_kind: str) -> None:
    where = f"{sig.name}: argument {i} ({p.describe()})"
    if not isinstance(a, array_type):
        raise KernelArgumentError(f"{where} must be a {array_kind}, got {type(a).__name__}")
    if a.dtype != p.dtype:
        raise KernelArgumentError(f"{where} must have dtype {p.dtype}, got {a.dtype}; use .astype({p.dtype.name})")
    if not a.flags.c_contiguous:
        raise KernelArgumentError(f"{where} must be C-contiguous; pass an ascontiguousarray copy")
    raise KernelArgumentError(f"{where} is written by the kernel but the array is read-only")


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
