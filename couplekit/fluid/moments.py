"""The NOCM-MRT moment space of D3Q27 (paper Eqs. 11-12), built explicitly for the NumPy reference.

Central moments are ``κ_abc = Σ_j f_j (c_jx − u_x)^a (c_jy − u_y)^b (c_jz − u_z)^c`` with a, b, c ∈ {0, 1, 2}.
The 27 non-orthogonal polynomial moments ``k_0 … k_26`` (De Rosis & Luo 2019, the order in which the paper's
equilibrium, Eq. 12, has its non-zero entries at k0, k9, k17, k18, k26) are fixed linear combinations of
the central monomials; :data:`BASIS` is that 27×27 matrix acting on κ flattened as ``κ[a*9 + b*3 + c]``.
"""

from __future__ import annotations

import numpy as np

from ..lattice import C27, CS2

# each polynomial: list of (coefficient, (a, b, c)) monomials x^a y^b z^c
_POLYNOMIALS: list[list[tuple[int, tuple[int, int, int]]]] = [
    [(1, (0, 0, 0))],  # 0: 1
    [(1, (1, 0, 0))],  # 1: x
    [(1, (0, 1, 0))],  # 2: y
    [(1, (0, 0, 1))],  # 3: z
    [(1, (1, 1, 0))],  # 4: xy
    [(1, (1, 0, 1))],  # 5: xz
    [(1, (0, 1, 1))],  # 6: yz
    [(1, (2, 0, 0)), (-1, (0, 2, 0))],  # 7: x²−y²
    [(1, (2, 0, 0)), (-1, (0, 0, 2))],  # 8: x²−z²
    [(1, (2, 0, 0)), (1, (0, 2, 0)), (1, (0, 0, 2))],  # 9: x²+y²+z²
    [(1, (1, 2, 0)), (1, (1, 0, 2))],  # 10: xy²+xz²
    [(1, (2, 1, 0)), (1, (0, 1, 2))],  # 11: x²y+yz²
    [(1, (2, 0, 1)), (1, (0, 2, 1))],  # 12: x²z+y²z
    [(1, (1, 2, 0)), (-1, (1, 0, 2))],  # 13: xy²−xz²
    [(1, (2, 1, 0)), (-1, (0, 1, 2))],  # 14: x²y−yz²
    [(1, (2, 0, 1)), (-1, (0, 2, 1))],  # 15: x²z−y²z
    [(1, (1, 1, 1))],  # 16: xyz
    [(1, (2, 2, 0)), (1, (2, 0, 2)), (1, (0, 2, 2))],  # 17: x²y²+x²z²+y²z²
    [(1, (2, 2, 0)), (1, (2, 0, 2)), (-1, (0, 2, 2))],  # 18: x²y²+x²z²−y²z²
    [(1, (2, 2, 0)), (-1, (2, 0, 2))],  # 19: x²y²−x²z²
    [(1, (2, 1, 1))],  # 20: x²yz
    [(1, (1, 2, 1))],  # 21: xy²z
    [(1, (1, 1, 2))],  # 22: xyz²
    [(1, (1, 2, 2))],  # 23: xy²z²
    [(1, (2, 1, 2))],  # 24: x²yz²
    [(1, (2, 2, 1))],  # 25: x²y²z
    [(1, (2, 2, 2))],  # 26: x²y²z²
]


def _basis() -> np.ndarray:
    b = np.zeros((27, 27))
    for row, poly in enumerate(_POLYNOMIALS):
        for coef, (a, bb, c) in poly:
            b[row, a * 9 + bb * 3 + c] += coef
    return b


BASIS = _basis()
"""k = BASIS @ κ (κ flattened as a*9 + b*3 + c)."""
BASIS_INV = np.linalg.inv(BASIS)

SHEAR_ROWS = (4, 5, 6, 7, 8)
"""Rows relaxed with the shear rate r_s (the deviatoric second-order moments); every other rate is 1."""

ODD_ROWS = (10, 11, 12, 13, 14, 15, 16, 23, 24, 25)
"""Rows of odd total order (3 and 5): the antisymmetric moments, relaxed at the odd rate (1 in the paper)."""


def _kappa_table(values_1d: tuple[float, float, float]) -> np.ndarray:
    v = np.asarray(values_1d)
    return np.einsum("a,b,c->abc", v, v, v).reshape(27)


KAPPA_EQ = _kappa_table((1.0, 0.0, CS2))
"""Central moments of the sixth-order Hermite (product-form) equilibrium: products of {1, 0, c_s²}."""
K_EQ = BASIS @ KAPPA_EQ
"""Polynomial equilibrium moments, Eq. 12: k0 = k9 = 1, k17 = 1/3, k18 = 1/9, k26 = 1/27, others 0."""


def kappa_force(a: np.ndarray) -> np.ndarray:
    """Central moments (27, ...) of the continuous Guo forcing term (a·(ξ−u)/c_s²) f^eq for acceleration a (3, ...).

    For a Gaussian of variance c_s² per axis the non-zero ones are κ_100 = a_x, κ_120 = κ_102 = a_x c_s²,
    κ_122 = a_x c_s⁴ and their permutations (lbm-method note §1a).
    """
    out = np.zeros((27,) + a.shape[1:], dtype=np.float64)
    for axis in range(3):
        for others in ((0, 0), (2, 0), (0, 2), (2, 2)):
            idx = [0, 0, 0]
            idx[axis] = 1
            rest = [d for d in range(3) if d != axis]
            idx[rest[0]], idx[rest[1]] = others
            out[idx[0] * 9 + idx[1] * 3 + idx[2]] = a[axis] * CS2 ** (sum(others) // 2)
    return out


def axis_matrices(u: np.ndarray) -> np.ndarray:
    """A[a, i] = (c_i − u)^a for c_i ∈ {−1, 0, 1}, per cell: shape (3 orders, 3 velocities, ...) for u (...)."""
    c = np.array([-1.0, 0.0, 1.0]).reshape((3,) + (1,) * u.ndim)
    d = c - u[None]
    return np.stack([np.ones_like(d), d, d * d])


CUBE_INDEX = ((C27[:, 0] + 1) * 9 + (C27[:, 1] + 1) * 3 + (C27[:, 2] + 1)).astype(np.int64)
"""Position of direction j in the 3×3×3 velocity cube (ix*9 + iy*3 + iz, i = c + 1)."""


def to_central(f: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Central moments κ (27, ...) of populations f (27, ...) about velocity u (3, ...)."""
    cube = np.zeros((27,) + f.shape[1:], dtype=np.float64)
    cube[CUBE_INDEX] = f
    cube = cube.reshape((3, 3, 3) + f.shape[1:])
    ax, ay, az = (axis_matrices(u[d]) for d in range(3))
    kappa = np.einsum("ai...,bj...,ck...,ijk...->abc...", ax, ay, az, cube)
    return kappa.reshape((27,) + f.shape[1:])


def from_central(kappa: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Populations f (27, ...) whose central moments about u are κ (inverse of :func:`to_central`)."""
    shape = kappa.shape[1:]
    inv = []
    for d in range(3):
        a = np.moveaxis(axis_matrices(u[d]), (0, 1), (-2, -1))  # (..., 3, 3)
        try:
            ainv = np.linalg.inv(a)
        except np.linalg.LinAlgError:  # a non-finite velocity (a diverged state): NaN populations, which the
            ainv = np.full_like(a, np.nan)  # divergence check then reports, instead of a traceback mid-step
        inv.append(np.moveaxis(ainv, (-2, -1), (0, 1)))  # (3 velocities, 3 orders, ...)
    cube = np.einsum("ia...,jb...,kc...,abc...->ijk...", inv[0], inv[1], inv[2], kappa.reshape((3, 3, 3) + shape))
    return cube.reshape((27,) + shape)[CUBE_INDEX]
