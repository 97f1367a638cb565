"""Constitutive model: yield surface after return mapping, no tension without cohesion, the hardening
curve, the cohesion trapezoid, the volume-correction cycle, the viscous overstress.  Run on the kernel (cpu
build); the kernel is checked against the NumPy reference in test_kernels_vs_reference.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from couplekit.sand import SandParams
from couplekit.sand.params import dp_alpha


def _trial_states(rng, n, scale):
    q_rot, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q_rot *= np.sign(np.linalg.det(q_rot))[:, None, None]
    stretch = np.exp(rng.normal(scale=scale, size=(n, 3)))
    F = (q_rot * stretch[:, None, :]) @ np.swapaxes(q_rot, 1, 2)
    return np.ascontiguousarray(F.reshape(n, 9).T.astype(np.float32))


def _principal_tau(tau):
    t = np.empty((tau.shape[1], 3, 3))
    for k, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))):
        t[:, i, j] = t[:, j, i] = tau[k]
    return np.linalg.eigvalsh(t)


@pytest.mark.parametrize("cohesion_max", [0.0, 3000.0])
def test_stress_on_or_inside_yield_surface(kops, cohesion_max):
    """y = alpha(q_old) tr(tau) + ||dev tau|| - c_C(S) <= 0 after the return mapping (Eq. 28 on tau).

    Tolerance: tau is rebuilt from float32 log-strains (relative error ~1e-6 of |tau|, the strains here
    reach 10 %, |tau| ~ 5e4 Pa), so y <= 1e-4 * max|tau| + 1e-3 * c_max.
    """
    params = SandParams(cohesion_max=cohesion_max)
    model = params.model()
    rng = np.random.default_rng(7)
    n = 20000
    F = _trial_states(rng, n, 0.05)
    q = (10 * rng.random(n)).astype(np.float32)
    vc = np.zeros(n, np.float32)
    sat = (0.4 * rng.random(n)).astype(np.float32)
    tau = np.zeros((6, n), np.float32)
    q_old = q.copy()
    kops.constitutive(F, tau, q, vc, sat, model)
    lam = _principal_tau(tau.astype(np.float64))
    tr = lam.sum(axis=1)
    dev = np.linalg.norm(lam - tr[:, None] / 3, axis=1)
    alpha = dp_alpha(model.friction_angle(q_old))
    y = alpha * tr + dev - model.cohesion_of(sat)
    tol = 1e-4 * np.abs(lam).max() + 1e-3 * cohesion_max
    assert np.max(y) <= tol
    # and the projection was exercised: many states were plastic (q grew), some were elastic
    assert np.mean(q > q_old) > 0.3 and np.mean(q == q_old) > 0.05
    if cohesion_max == 0:
        # cohesionless sand holds no tension: the mean stress is never tensile
        assert np.max(tr) <= tol


def test_pure_expansion_is_stress_free(kops):
    model = SandParams(cohesion_max=0.0).model()
    n = 3
    F = np.ascontiguousarray(
        np.stack([1.01 * np.eye(3), np.diag([1.2, 1.0, 1.0]), np.diag([1.05, 1.05, 0.99])])
        .reshape(n, 9)
        .T.astype(np.float32)
    )
    tau = np.ones((6, n), np.float32)
    q = np.zeros(n, np.float32)
    vc = np.zeros(n, np.float32)
    kops.constitutive(F, tau, q, vc, np.zeros(n, np.float32), model)
    assert np.all(tau == 0)
    assert np.allclose(F, np.eye(3).reshape(9, 1), atol=1e-6)
    assert np.all(q > 0)


def test_hardening_curve():
    """phi_F(q) = h0 + (h1 q - h3) exp(-h2 q) with paper 000's h0=35, h1=9, h2=0.2, h3=10 (degrees):
    25 deg at q = 0, a peak of 48.3 deg at q* = (h1 + h2 h3)/(h1 h2) = 6.11, 35 deg as q -> inf
    (notes Sec. 2.3 table); alpha(0) = 0.2678 (the value Taichi re-implementations start from)."""
    model = SandParams().model()
    q = np.linspace(0, 200, 200001)
    phi = np.degrees(model.friction_angle(q))
    assert phi[0] == pytest.approx(25.0, abs=1e-9)
    assert q[np.argmax(phi)] == pytest.approx((9 + 0.2 * 10) / (9 * 0.2), abs=1e-3)
    assert phi.max() == pytest.approx(48.3, abs=0.05)
    assert phi[-1] == pytest.approx(35.0, abs=1e-6)
    assert dp_alpha(math.radians(25.0)) == pytest.approx(0.267765, abs=1e-6)
    assert dp_alpha(math.radians(35.0)) == pytest.approx(0.3860, abs=1e-4)


def test_cohesion_trapezoid():
    model = SandParams(cohesion_max=800.0, cohesion_s1=0.05, cohesion_s2=0.18, cohesion_s3=0.36).model()
    s = np.array([0.0, 0.025, 0.05, 0.1, 0.18, 0.27, 0.36, 0.5])
    assert np.allclose(model.cohesion_of(s), [0, 400, 800, 800, 800, 400, 0, 0])
    assert np.all(SandParams(cohesion_max=0.0).model().cohesion_of(s) == 0)


def test_volume_correction_cycle(kops):
    """Expand 10 % per axis (to the apex: F -> I, v_c = 3 ln 1.1), recompress by 1/1.05 per axis (still
    looser than the original state: F stays I, v_c drops by 3 ln 1.05), then by 1/1.1 (now 1/1.05 per
    axis denser than the original, unexpanded state: that compression is elastic, F = I/1.05, v_c -> 0 —
    the stored expansion is spent, so loose sand does not gain volume).  float32 logs:
    1e-6."""
    model = SandParams(cohesion_max=0.0).model()

    def step(F, vc):
        tau = np.zeros((6, 1), np.float32)
        q = np.zeros(1, np.float32)
        Fa = np.ascontiguousarray(F.reshape(9, 1).astype(np.float32))
        kops.constitutive(Fa, tau, q, vc, np.zeros(1, np.float32), model)
        return Fa.reshape(3, 3).astype(np.float64)

    vc = np.zeros(1, np.float32)
    F = step(1.1 * np.eye(3), vc)
    assert np.allclose(F, np.eye(3), atol=1e-6) and vc[0] == pytest.approx(3 * math.log(1.1), abs=1e-6)
    F = step(F / 1.05, vc)
    assert np.allclose(F, np.eye(3), atol=1e-6)
    assert vc[0] == pytest.approx(3 * math.log(1.1) - 3 * math.log(1.05), abs=1e-6)
    F = step(F / 1.1, vc)
    assert np.allclose(F, np.eye(3) / 1.05, atol=1e-6)
    assert vc[0] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("cohesion_max", [0.0, 3000.0])
def test_hardening_counts_plastic_flow_not_stored_volume_gain(kops, rops, cohesion_max):
    """q accumulates plastic strain (Klár 2016): a loose particle (stored expansion v_c = 0.05) at rest in
    its apex state gains no hardening, however many steps it sits there; before the fix q grew by
    v_c/sqrt(3) = 0.029 per step (a resting column's mean q climbed from 3 to 9 in 0.15 s and its friction
    angle past the 48 deg peak).  A fresh expansion F = 1.01 I from the apex still counts its strain:
    dq = ||ln 1.01 (1, 1, 1)|| = sqrt(3) ln 1.01.  Kernel and reference.  Tolerances: one step 1e-6
    (float32 logs); 50 steps 5e-5 (each float32 SVD + log round trip moves ln sigma by a few 1e-7, and
    q, v_c add them up), against the 50 x 0.029 = 1.4 of the bug."""
    model = SandParams(cohesion_max=cohesion_max).model()
    sat = np.full(1, 0.1, np.float32)
    dc = float(model.cohesion_of(sat)[0]) / (3 * dp_alpha(model.h0 - model.h3) * (3 * model.lam + 2 * model.mu))
    for ops in (kops, rops):
        vc = np.full(1, 0.05, np.float32)
        q = np.zeros(1, np.float32)
        for _ in range(50):
            F = np.ascontiguousarray((math.exp(dc) * np.eye(3)).reshape(9, 1).astype(np.float32))
            ops.constitutive(F, np.zeros((6, 1), np.float32), q, vc, sat, model)
        assert q[0] == pytest.approx(0.0, abs=5e-5)
        assert vc[0] == pytest.approx(0.05, abs=5e-5)
        q[0] = 0.0
        F = np.ascontiguousarray((1.01 * math.exp(dc) * np.eye(3)).reshape(9, 1).astype(np.float32))
        ops.constitutive(F, np.zeros((6, 1), np.float32), q, vc, sat, model)
        assert q[0] == pytest.approx(math.sqrt(3) * math.log(1.01), abs=2e-6)


def _sheared_overstress(ops, viscosity: float, dt: float, rate: float = 20.0, steps: int = 300) -> float:
    """Steady simple shear (v_x = rate z) of a particle under a mean compression of 1e-3 per axis, one
    constitutive update per step of ``dt``: the deviatoric Kirchhoff stress beyond the 20 deg cone,
    ||dev tau|| + alpha tr tau (Pa), averaged over the last 50 steps."""
    model = SandParams(hardening=False, h0=20.0, cohesion_max=0.0, volume_correction=False, viscosity=viscosity).model()
    F = np.diag(np.full(3, math.exp(-1e-3)))
    step = np.eye(3)
    step[0, 2] = dt * rate  # F_trial = (I + dt L) F
    vc = np.zeros(1, np.float32)
    excess = []
    for _ in range(steps):
        Ft = np.ascontiguousarray((step @ F).reshape(9, 1).astype(np.float32))
        tau = np.zeros((6, 1), np.float32)
        ops.constitutive(Ft, tau, None, vc, None, model, dt)
        F = Ft.reshape(3, 3).astype(np.float64)
        t = tau[:, 0].astype(np.float64)
        tr = t[:3].sum()
        dev = np.linalg.norm(np.concatenate([t[:3] - tr / 3, math.sqrt(2.0) * t[3:]]))
        excess.append(dev + float(dp_alpha(math.radians(20.0))) * tr)
    return float(np.mean(excess[-50:]))


@pytest.mark.parametrize("dt", [5e-5, 2e-4])
def test_viscous_overstress_is_eta_times_shear_rate_at_any_dt(kops, rops, dt):
    """SandParams.viscosity (Duvaut-Lions): in steady plastic shear the stress stays outside the cone by
    2 eta D, i.e. ||dev tau|| exceeds the cone by sqrt(2) eta rate in simple shear, whatever the step (here
    dt = 5e-5 and 2e-4 s, keep = 0.82 and 0.95 at eta = 1.5 Pa s); the kernel and the reference agree; without
    viscosity the stress sits on the cone (measured 42.41-42.43 Pa against sqrt(2) eta rate = 42.43 Pa)."""
    eta, rate = 1.5, 20.0
    for ops in (kops, rops):
        assert _sheared_overstress(ops, eta, dt, rate) == pytest.approx(math.sqrt(2.0) * eta * rate, rel=0.01)
        assert abs(_sheared_overstress(ops, 0.0, dt, rate)) < 0.5  # Pa, against a cone of ~560 Pa
