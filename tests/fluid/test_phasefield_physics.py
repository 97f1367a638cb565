"""Phase-field validation: streaming convention, conservation, interface profile, advection, boundaries,
volume controller and the chemical potential, each against a closed-form answer with a stated tolerance.

All runs use the cpu backend with one OpenMP thread: the domains are tiny (<= 24^3 cells), where thread
start-up dominates and a loaded 2-core machine made two threads 10x slower than one.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import curve_fit

from couplekit.backend import get_backend
from couplekit.backend.errors import BackendUnavailableError
from couplekit.fluid.phasefield import (
    FLUID,
    INFLOW,
    OUTFLOW,
    PhaseFieldKernelOps,
    PhaseFieldReferenceOps,
    PhaseFieldRunner,
    chemical_potential_coefficients,
    continuum_coefficients,
    discrete_surface_tension_factor,
    pad_flags,
    padded_shape,
    relaxation_rate,
    tanh_profile,
    volume_controller_gamma,
)
from couplekit.lattice import C7, CS2_7, W7

OPP7 = np.array([0, 2, 1, 4, 3, 6, 5])
HALF_ULP_QUARTER = 2.0**-26  # half an ulp of a float32 in [0.25, 0.5): the rest population's rounding


@pytest.fixture(scope="module")
def cpu():
    try:
        return get_backend("cpu", threads=1)
    except BackendUnavailableError as exc:
        pytest.skip(str(exc))


def sphere(n: int, radius: float, width: float, centre=None) -> np.ndarray:
    """phi of a droplet (phase 1 inside) on an n^3 grid of cell centres."""
    c = np.full(3, n / 2) if centre is None else np.asarray(centre, dtype=float)
    z, y, x = np.meshgrid(*[np.arange(n) + 0.5] * 3, indexing="ij")
    r = np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)
    return tanh_profile(radius - r, width)


def population_sum(run: PhaseFieldRunner) -> float:
    """Sigma of all populations of interior fluid cells in float64, read from h at an even step.

    At an even AA parity every population of cell c is stored in c's own slots h[:, c], so this is the
    exact total the scheme must conserve (no float32 summation into phi in between).
    """
    assert run.step_count % 2 == 0
    h = run.to_host(run.h)[:, 1:-1, 1:-1, 1:-1].astype(np.float64)
    fluid = run.to_host(run.flags)[1:-1, 1:-1, 1:-1] == FLUID
    return float(h[:, fluid].sum())


# ------------------------------------------------------------------------------------ streaming convention
class TwoArrayPhaseField:
    """Textbook two-array D3Q7 scheme (pull streaming, halfway bounce-back), written independently of the
    in-place AA storage: f_q(x, t+1) = f*_q(x - d_q, t), or f*_opp(q)(x, t) when x - d_q is a wall."""

    def __init__(self, phi0, u, flags, periodic, mobility, width):
        self.u = u.astype(np.float64)
        self.flags, self.periodic = flags, periodic
        self.mobility, self.width = mobility, width
        inner = u[:, 1:-1, 1:-1, 1:-1].astype(np.float64)
        self.f = np.stack([W7[q] * phi0 * (1.0 + np.tensordot(C7[q], inner, axes=1) / CS2_7) for q in range(7)])
        self.ref = PhaseFieldReferenceOps(periodic, surface_tension=False)

    def phi_padded(self) -> np.ndarray:
        phi = self.f.sum(axis=0)
        for axis, per in enumerate(reversed(self.periodic)):  # (z, y, x) axes
            width = [(0, 0)] * 3
            width[axis] = (1, 1)
            phi = np.pad(phi, width, mode="wrap" if per else "edge")
        return phi

    def step(self) -> None:
        phi_p = self.phi_padded().astype(np.float32)
        grad = np.zeros((3, *phi_p.shape), np.float32)
        self.ref.gradients(phi_p, self.flags, grad, None, 0.0, 0.0)
        g = grad[:, 1:-1, 1:-1, 1:-1].astype(np.float64)
        phi = self.f.sum(axis=0)
        norm = np.sqrt((g * g).sum(axis=0))
        n = np.where(norm > 1e-6, g / np.maximum(norm, 1e-30), 0.0)
        H = 4.0 / self.width * phi * (1 - phi) * n
        omega = relaxation_rate(self.mobility)
        u = self.u[:, 1:-1, 1:-1, 1:-1]
        post = np.empty_like(self.f)
        for q in range(7):
            feq = W7[q] * phi * (1.0 + np.tensordot(C7[q], u, axes=1) / CS2_7)
            post[q] = self.f[q] - omega * (self.f[q] - feq) + (1 - omega / 2) * W7[q] * np.tensordot(C7[q], H, axes=1)
        fluid_pad = self.flags == FLUID
        new = np.empty_like(post)
        for q in range(7):
            dx, dy, dz = C7[q]
            src = post[q]
            for axis, d in ((2, dx), (1, dy), (0, dz)):
                if d:
                    src = np.roll(src, d, axis=axis)  # value from x - d_q, wrapped (walls are replaced below)
            # is x - d_q fluid?  The padded flags hold WALL on wall ghosts and the image's flag on periodic ones
            upstream_fluid = fluid_pad[
                1 - dz : fluid_pad.shape[0] - 1 - dz,
                1 - dy : fluid_pad.shape[1] - 1 - dy,
                1 - dx : fluid_pad.shape[2] - 1 - dx,
            ]
            new[q] = np.where(upstream_fluid, src, post[OPP7[q]])
        inner_fluid = fluid_pad[1:-1, 1:-1, 1:-1]
        self.f = np.where(inner_fluid[None], new, 0.0)


@pytest.mark.parametrize("periodic", [(True, True, True), (False, True, False), (False, False, False)])
def test_in_place_aa_matches_two_array_scheme(cpu, periodic):
    """The in-place AA storage with its wall rules must be a pure re-arrangement of the textbook scheme.

    Tolerance 2e-5 on phi after 21 steps: the kernel works in float32 (about 1e-7 relative per step and
    value), the textbook scheme in float64; a wrong slot or a missed bounce-back moves O(0.01-0.1).
    """
    shape = (6, 7, 8)
    rng = np.random.default_rng(3)
    solid = np.zeros(shape, bool)
    solid[2:4, 3, 4:6] = True
    phi0 = sphere(8, 2.5, 3.0, centre=(3.5, 4.0, 3.0))[: shape[0], : shape[1], : shape[2]]
    phi0 = np.where(solid, 0.0, phi0)
    u = np.zeros((3, *padded_shape(shape)), np.float32)
    u[:, 1:-1, 1:-1, 1:-1] = (rng.random((3, *shape)) - 0.5) * 0.06
    flags = pad_flags(solid, shape, periodic)
    run = PhaseFieldRunner(PhaseFieldKernelOps(cpu, periodic, False), phi0, mobility=0.08, width=3.0, flags=flags, u=u)
    book = TwoArrayPhaseField(phi0, u, flags, periodic, 0.08, 3.0)
    for _ in range(21):
        run.step()
        book.step()
    fluid = ~solid
    diff = np.abs(run.phi_host() - book.f.sum(axis=0))[fluid]
    assert diff.max() < 2e-5
    assert np.abs(book.f.sum(axis=0) - phi0)[fluid].max() > 0.05  # the state really moved


# ------------------------------------------------------------------------------------------ conservation
@pytest.mark.parametrize("periodic, obstacle", [(True, False), ((False, True, False), True), (False, True)])
def test_mass_is_conserved_to_round_off(cpu, periodic, obstacle):
    """Sigma phi with zero source, periodic faces, no-flux walls and an obstacle, 200 steps.

    The kernel balances each cell exactly in double (sum h* = sum h + S) and rounds only the rest
    population once (|h*_0| < 0.5), so the population total may change by at most
    steps * cells * half an ulp of [0.25, 0.5) = 200 * 4096 * 2^-26 ~ 1.2e-2 (of ~600); streaming and
    bounce-back move values without arithmetic.  A single lost population per step would be ~0.1.
    """
    n = 16
    phi0 = sphere(n, 4.5, 4.0, centre=(7.0, 8.5, 8.0))
    solid = None
    if obstacle:
        solid = np.zeros((n, n, n), bool)
        solid[10:14, 2:6, 10:14] = True
        phi0 = np.where(solid, 0.0, phi0)
    z, y, x = np.meshgrid(*[np.arange(n) + 0.5] * 3, indexing="ij")
    u = np.zeros((3, *padded_shape((n, n, n))), np.float32)
    u[0, 1:-1, 1:-1, 1:-1] = 0.05 * np.sin(2 * np.pi * y / n)  # sheared, divergent in places: mass still exact
    u[1, 1:-1, 1:-1, 1:-1] = 0.05 * np.cos(2 * np.pi * x / n) * np.sin(np.pi * z / n)
    run = PhaseFieldRunner(
        PhaseFieldKernelOps(cpu, periodic, True), phi0, mobility=0.05, width=4.0, sigma=1e-3, solid=solid, u=u
    )
    m0 = population_sum(run)
    run.step(200)
    m1 = population_sum(run)
    cells = int((run.to_host(run.flags)[1:-1, 1:-1, 1:-1] == FLUID).sum())
    assert abs(m1 - m0) <= 200 * cells * HALF_ULP_QUARTER
    assert abs(run.volume() - run.v0) <= 200 * cells * HALF_ULP_QUARTER + cells * 2.0**-24  # + phi rounding
    assert np.abs(run.phi_host() - phi0).max() > 0.05  # the droplet was advected


def test_reference_conserves_mass(cpu):
    """The NumPy reference (float64 arithmetic, float32 storage: 7 roundings per cell) over 40 steps:
    bound 40 * cells * 7 * 2^-26 (half an ulp of values < 0.5)."""
    n = 10
    phi0 = sphere(n, 3.0, 3.0)
    u = np.zeros((3, *padded_shape((n, n, n))), np.float32)
    u[0] = 0.03
    run = PhaseFieldRunner(PhaseFieldReferenceOps((False, True, True), False), phi0, mobility=0.05, width=3.0, u=u)
    m0 = population_sum(run)
    run.step(40)
    assert abs(population_sum(run) - m0) <= 40 * n**3 * 7 * HALF_ULP_QUARTER


# ------------------------------------------------------------------------------------ flat interface
def relaxed_flat_interface(cpu, width: float, mobility: float) -> tuple[float, float, np.ndarray]:
    """A 1-D interface between no-flux walls, started at 1.6x the target width, relaxed at rest.

    Returns (fitted width, fitted centre, phi).  6 W^2 / M steps: the width relaxes diffusively on the
    time scale W^2 / M, so the start error (60 %) decays by far more than the tolerances below.
    """
    nx = int(16 * width)
    x = np.arange(nx) + 0.5
    x0 = nx / 2 + 0.3
    phi0 = tanh_profile(x - x0, 1.6 * width)[None, None, :]
    run = PhaseFieldRunner(PhaseFieldKernelOps(cpu, (False, True, True), False), phi0, mobility=mobility, width=width)
    run.step(int(6 * width**2 / mobility))
    phi = run.phi_host()[0, 0]
    (centre, fitted), _ = curve_fit(lambda s, c, w: tanh_profile(s - c, w), x, phi, p0=(x0, width))
    return fitted, centre, phi


def test_flat_interface_relaxes_to_tanh_profile(cpu):
    """Steady profile = (1 + tanh(2 s / W)) / 2 with the requested W, independent of the mobility.

    * Width error: the scheme's truncation error is O((dx / W)^2) (second-order moments of D3Q7 and the
      27-point gradient), so it must be small at W = 4 and shrink about 4x from W = 4 to W = 8; we require
      |W_fit / W - 1| < 3 % at W = 4 (the note's target is 5 %) and a ratio > 2.5 (4 minus room for the
      higher-order terms; measured 3.5).
    * Mobility: with the (1 - omega/2) factor the recovered counter-flux is M H for every M, so the widths
      for M = 0.02 and 0.1 must agree to 0.5 %; without it the width would be W (tau - 1/2) / tau, i.e. 0.14 W
      and 0.44 W (notes §1c pitfall).
    * Profile: max |phi - tanh profile of width W| < 0.01 at W = 4 (measured 0.006): the same O((dx/W)^2) error.
    """
    w4_fast, c4, phi4 = relaxed_flat_interface(cpu, 4.0, 0.1)
    w4_slow, _, _ = relaxed_flat_interface(cpu, 4.0, 0.02)
    w8, _, _ = relaxed_flat_interface(cpu, 8.0, 0.1)
    assert abs(w4_fast / 4.0 - 1.0) < 0.03
    assert abs(w4_slow / w4_fast - 1.0) < 0.005
    assert abs(w4_fast / 4.0 - 1.0) / abs(w8 / 8.0 - 1.0) > 2.5
    x = np.arange(phi4.size) + 0.5
    assert np.abs(phi4 - tanh_profile(x - c4, 4.0)).max() < 0.01
    # the no-flux walls hold the two bulk phases: phi stays in [0, 1] up to round-off
    assert phi4.min() > -1e-6 and phi4.max() < 1 + 1e-6


# ------------------------------------------------------------------------------------ advection
def test_diagonally_translated_droplet_keeps_its_shape(cpu):
    """A droplet (R = 6, W = 4) carried by u = (U, U, U), U = 0.04, once around the periodic 24^3 box
    (600 steps, 41.6 cells travelled) against the same droplet left at rest for 600 steps.

    * mass exact (round-off bound as above);
    * centroid back at its start within 0.1 cells per axis (measured lag 0.032: a 0.1 % speed error from
      the O(u^2) terms of the first-order equilibrium along the lattice diagonal);
    * shape: max |phi_moved - phi_rest| < 0.06.  An interface shifted by d cells changes phi by at most
      d * max|grad phi| = d / W, so this bounds the local interface displacement by 0.24 cells after
      41.6 cells of travel (measured 0.044, i.e. 0.17 cells); the relative L1 difference stays < 5 %.
    """
    n, steps, speed = 24, 600, 0.04
    phi0 = sphere(n, 6.0, 4.0)
    ops = PhaseFieldKernelOps(cpu, True, False)
    rest = PhaseFieldRunner(ops, phi0, mobility=0.05, width=4.0)
    u = np.full((3, *padded_shape((n, n, n))), speed, np.float32)
    moved = PhaseFieldRunner(ops, phi0, mobility=0.05, width=4.0, u=u)
    m0 = population_sum(moved)
    rest.step(steps)
    moved.step(steps)
    assert abs(population_sum(moved) - m0) <= steps * n**3 * HALF_ULP_QUARTER
    a, b = rest.phi_host(), moved.phi_host()
    coords = np.meshgrid(*[np.arange(n) + 0.5] * 3, indexing="ij")
    centroid = np.array([(b * c).sum() / b.sum() for c in coords])
    assert np.abs(centroid - n / 2).max() < 0.1
    assert np.abs(a - b).max() < 0.06
    assert np.abs(a - b).sum() / a.sum() < 0.05
    # halfway round the box the droplet is really elsewhere (the check above is not trivially true)
    half = PhaseFieldRunner(ops, phi0, mobility=0.05, width=4.0, u=u)
    half.step(steps // 2)
    assert np.abs(half.phi_host() - a).max() > 0.9


# ------------------------------------------------------------------------------------ inflow / outflow
def test_inflow_fills_channel_and_outflow_lets_the_interface_leave(cpu):
    """Plug flow U = 0.05 along x from an INFLOW face carrying phi = 1 into a channel of phi = 0 that ends
    in an OUTFLOW face.  Closed form: the front (phi = 0.5) moves at exactly U; after it has left,
    phi = 1 everywhere.  Tolerances: front speed within 0.5 % (measured 0.002 %: pure advection of a
    steady profile), the profile's width within 5 % of W (as the flat-interface test), and phi = 1 to
    1e-5 once the front is out (no reflection or accumulation at the outflow: a reflected population would
    leave O(1e-2))."""
    nx, speed, width = 48, 0.05, 4.0
    shape = (1, 1, nx)
    flags = pad_flags(None, shape, (False, True, True))
    flags[:, :, 0] = INFLOW
    flags[:, :, -1] = OUTFLOW
    u = np.zeros((3, *padded_shape(shape)), np.float32)
    u[0] = speed
    ops = PhaseFieldKernelOps(cpu, (False, True, True), False)
    run = PhaseFieldRunner(ops, np.zeros(shape), mobility=0.05, width=width, flags=flags, u=u)
    run.phi[:, :, 0] = 1.0  # the phase value the inflow carries
    x = np.arange(nx) + 0.5

    def front() -> float:
        p = run.phi_host()[0, 0]
        i = int(np.argmax(p < 0.5))
        return x[i - 1] + (p[i - 1] - 0.5) / (p[i - 1] - p[i])

    run.step(200)
    f1 = front()
    run.step(400)
    f2 = front()
    assert (f2 - f1) / (400 * speed) == pytest.approx(1.0, abs=0.005)
    p = run.phi_host()[0, 0]
    (c, w), _ = curve_fit(lambda s, c, w: tanh_profile(c - s, w), x, p, p0=(f2, width))
    assert w == pytest.approx(width, rel=0.05)
    run.step(1400)  # the front left at step ~950
    assert np.abs(run.phi_host() - 1.0).max() < 1e-5


# ------------------------------------------------------------------------------------ volume controller
def test_source_changes_volume_by_its_sum(cpu):
    """Eq. 51: S_k = w_k S_phi has zeroth moment S_phi, so with the controller off one step changes
    Sigma phi by exactly Sigma S_phi (note §1g iv).  Tolerance: phi rounding (2^-24 per cell) plus the
    rest-population rounding (2^-26 per cell) per step, over 10 steps, = 0.7 % of Sigma S * 10 here."""
    n = 12
    run = PhaseFieldRunner(
        PhaseFieldKernelOps(cpu, (True, False, True), False), sphere(n, 3.5, 3.0), mobility=0.05, width=3.0
    )
    run.source[4:9, 3:7, 2:10] = 2e-3
    run.source[1:3, 1:3, 1:3] = -1e-3
    v0, s_sum = run.ops.volume_sums(run.phi, run.source, run.flags)
    run.step(10)
    assert run.volume() - v0 == pytest.approx(10 * s_sum, abs=10 * n**3 * (2.0**-24 + 2.0**-26))


def test_volume_controller_gamma_closed_form():
    assert volume_controller_gamma(10.0, 9.0, 0.5, 1.5) == 1.5  # clamped: wants 2
    assert volume_controller_gamma(10.0, 9.5, 0.5, 1.5) == pytest.approx(1.0)
    assert volume_controller_gamma(10.0, 10.5, 0.5, 1.5) == pytest.approx(-1.0)
    assert volume_controller_gamma(10.0, 12.0, 0.5, 1.5) == -1.5
    assert volume_controller_gamma(10.0, 9.0, 0.5, 0.0) == 1.0  # eta = 0: controller off, source as is
    assert volume_controller_gamma(10.0, 9.0, 0.0, 2.0) == 0.0  # nothing to scale
    with pytest.raises(ValueError):
        volume_controller_gamma(1.0, 1.0, 1.0, -1.0)


def test_volume_controller_restores_volume_at_predicted_rate(cpu):
    """A volume deficit D0 with source S_phi (sum s) and threshold eta: Eq. 52 predicts a change of
    gamma * s = min(D, eta s) per step, i.e. a linear recovery at eta * s per step, then an exact landing
    on V0.  The measured trajectory must follow the prediction step by step to the rounding bound of the
    source test (2^-24 + 2^-26 per cell and step, accumulated)."""
    n, eta = 12, 1.5
    ops = PhaseFieldKernelOps(cpu, True, False)
    run = PhaseFieldRunner(ops, sphere(n, 3.5, 3.0), mobility=0.05, width=3.0, eta=eta)
    run.source[3:9, 3:9, 3:9] = -1e-3 * run.phi[3:9, 3:9, 3:9]  # the shape of an Eq. 45 source (any sign)
    _, s_sum = ops.volume_sums(run.phi, run.source, run.flags)
    deficit = 12.3 * eta * abs(s_sum)
    run.v0 = run.volume() + deficit  # perturb: the target is above the current volume
    tol_step = n**3 * (2.0**-24 + 2.0**-26)
    predicted = run.volume()
    steps_needed = int(np.ceil(deficit / (eta * abs(s_sum))))
    for k in range(steps_needed + 3):
        _, s_now = ops.volume_sums(run.phi, run.source, run.flags)
        gamma = volume_controller_gamma(run.v0, predicted, s_now, eta)
        predicted += gamma * s_now
        run.step()
        assert run.volume() == pytest.approx(predicted, abs=(k + 1) * tol_step)
        if k < steps_needed - 1:
            assert abs(run.gamma) == eta  # clamped: recovering at the maximum rate eta * |sum S|
    assert run.volume() == pytest.approx(run.v0, abs=(steps_needed + 3) * tol_step)
    assert steps_needed == 13


# ------------------------------------------------------------------------------------ chemical potential
def flat_profile_fields(cpu, width: float, sigma: float):
    """phi = tanh profile along x (walls in x), and the kernels' grad phi and mu."""
    nx = int(12 * width)
    x = np.arange(nx) + 0.5
    phi_i = np.broadcast_to(tanh_profile(x - nx / 2, width), (3, 3, nx))
    shape = phi_i.shape
    flags = pad_flags(None, shape, (False, True, True))
    phi = np.zeros(padded_shape(shape), np.float32)
    phi[1:-1, 1:-1, 1:-1] = phi_i
    phi[1:-1, 1:-1, 0], phi[1:-1, 1:-1, -1] = phi_i[..., 0], phi_i[..., -1]
    phi[0], phi[-1] = phi[-2], phi[1]  # periodic y, z ghosts
    phi[:, 0], phi[:, -1] = phi[:, -2], phi[:, 1]
    beta, kappa = continuum_coefficients(sigma, width)  # the closed forms below are the continuum's
    grad = np.zeros((3, *phi.shape), np.float32)
    mu = np.zeros(phi.shape, np.float32)
    PhaseFieldKernelOps(cpu, (False, True, True), True).gradients(phi, flags, grad, mu, beta, kappa)
    return x, phi_i[1, 1], grad[:, 2, 2, 1:-1].astype(np.float64), mu[2, 2, 1:-1].astype(np.float64), kappa


def test_chemical_potential_vanishes_on_equilibrium_profile_and_gives_sigma(cpu):
    """Closed forms (Jacqmin 1999, beta = 12 sigma / W, kappa = 3 sigma W / 2): on the profile
    phi = (1 + tanh(2x/W))/2 the chemical potential (Eq. 22) vanishes and the excess free energy
    kappa * integral(phi_x^2) equals sigma.  Across a flat interface the 27-point stencils (Eqs. 21, 23)
    reduce to the 3-point central ones, whose leading errors are known in closed form:

    * lap = phi_xx + phi_xxxx / 12 + O(W^-6), so the discrete mu = -kappa phi_xxxx / 12 + O(W^-6) with
      phi_xxxx = (2/W)^4 T (1 - T^2)(16 - 24 T^2) / 2, T = tanh(2x/W).  Any error in beta, kappa, the
      double well or the Laplacian's weight leaves a residual of the order of the double-well scale
      24 sigma / W * 0.0962; we require the residual < 1 % of that scale at W = 5 (measured 0.4 %) and
      mu itself to shrink with W (ratio > 3 from W = 5 to 10, second order).
    * grad = phi_x + phi_xxx / 6 + ..., so kappa * sum(grad^2) / sigma - 1 = -(1/3) int phi_xx^2 / int
      phi_x^2 = -1.0667 / W^2 + O(W^-4) (-4.3 % at W = 5, -1.1 % at W = 10); we require agreement to 0.5 %.
    Evaluated away from the walls (the zero-gradient wall rule is not the profile)."""
    sigma = 0.01
    mu_sizes = []
    for width in (5.0, 10.0):
        x, phi, grad, mu, kappa = flat_profile_fields(cpu, width, sigma)
        inner = slice(int(2 * width), -int(2 * width))
        scale = 24 * sigma / width * 0.0962
        t = np.tanh(2 * (x - x.size / 2) / width)
        d4 = 0.5 * (2 / width) ** 4 * t * (1 - t**2) * (16 - 24 * t**2)
        assert np.abs(mu + kappa / 12 * d4)[inner].max() < 0.01 * scale
        mu_sizes.append(np.abs(mu[inner]).max())
        excess = kappa * (grad[0, inner] ** 2).sum() / sigma - 1.0
        assert excess == pytest.approx(-1.0667 / width**2, abs=0.005)
        assert np.abs(grad[1:]).max() < 1e-7  # no gradient along a flat interface
    assert mu_sizes[0] / mu_sizes[1] > 3


def test_coefficients_carry_the_lattice_surface_tension_correction():
    """chemical_potential_coefficients = the continuum (beta, kappa) over discrete_surface_tension_factor: both
    scaled alike (the width sqrt(8 kappa / beta) stays W), the factor the fitted 1 - 0.112/W - 0.897/W^2 at the
    measured widths (0.863, 0.912, 0.940, 0.956, 0.972 at W = 3, 4, 5, 6, 8, within 0.005), tending to 1."""
    measured = {3.0: 0.863, 4.0: 0.912, 5.0: 0.940, 6.0: 0.956, 8.0: 0.972}
    for width, s in measured.items():
        assert discrete_surface_tension_factor(width) == pytest.approx(s, abs=0.005)
        beta, kappa = chemical_potential_coefficients(0.01, width)
        b0, k0 = continuum_coefficients(0.01, width)
        assert beta / b0 == pytest.approx(kappa / k0) == pytest.approx(1 / discrete_surface_tension_factor(width))
        assert np.sqrt(8 * kappa / beta) == pytest.approx(width)
    assert discrete_surface_tension_factor(40.0) > 0.99
    assert discrete_surface_tension_factor(2.0) == discrete_surface_tension_factor(3.0)  # not extrapolated


def test_stencils_exact_on_polynomials(cpu):
    """Eq. 21 is exact for linear fields and Eq. 23 for quadratic ones (they are second-order central
    stencils): grad (a.x) = a, lap (x^2 + 2 y^2 - z^2) = 4, to float32 round-off (1e-4 on values ~10)."""
    n = 8
    shape = (n, n, n)
    z, y, x = np.meshgrid(*[np.arange(n + 2) - 0.5] * 3, indexing="ij")  # padded cell centres
    flags = np.zeros(padded_shape(shape), np.uint8)  # all FLUID: every neighbour value is used
    a = np.array([0.3, -0.2, 0.1])
    ops = PhaseFieldKernelOps(cpu, True, True)
    grad = np.zeros((3, *flags.shape), np.float32)
    mu = np.zeros(flags.shape, np.float32)
    linear = (a[0] * x + a[1] * y + a[2] * z).astype(np.float32)
    ops.gradients(linear, flags, grad, mu, 0.0, 1.0)
    assert np.abs(grad[:, 1:-1, 1:-1, 1:-1] - a[:, None, None, None]).max() < 1e-5
    quad = (0.1 * (x**2 + 2 * y**2 - z**2)).astype(np.float32)
    ops.gradients(quad, flags, grad, mu, 0.0, 1.0)  # beta = 0, kappa = 1: mu = -lap
    assert np.abs(mu[1:-1, 1:-1, 1:-1] + 0.4).max() < 1e-4
