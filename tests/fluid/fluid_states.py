"""Random but valid fluid states on a small padded grid with every boundary kind, for kernel-vs-reference tests."""

from __future__ import annotations

import numpy as np

from couplekit.fluid.grid import (
    Boundaries,
    Face,
    build_flags,
    link_box_arrays,
    outflow_directions,
    outflow_lists,
    padded_shape,
    periodic_link_boxes,
    periodic_lists,
)
from couplekit.fluid.reference import equilibrium, to_stored

SHAPE = (6, 7, 9)  # (nz, ny, nx) interior

BOUNDARY_SETS = {
    "periodic": Boundaries(),
    "mixed": Boundaries(
        {
            "y-": Face("wall"),
            "y+": Face("wall", velocity=(0.03, 0.0, -0.01)),
            "z-": Face("inflow", velocity=(0.0, 0.01, 0.04), phi=1.0),
            "z+": Face("outflow"),
        }
    ),
}


def random_state(
    seed: int, boundaries: Boundaries, shape=SHAPE, obstacle: bool = True, solid: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Every array a fluid stage reads, float32 and padded, drawn from ``seed``; ``solid`` (interior shape)
    replaces the default obstacle (a small box, ``obstacle=True``).

    f (stored as f − w) is an equilibrium at a random velocity (|u| ≲ 0.05) plus 1e-3 noise; φ a diffuse sphere (width 4) with
    1e-2 noise, so a little outside [0, 1] as happens near interfaces; ε in [0.6, 1]; small pressure,
    chemical potential and forces.
    """
    rng = np.random.default_rng(seed)
    pshape = padded_shape(shape)
    if solid is None and obstacle:
        solid = np.zeros(shape, bool)
        solid[2:4, 3, 4:6] = True
    flags, wall_u, _ = build_flags(shape, boundaries, solid)
    u = rng.uniform(-0.05, 0.05, (3,) + pshape)
    f = equilibrium(u) * (1.0 + 1e-3 * rng.standard_normal((27,) + pshape))
    velocity = np.where(flags[None] == 0, rng.uniform(-0.05, 0.05, (3,) + pshape), wall_u)
    ghost, image = periodic_lists(shape, boundaries)
    links = link_box_arrays(periodic_link_boxes(shape, boundaries))
    out_ghost, out_src = outflow_lists(shape, flags)
    out_dir = outflow_directions(shape, out_ghost, boundaries.periodic_axes)
    state = {
        "f": to_stored(f),  # the fluid arrays hold f - w (shifted storage)
        "flags": flags,
        "velocity": velocity.astype(np.float32),
        "phi": _smooth_phi(rng, pshape).astype(np.float32),
        "mu": rng.uniform(-1e-3, 1e-3, pshape).astype(np.float32),  # drawn so the later arrays stay as they were
        "eps": rng.uniform(0.6, 1.0, pshape).astype(np.float32),
        "sand_v": rng.uniform(-0.02, 0.02, (3,) + pshape).astype(np.float32),
        "force": rng.uniform(-1e-4, 1e-4, (3,) + pshape).astype(np.float32),
        "p": rng.uniform(-1e-3, 1e-3, pshape).astype(np.float32),
        "pbar": rng.uniform(-1e-3, 1e-3, pshape).astype(np.float32),
        "ghost": ghost,
        "image": image,
        "links": links,
        "out_ghost": out_ghost,
        "out_src": out_src,
        "out_dir": out_dir,
    }
    # cells with the porosity-slip term of Eq. 39: a random half of the fluid cells (drawn last, so the other
    # arrays are those of earlier versions), for the kernels must follow whatever mask they are given
    state["slip"] = ((rng.random(pshape) < 0.5) & (flags == 0)).astype(np.uint8)
    # (beta, kappa) of Eq. 22 for sigma = 1e-3, W = 4 (chemical_potential_coefficients): the collide computes
    # mu_phi ~ 1e-3 from phi with them; the "mu" field above is not an input any more
    state["chem"] = np.array([3e-3, 6e-3])
    return state


def chem_of(ops, state):
    """The collide's ``chemical_potential`` argument for ``ops``: the state's (beta, kappa) with surface tension."""
    return state["chem"] if ops.surface_tension else None


def _smooth_phi(rng, pshape) -> np.ndarray:
    zz, yy, xx = np.meshgrid(*(np.arange(n, dtype=float) for n in pshape), indexing="ij")
    centre = [n / 2 + rng.uniform(-1, 1) for n in pshape]
    r = np.sqrt((zz - centre[0]) ** 2 + (yy - centre[1]) ** 2 + (xx - centre[2]) ** 2)
    return 0.5 * (1 + np.tanh(2 * (3.0 - r) / 4.0)) + 0.01 * rng.standard_normal(pshape)


JET_SHAPE, JET_SPEED = (8, 8, 32), 0.02


def water_jet_into_air(backend, eta: float = 0.0):
    """A FluidSolver of a water jet into air (800:1): inflow face x- carrying φ = 1 at u_in = 0.02, outflow x+,
    walls around, 8 × 8 × 32; it starts from a smooth water plug (tanh, ξ = 4) moving at u_in. ``eta``: the
    volume controller's bound."""
    from couplekit.fluid.solver import FluidParams, FluidSolver

    n, u_in = JET_SHAPE, JET_SPEED
    faces = {"x-": Face("inflow", velocity=(u_in, 0, 0), phi=1.0), "x+": Face("outflow")}
    faces.update({k: Face("wall") for k in ("y-", "y+", "z-", "z+")})
    params = FluidParams(rho_h=1.0, rho_l=1 / 800, nu_h=0.01, nu_l=0.01, sigma=1e-4, mobility=0.02, width=4.0, eta=eta)
    xc = np.arange(n[2]) + 0.5
    phi0 = np.broadcast_to(0.5 * (1 + np.tanh(2 * (6 - xc) / 4.0)), n).copy()
    vel0 = np.zeros((3,) + n)
    vel0[0] = u_in * phi0
    return FluidSolver(backend, n, params, Boundaries(faces), phi=phi0, velocity=vel0)
