"""A stand-in GPU for testing the cuda backend's Python code on a machine without one.

:func:`stand_in_device` puts a stand-in for the part of the CuPy module that couplekit uses in
``sys.modules["cupy"]``, so ``get_backend("cuda")`` and everything above it (solvers, coupler, schedulers,
``Simulation``: fields, particles, diagnostics, checkpoints) run unchanged on it:

* arrays (:class:`StandInArray`) hold NumPy memory but, like CuPy's, refuse implicit conversion:
  ``np.asarray(a)``, ``np.array(a)``, h5py writes and NumPy functions on them raise ``TypeError``; an
  operation mixing them with a ``numpy.ndarray`` raises ``TypeError`` (CuPy: "Unsupported type");
  assigning a non-scalar ``numpy.ndarray`` into one raises ``ValueError`` (CuPy's ``ndarray.fill``);
  ``a.get()``, ``cupy.asnumpy(a)``, ``cupy.asarray(host)``, ``a.set(host)`` are the explicit transfers, and
  ``float(a)``/``int(a)``/``bool(a)``/``a.item()`` of one element the implicit ones CuPy allows;
* their attributes are CuPy's (``a.flags`` has ``c_contiguous``, ``f_contiguous``, ``owndata`` and no
  ``writeable``; there is no ``a.ctypes``), reductions return 0-d arrays, not NumPy scalars;
* ``cupy.RawModule(code=..., options=...)`` compiles the very text the cuda backend hands to NVRTC with the
  host compiler in device-path mode (``-DCK_DEVICE_PATH=1``: the kernels' CUDA code paths, see
  kernels/common.cuh), taking the ``-D`` options; its kernels launch as ``kernel(grid, block, args)`` with
  device arrays and NumPy scalars only (CuPy would pass a Python int as int64 and a float as double).

It is stricter than CuPy in one respect, on purpose: CuPy dispatches many NumPy functions called on its
arrays (``np.sum(a)``) to its own, the stand-in refuses every one, so that code names ``backend.xp`` or
transfers explicitly. For tests; no part of couplekit's runtime imports this module.

>>> with stand_in_device():
...     sim = Simulation(scene, backend="cuda")
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import re
import sys
import types
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .host import build_library, cache_dir

__all__ = ["StandInArray", "stand_in_device", "make_cupy"]

IMPLICIT = (
    "Implicit conversion to a NumPy array is not allowed (stand-in device, as CuPy). "
    "Use .get() or cupy.asnumpy() (couplekit: backend.to_host) to copy it to the host explicitly."
)

# the ndarray methods of CuPy 14 that the stand-in forwards to NumPy (CuPy has them all; NumPy-only ones,
# such as ctypes, tofile's siblings or setflags, are absent so that code using them fails here as on a GPU)
_METHODS = frozenset(
    "all any argmax argmin argsort astype clip conj conjugate copy cumprod cumsum diagonal dot fill flatten "
    "max mean min nonzero prod ptp ravel repeat reshape round sort squeeze std sum swapaxes take "
    "tobytes tolist trace transpose var view".split()
)

# module functions forwarded to NumPy; every one exists in CuPy.  They refuse numpy.ndarray arguments as
# CuPy does, except the transfers (_FROM_HOST).
_FUNCTIONS = frozenset(
    "abs absolute add all allclose amax amin any arange argmax argmin argsort around array_equal "
    "ascontiguousarray broadcast_to ceil clip concatenate copy count_nonzero cos cumsum diff divide "
    "dot einsum empty empty_like equal exp expand_dims eye flip floor full full_like isclose isfinite isinf "
    "isnan linspace log logical_and logical_not logical_or matmul maximum mean meshgrid minimum moveaxis "
    "multiply nonzero ones ones_like pad prod ravel repeat reshape roll rint round sign sin sqrt square "
    "squeeze stack std subtract sum swapaxes take tile transpose unravel_index var where zeros zeros_like".split()
)
_FROM_HOST = frozenset({"array", "asarray", "asanyarray"})
# NumPy names CuPy re-exports unchanged (types, constants)
_PASSTHROUGH = frozenset(
    "bool_ complex64 complex128 dtype e float16 float32 float64 inf int8 int16 int32 int64 intp nan newaxis "
    "pi uint8 uint16 uint32 uint64 finfo iinfo".split()
)


def _host_refused(where: str) -> TypeError:
    return TypeError(
        f"{where}: a numpy.ndarray cannot be mixed with device arrays (stand-in device, as CuPy: "
        "'Unsupported type <class 'numpy.ndarray'>'); copy it to the device first with backend.asarray / cupy.asarray"
    )


def _unwrap(obj, where: str, allow_host: bool = False):
    """Device arrays -> their NumPy memory, recursively through lists/tuples/dicts; host arrays refused."""
    if isinstance(obj, StandInArray):
        return obj._a
    if isinstance(obj, np.ndarray):
        if not allow_host:
            raise _host_refused(where)
        return obj
    if isinstance(obj, (list, tuple)):
        return type(obj)(_unwrap(o, where, allow_host) for o in obj)
    if isinstance(obj, dict):
        return {k: _unwrap(v, where, allow_host) for k, v in obj.items()}
    return obj


def _wrap(obj):
    """NumPy results -> device arrays (NumPy scalars become 0-d arrays, as CuPy's reductions return)."""
    if isinstance(obj, np.ndarray):
        return StandInArray(obj)
    if isinstance(obj, np.generic):
        return StandInArray(np.asarray(obj))
    if isinstance(obj, tuple):
        return tuple(_wrap(o) for o in obj)
    if isinstance(obj, list):
        return [_wrap(o) for o in obj]
    return obj


class StandInFlags:
    """CuPy's ``ndarray.flags``: c_contiguous, f_contiguous, owndata (no ``writeable``)."""

    __slots__ = ("c_contiguous", "f_contiguous", "owndata")

    def __init__(self, a: np.ndarray):
        self.c_contiguous = bool(a.flags.c_contiguous)
        self.f_contiguous = bool(a.flags.f_contiguous)
        self.owndata = bool(a.flags.owndata)


class _Pointer:
    __slots__ = ("ptr",)

    def __init__(self, ptr: int):
        self.ptr = ptr


class StandInArray:
    """A device array of the stand-in GPU: NumPy memory behind CuPy's interface and refusals."""

    __slots__ = ("_a",)
    __array_priority__ = 100.0
    __hash__ = None  # type: ignore[assignment]

    def __init__(self, a: np.ndarray):
        if not isinstance(a, np.ndarray):
            raise TypeError(f"StandInArray wraps a numpy.ndarray, got {type(a).__name__}")
        self._a = a

    # ---- what CuPy refuses
    def __array__(self, dtype=None, copy=None):
        raise TypeError(IMPLICIT)

    def __array_function__(self, func, types_, args, kwargs):
        name = getattr(func, "__name__", str(func))
        raise TypeError(
            f"NumPy function numpy.{name} called on a device array (stand-in device). Use backend.xp.{name}, "
            "or copy to the host first with backend.to_host"
        )

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        # a NumPy scalar on the left of an operator (np.float32(2) * a) arrives here; CuPy computes it
        if method == "__call__" and not kwargs and len(inputs) == 2:
            if all(isinstance(x, (StandInArray, np.generic, int, float, bool)) for x in inputs):
                return StandInArray(np.asarray(ufunc(*(_unwrap(x, ufunc.__name__) for x in inputs))))
        raise TypeError(
            f"NumPy ufunc numpy.{ufunc.__name__} called on a device array (stand-in device). Use "
            f"backend.xp.{ufunc.__name__}, or copy to the host first with backend.to_host"
        )

    # ---- attributes
    shape = property(lambda self: self._a.shape)
    dtype = property(lambda self: self._a.dtype)
    size = property(lambda self: self._a.size)
    ndim = property(lambda self: self._a.ndim)
    strides = property(lambda self: self._a.strides)
    nbytes = property(lambda self: self._a.nbytes)
    itemsize = property(lambda self: self._a.itemsize)
    flags = property(lambda self: StandInFlags(self._a))
    data = property(lambda self: _Pointer(self._a.ctypes.data))
    T = property(lambda self: StandInArray(self._a.T))
    real = property(lambda self: StandInArray(self._a.real))
    imag = property(lambda self: StandInArray(self._a.imag))
    flat = property(lambda self: StandInArray(self._a.reshape(-1)))

    def __getattr__(self, name: str):
        if name in _METHODS:
            method = getattr(self._a, name)

            def call(*args, **kwargs):
                return _wrap(method(*_unwrap(args, f"ndarray.{name}"), **_unwrap(kwargs, f"ndarray.{name}")))

            return call
        raise AttributeError(f"'cupy.ndarray' (stand-in device) has no attribute {name!r}")

    # ---- explicit transfers
    def get(self, stream=None, order="C", out=None, blocking=True) -> np.ndarray:
        """A NumPy copy (device -> host)."""
        if out is not None:
            out[...] = self._a
            return out
        return np.array(self._a, order=order, copy=True)

    def set(self, arr, stream=None) -> None:
        """Copy the host array ``arr`` into this array (host -> device)."""
        if not isinstance(arr, np.ndarray):
            raise TypeError(f"ndarray.set takes a numpy.ndarray, got {type(arr).__name__}")
        if arr.shape != self._a.shape or arr.dtype != self._a.dtype:
            raise ValueError(f"ndarray.set: shape/dtype {arr.shape}/{arr.dtype} != {self._a.shape}/{self._a.dtype}")
        self._a[...] = arr

    def item(self):
        return self._a.item()

    # ---- the implicit transfers CuPy allows (one element; a synchronising copy on a GPU)
    def _one(self, kind):
        if self._a.size != 1:
            raise TypeError(f"only size-1 device arrays can be converted to Python scalars, got shape {self.shape}")
        return kind(self._a.reshape(()).item())

    def __float__(self):
        return self._one(float)

    def __int__(self):
        return self._one(int)

    def __complex__(self):
        return self._one(complex)

    def __bool__(self):
        if self._a.size != 1:
            raise ValueError("The truth value of an array with more than one element is ambiguous.")
        return bool(self._a.reshape(()).item())

    def __len__(self):
        if self._a.ndim == 0:
            raise TypeError("len() of unsized object")
        return len(self._a)

    def __iter__(self) -> Iterator[StandInArray]:
        if self._a.ndim == 0:
            raise TypeError("iteration over a 0-d array")
        return (StandInArray(np.asarray(self._a[i])) for i in range(len(self._a)))

    def __repr__(self):
        return f"array({self._a!r}) [stand-in device]"

    def __str__(self):
        return str(self._a)

    def __copy__(self):
        return StandInArray(self._a.copy())

    def __deepcopy__(self, memo):
        return StandInArray(self._a.copy())

    def __reduce__(self):
        raise TypeError("pickling a device array (stand-in device) would hide a device->host copy; use .get()")

    # ---- indexing: host index arrays are accepted (CuPy copies them to the device); an assigned value must
    # be a device array or a scalar: CuPy's __setitem__ refuses a non-scalar numpy.ndarray (ndarray.fill)
    def __getitem__(self, key):
        return _wrap(self._a[_unwrap(key, "indexing", allow_host=True)])

    def __setitem__(self, key, value):
        if isinstance(value, np.ndarray) and value.shape != ():
            raise ValueError(
                "non-scalar numpy.ndarray cannot be used for fill (stand-in device, as CuPy's __setitem__): copy "
                "the host array to the device first (backend.asarray / cupy.asarray) or use .set()"
            )
        self._a[_unwrap(key, "indexing", allow_host=True)] = _unwrap(value, "assignment", allow_host=True)


def _operand(x, op: str):
    if isinstance(x, StandInArray):
        return x._a
    if isinstance(x, np.ndarray):
        raise _host_refused(f"operator {op}")
    if isinstance(x, (np.generic, int, float, bool, complex)):
        return x
    return NotImplemented


def _binary(op: str, reflected: bool = False, inplace: bool = False):
    fn = getattr(np.ndarray, f"__{op}__")

    def method(self, other):
        o = _operand(other, op)
        if o is NotImplemented:
            return NotImplemented
        if inplace:
            fn(self._a, o)
            return self
        return _wrap(np.asarray(fn(self._a, o)))

    return method


for _op in "add sub mul truediv floordiv mod pow matmul and or xor lshift rshift eq ne lt le gt ge".split():
    setattr(StandInArray, f"__{_op}__", _binary(_op))
for _op in "add sub mul truediv floordiv mod pow matmul and or xor lshift rshift".split():
    setattr(StandInArray, f"__r{_op}__", _binary(f"r{_op}"))
    setattr(StandInArray, f"__i{_op}__", _binary(f"i{_op}", inplace=True))


def _unary(op: str):
    fn = getattr(np.ndarray, f"__{op}__")

    def method(self):
        return StandInArray(np.asarray(fn(self._a)))

    return method


for _op in "neg pos abs invert".split():
    setattr(StandInArray, f"__{_op}__", _unary(_op))


# ------------------------------------------------------------------------------------------ kernels
_LINE = re.compile(r'^#line 1 "([^"]+)"', re.MULTILINE)


class StandInRawKernel:
    """``cupy.RawKernel`` of the stand-in: ``kernel(grid, block, args)`` runs the device-path host build."""

    def __init__(self, cfunc, name: str):
        self._cfunc = cfunc
        self._cfunc.restype = None
        self.name = name
        self.launches = 0

    def __call__(self, grid, block, args, *, shared_mem: int = 0, stream=None, enable_cooperative_groups=False):
        for what, dims, limit in (("grid", grid, 2**31 - 1), ("block", block, 1024)):
            if not isinstance(dims, tuple) or not 1 <= len(dims) <= 3:
                raise TypeError(f"{self.name}: {what} must be a tuple of 1 to 3 ints, got {dims!r}")
            if not all(isinstance(d, (int, np.integer)) and 1 <= d <= limit for d in dims):
                raise ValueError(f"{self.name}: {what} dimensions must be in [1, {limit}], got {dims!r}")
        if int(np.prod(block)) > 1024:
            raise ValueError(f"{self.name}: {np.prod(block)} threads per block exceed the CUDA limit of 1024")
        if not isinstance(args, tuple):
            raise TypeError(f"{self.name}: kernel arguments must be a tuple, got {type(args).__name__}")
        ctypes_args, argtypes = [], []
        for i, a in enumerate(args):
            if isinstance(a, StandInArray):
                ctypes_args.append(a._a.ctypes.data)
                argtypes.append(ctypes.c_void_p)
            elif isinstance(a, np.generic):
                ctype = np.ctypeslib.as_ctypes_type(a.dtype)
                ctypes_args.append(ctype(a.item()))
                argtypes.append(ctype)
            elif isinstance(a, np.ndarray):
                raise TypeError(f"{self.name}: argument {i} is a host numpy.ndarray; kernels take device arrays")
            else:
                raise TypeError(
                    f"{self.name}: argument {i} is a Python {type(a).__name__}; pass a NumPy scalar of the "
                    "parameter's C type (CuPy passes a Python int as int64 and a float as double)"
                )
        self._cfunc.argtypes = argtypes
        self._cfunc(*ctypes_args)
        self.launches += 1


class StandInRawModule:
    """``cupy.RawModule(code=..., options=...)`` of the stand-in: the code built by the host compiler in
    device-path mode (the CUDA code paths), its ``-D`` options as defines."""

    def __init__(self, code: str | None = None, *, path=None, options: tuple = (), backend="nvrtc", **kwargs):
        if code is None:
            raise TypeError("the stand-in RawModule compiles source code (code=...), not a cubin path")
        self.options = tuple(options)
        defines: dict[str, str] = {}
        for opt in self.options:
            if opt.startswith("-D"):
                key, _, value = opt[2:].partition("=")
                defines[key] = value or "1"
            elif opt != "--std=c++17":
                raise ValueError(f"the stand-in device does not model the NVRTC option {opt!r}")
        m = _LINE.search(code)
        stem = Path(m.group(1)).stem if m else "module"
        digest = hashlib.sha256(code.encode()).hexdigest()[:16]
        source = _workdir() / f"{stem}-{digest}.cu"
        if not source.is_file():
            source.write_text(code)
        self.build = build_library(source, defines, device_path=True)
        self._lib = ctypes.CDLL(str(self.build.library))
        self._kernels: dict[str, StandInRawKernel] = {}

    def get_function(self, name: str) -> StandInRawKernel:
        if name not in self._kernels:
            try:
                cfunc = getattr(self._lib, name)
            except AttributeError:
                raise RuntimeError(f"CUDA_ERROR_NOT_FOUND: named symbol not found: {name} (stand-in device)") from None
            self._kernels[name] = StandInRawKernel(cfunc, name)
        return self._kernels[name]


_WORKDIR: list[Path] = []


def _workdir() -> Path:
    if not _WORKDIR:
        raise RuntimeError("the stand-in device is not installed; use `with stand_in_device(workdir):`")
    return _WORKDIR[-1]


# ------------------------------------------------------------------------------------------ the module
def _forward(name: str):
    fn = getattr(np, name)
    allow_host = name in _FROM_HOST

    def call(*args, **kwargs):
        return _wrap(fn(*_unwrap(args, f"cupy.{name}", allow_host), **_unwrap(kwargs, f"cupy.{name}", allow_host)))

    call.__name__ = name
    return call


def _asarray(a, dtype=None, order=None, *, blocking=False):
    """``cupy.asarray``: a device array (host arrays, lists and scalars are copied to the device)."""
    if isinstance(a, StandInArray):
        return a if dtype is None or np.dtype(dtype) == a.dtype else StandInArray(a._a.astype(dtype))
    return StandInArray(np.array(_unwrap(a, "cupy.asarray", allow_host=True), dtype=dtype, order=order or "K"))


def _array(obj, dtype=None, copy=True, order="K", subok=False, ndmin=0, *, blocking=False):
    """``cupy.array``: a new device array (a copy unless ``copy=False`` allows reuse)."""
    if isinstance(obj, StandInArray) and not copy and (dtype is None or np.dtype(dtype) == obj.dtype):
        return obj
    host = _unwrap(obj, "cupy.array", allow_host=True)
    return StandInArray(np.array(host, dtype=dtype, order=order, ndmin=ndmin, copy=True))


def _asnumpy(a, stream=None, order="C", out=None, blocking=True):
    """``cupy.asnumpy``: a host copy of a device array (host input passes through ``numpy.asarray``)."""
    if isinstance(a, StandInArray):
        return a.get(order=order, out=out)
    return np.asarray(a, order=order)


def _cuda_namespace(free_bytes: int) -> types.SimpleNamespace:
    class Device:
        def __init__(self, device: int = 0):
            self.id = int(device)

        def synchronize(self) -> None:
            pass

        def use(self) -> None:
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    runtime = types.SimpleNamespace(
        getDeviceCount=lambda: 1,
        getDeviceProperties=lambda i: {"name": b"stand-in device (host build of the CUDA code paths)"},
        memGetInfo=lambda: (free_bytes, 2 * free_bytes),
        deviceSynchronize=lambda: None,
    )
    return types.SimpleNamespace(runtime=runtime, Device=Device)


def make_cupy(free_bytes: int = 8 << 30) -> types.ModuleType:
    """A module object with the stand-in CuPy surface (``free_bytes``: what ``memGetInfo`` reports free)."""
    mod = types.ModuleType("cupy", "stand-in CuPy (couplekit.backend.standin): NumPy memory, CuPy's refusals")
    mod.__version__ = "stand-in"
    mod.ndarray = StandInArray
    mod.RawModule = StandInRawModule
    mod.RawKernel = StandInRawKernel
    mod.asarray = _asarray
    mod.array = _array
    mod.asanyarray = _asarray
    mod.asnumpy = _asnumpy
    mod.cuda = _cuda_namespace(free_bytes)
    mod.get_array_module = lambda *args: mod if any(isinstance(a, StandInArray) for a in args) else np
    for name in _FUNCTIONS:
        setattr(mod, name, _forward(name))
    for name in _PASSTHROUGH:
        setattr(mod, name, getattr(np, name))

    def __getattr__(name: str):
        raise AttributeError(
            f"the stand-in cupy has no attribute {name!r}; if CuPy has it, add it to couplekit/backend/standin.py"
        )

    mod.__getattr__ = __getattr__
    return mod


@contextlib.contextmanager
def stand_in_device(workdir: str | Path | None = None, free_bytes: int = 8 << 30) -> Iterator[types.ModuleType]:
    """Install the stand-in as ``cupy`` for the duration of the block (the real module, if any, is put
    back after).  ``workdir`` holds the kernel texts it builds (default: ``stand-in`` in the kernel cache,
    a fixed place, so that the built libraries are reused between sessions).  Yields the stand-in module."""
    workdir = Path(workdir) if workdir is not None else cache_dir() / "stand-in"
    workdir.mkdir(parents=True, exist_ok=True)
    saved = {k: v for k, v in sys.modules.items() if k == "cupy" or k.startswith("cupy.")}
    for k in saved:
        del sys.modules[k]
    fake = make_cupy(free_bytes)
    sys.modules["cupy"] = fake
    _WORKDIR.append(workdir)
    try:
        yield fake
    finally:
        _WORKDIR.pop()
        for k in [k for k in sys.modules if k == "cupy" or k.startswith("cupy.")]:
            del sys.modules[k]
        sys.modules.update(saved)
