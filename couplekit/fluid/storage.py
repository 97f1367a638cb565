"""Storage precision of the populations f (D3Q27) and h (D3Q7): ``"fp32"`` (default) or ``"fp16"``.

fp16 storage keeps the arithmetic in float32 (kernels) or float64 (NumPy reference) and rounds only what is
stored, round-to-nearest-even (NumPy's float16 conversion, the host kernels' ``_Float16``, CUDA's
``cvt.rn.f16.f32``). The stored binary16 values are scaled by powers of two so that they stay in binary16's
normal range (docs/precision.md, "fp16 storage"):

* f is stored as ``(f − w) · F_SCALE`` with ``F_SCALE = 32768`` (FluidX3D's FP16S choice): |f − w| up to
  65504 / 32768 ≈ 2 (a population f_j is within [0, 1] in any run that is not diverging, so |f − w| < 1);
  the smallest normal value is 6.1e-5 / 32768 = 1.9e-9, subnormals reach 1.8e-12.
* h is stored as ``(h_q − H_REST w_q) · H_SCALE`` with ``H_REST = 0`` (unshifted) and ``H_SCALE = 32768``
  (h ≤ 65504 / 32768 ≈ 2; h_q ≈ w_q φ ≤ 0.25 for φ ≤ 1). Chosen by measurement over ``H_REST = 1`` (h − w_q,
  which stores the water bulk's flux parts finely): with the shift the small φ tails in the air round away
  against −w_q, always towards 0, and the Fig. 13 small scene lost 8.2e-4 of its water in 276 steps against
  4.7e-5 unshifted (docs/precision.md, "fp16 storage"). Resting water (h = w_q) and air (h = 0) are exact
  either way.

A stored value beyond 65504 / scale becomes ±inf (a conversion, not a clamp): the solver's finite checks then
see the divergence. The constants mirror ``kernels/common.cuh`` (``CK_F_SCALE``, ``CK_H_SCALE``,
``CK_H_REST``), which a test reads.

float32 arrays hold f − w and h unscaled, so fp32 storage is exactly what it was before this option.
"""

from __future__ import annotations

import numpy as np

from ..lattice import W7, W27

STORAGES = ("fp32", "fp16")
"""The storage choices (``fluid.storage`` in a scene, ``FluidSolver(storage=...)``)."""

F_SCALE = 32768.0
H_SCALE = 32768.0
H_REST = 0.0


def check_storage(storage: str, where: str = "storage") -> str:
    """``storage`` if it is one of :data:`STORAGES`, else a ValueError naming ``where`` and the choices."""
    if storage not in STORAGES:
        raise ValueError(f"{where} must be one of {', '.join(map(repr, STORAGES))}, got {storage!r}")
    return storage


def dtype_of(storage: str) -> np.dtype:
    """NumPy dtype of the population arrays for ``storage``."""
    return np.dtype(np.float16 if check_storage(storage) == "fp16" else np.float32)


def storage_of(a) -> str:
    """The storage of a population array, from its dtype (float16 → ``"fp16"``, float32 → ``"fp32"``)."""
    dt = np.dtype(a.dtype)
    if dt == np.float16:
        return "fp16"
    if dt == np.float32:
        return "fp32"
    raise TypeError(f"a population array is float32 or float16, got {dt}")


def bytes_per_value(storage: str) -> int:
    """Bytes of one stored population."""
    return dtype_of(storage).itemsize


def _w(weights: np.ndarray, ndim: int) -> np.ndarray:
    return weights.reshape((weights.size,) + (1,) * (ndim - 1))


def encode_f(shifted: np.ndarray, storage: str) -> np.ndarray:
    """Stored array of f − w values ``shifted`` (27, ...; any float dtype, rounded once from float64)."""
    shifted = np.asarray(shifted, np.float64)
    if storage == "fp16":
        with np.errstate(over="ignore"):
            return (shifted * F_SCALE).astype(np.float16)
    return shifted.astype(np.float32)


def decode_f(stored: np.ndarray) -> np.ndarray:
    """f − w (float64) of a stored f array (float32 or float16)."""
    out = np.asarray(stored).astype(np.float64)
    if np.asarray(stored).dtype == np.float16:
        out /= F_SCALE
    return out


def encode_h(h: np.ndarray, storage: str) -> np.ndarray:
    """Stored array (7, ...) of phase-field populations ``h`` (float64 or float32 values)."""
    if storage == "fp16":
        shifted = np.asarray(h, np.float64) - H_REST * _w(W7, np.ndim(h))
        with np.errstate(over="ignore"):
            return (shifted * H_SCALE).astype(np.float16)
    return np.asarray(h).astype(np.float32)


def decode_h(stored: np.ndarray) -> np.ndarray:
    """The populations h (float64, 7, ...) of a stored h array (float32 or float16)."""
    out = np.asarray(stored).astype(np.float64)
    if np.asarray(stored).dtype == np.float16:
        out = out / H_SCALE + H_REST * _w(W7, out.ndim)
    return out


def round_h(h: np.ndarray, storage: str) -> np.ndarray:
    """h (float64) rounded to what ``storage`` can hold (the identity on float32-representable values for fp32)."""
    if storage == "fp16":
        return decode_h(encode_h(h, storage))
    return np.asarray(h, np.float64).astype(np.float32).astype(np.float64)


def weights27(ndim: int) -> np.ndarray:
    """W27 shaped to broadcast against a (27, ...) array of ``ndim`` dimensions."""
    return _w(W27, ndim)
