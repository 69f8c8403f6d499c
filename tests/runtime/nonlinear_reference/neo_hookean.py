"""Static, geometrically nonlinear finite elements: P1 tetrahedra, hyperelastic.

Independent of palpate (no code shared): NumPy assembly, SciPy sparse LU.

Kinematics (total Lagrangian). Reference positions X, current positions x.
In a linear tetrahedron the shape-function gradients g_a = grad_X N_a are
constant: with D = [X1-X0, X2-X0, X3-X0] (as columns), the rows of D^-1 are
g_1, g_2, g_3 and g_0 = -(g_1 + g_2 + g_3). The deformation gradient is
F = sum_a x_a g_a^T, J = det F, and the element's volume V = det(D) / 6.

Laws (strain energy per reference volume, Lame coefficients from the
small-strain E and nu: mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)),
bulk modulus K = lambda + 2 mu / 3; both laws reduce to linear elasticity
with these E, nu for small strains):

  "neo-hookean" (default; Simo-Pister / Bonet-Wood compressible form)
      W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2,       I1 = tr(F^T F)
      P = mu (F - F^-T) + lambda ln J F^-T
  "ccx" (CalculiX's and Abaqus's NEO HOOKE with C10 = mu/2, D1 = 2/K:
      U = C10 (Ibar1 - 3) + (J - 1)^2 / D1, Ibar1 = J^(-2/3) I1)
      W = mu/2 (J^(-2/3) I1 - 3) + K/2 (J - 1)^2
      P = mu J^(-2/3) (F - I1/3 F^-T) + K (J - 1) J F^-T

  "svk" (St Venant-Kirchhoff, for comparison: not polyconvex, softens and
  fails in strong compression)
      W = lambda/2 (tr E)^2 + mu tr(E^2),   E = (F^T F - I) / 2
      P = F S,   S = lambda tr(E) I + 2 mu E

P is the first Piola-Kirchhoff stress. The internal (elastic) force on
vertex a is f_a = V P g_a: at equilibrium it is the external force applied
on the vertex, so on an imposed vertex it is the force the grasp exerts on
the body. The consistent tangent is K_(a i)(b k) = V g_aJ A_iJkL g_bL with
A = dP/dF (written out in `_stress_and_tangent`, checked by finite
differences in `check_tangent`).

Newton's method with a line search solves f_free(x) = 0 at each imposed
position of the Dirichlet vertices (fixed: zero displacement; grasped:
imposed positions), stepping the load parameter in increments that halve
on failure.
"""

import math
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

LAWS = ("neo-hookean", "ccx", "svk")


def lame(young_modulus_pa, poisson_ratio):
    """(mu, lambda) in Pa from the small-strain E (Pa) and nu."""
    e, nu = young_modulus_pa, poisson_ratio
    return e / (2 * (1 + nu)), e * nu / ((1 + nu) * (1 - 2 * nu))


def boundary_vertices(tets):
    """Sorted indices of the vertices of the faces that belong to exactly one tetrahedron."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]])
    faces = np.sort(faces, axis=1)
    uniq, counts = np.unique(faces, axis=0, return_counts=True)
    return np.unique(uniq[counts == 1])


def _stress_and_tangent(F, mu, lam, law, want_tangent=True):
    """Energy density W [T], stress P [T,3,3] and A = dP/dF [T,3,3,3,3] (indices i,J,k,L).

    Elements with J <= 0 get W = inf (the line search rejects them)."""
    J = np.linalg.det(F)
    bad = ~(J > 0)
    Jsafe = np.where(bad, 1.0, J)
    FiT = np.transpose(np.linalg.inv(np.where(bad[:, None, None], np.eye(3), F)), (0, 2, 1))
    I1 = np.einsum("tij,tij->t", F, F)
    if want_tangent:
        dd = np.einsum("ik,JL->iJkL", np.eye(3), np.eye(3))[None]
        a_il_kj = np.einsum("tiL,tkJ->tiJkL", FiT, FiT)  # FiT_iL FiT_kJ
        a_ij_kl = np.einsum("tiJ,tkL->tiJkL", FiT, FiT)  # FiT_iJ FiT_kL
    if law == "neo-hookean":
        lnJ = np.log(Jsafe)
        W = mu / 2 * (I1 - 3) - mu * lnJ + lam / 2 * lnJ**2
        P = mu * (F - FiT) + (lam * lnJ)[:, None, None] * FiT
        if want_tangent:
            A = mu * dd + (mu - lam * lnJ)[:, None, None, None, None] * a_il_kj + lam * a_ij_kl
    elif law == "ccx":
        kappa = lam + 2 * mu / 3
        Jm = Jsafe ** (-2.0 / 3.0)
        W = mu / 2 * (Jm * I1 - 3) + kappa / 2 * (Jsafe - 1) ** 2
        c = lambda s: s[:, None, None]  # noqa: E731
        C = lambda s: s[:, None, None, None, None]  # noqa: E731
        P = mu * c(Jm) * (F - c(I1 / 3) * FiT) + kappa * c((Jsafe - 1) * Jsafe) * FiT
        if want_tangent:
            F_ij_FiT_kl = np.einsum("tiJ,tkL->tiJkL", F, FiT)
            FiT_ij_F_kl = np.einsum("tiJ,tkL->tiJkL", FiT, F)
            A = (
                mu * C(Jm) * (dd - 2.0 / 3.0 * F_ij_FiT_kl)
                - mu / 3 * C(Jm) * (-2.0 / 3.0 * C(I1) * a_ij_kl + 2 * FiT_ij_F_kl - C(I1) * a_il_kj)
                + kappa * (C(2 * Jsafe**2 - Jsafe) * a_ij_kl - C(Jsafe**2 - Jsafe) * a_il_kj)
            )
    elif law == "svk":
        Egl = 0.5 * (np.einsum("tki,tkj->tij", F, F) - np.eye(3))
        trE = np.trace(Egl, axis1=1, axis2=2)
        W = lam / 2 * trE**2 + mu * np.einsum("tij,tij->t", Egl, Egl)
        S = (lam * trE)[:, None, None] * np.eye(3) + 2 * mu * Egl
        P = np.einsum("tiM,tMJ->tiJ", F, S)
        if want_tangent:
            # dP_iJ/dF_kL = delta_ik S_JL + F_iM C_MJNL F_kN,
            # C_MJNL = lambda delta_MJ delta_NL + mu (delta_MN delta_JL + delta_ML delta_JN)
            A = (
                np.einsum("ik,tJL->tiJkL", np.eye(3), S)
                + lam * np.einsum("tiJ,tkL->tiJkL", F, F)
                + mu * np.einsum("tiN,tkN,JL->tiJkL", F, F, np.eye(3))
                + mu * np.einsum("tiL,tkJ->tiJkL", F, F)
            )
        # SVK has finite energy for J <= 0; keep inverted elements out all the same.
    else:
        raise ValueError(f"unknown law {law!r}; accepted: {', '.join(LAWS)}")
    W = np.where(bad, np.inf, W)
    return W, P, (A if want_tangent else None)


class Solid:
    """A P1 tetrahedral body with one hyperelastic material.

    vertices: [V,3] reference positions, m. tets: [T,4] vertex indices,
    positively oriented (checked)."""

    def __init__(self, vertices, tets, young_modulus_pa, poisson_ratio, law="neo-hookean"):
        if law not in LAWS:
            raise ValueError(f"unknown law {law!r}; accepted: {', '.join(LAWS)}")
        self.X = np.asarray(vertices, dtype=float)
        self.tets = np.asarray(tets, dtype=np.int64)
        self.law = law
        self.mu, self.lam = lame(young_modulus_pa, poisson_ratio)
        p = self.X[self.tets]
        D = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # columns
        detD = np.linalg.det(D)
        if not np.all(detD > 0):
            t = int(np.argmin(detD))
            raise ValueError(f"tetrahedron {t} is not positively oriented (6V = {detD[t]:.3g} m^3)")
        self.volume = detD / 6.0
        Dinv = np.linalg.inv(D)  # rows are g_1, g_2, g_3
        g0 = -Dinv.sum(axis=1, keepdims=True)
        self.g = np.concatenate([g0, Dinv], axis=1)  # [T,4,3]
        dofs = (3 * self.tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, 12)
        self.dofs = dofs
        self.rows = np.repeat(dofs, 12, axis=1).ravel()
        self.cols = np.tile(dofs, (1, 12)).ravel()
        self.ndof = 3 * len(self.X)

    def deformation_gradient(self, x):
        return np.einsum("tai,taJ->tiJ", x[self.tets], self.g)

    def energy(self, x):
        W, _, _ = _stress_and_tangent(self.deformation_gradient(x), self.mu, self.lam, self.law, False)
        return float(np.sum(self.volume * W))

    def forces(self, x, want_tangent=True):
        """(energy, internal force [3V], tangent (CSR, 3V x 3V) or None) at positions x [V,3]."""
        F = self.deformation_gradient(x)
        W, P, A = _stress_and_tangent(F, self.mu, self.lam, self.law, want_tangent)
        fe = self.volume[:, None, None] * np.einsum("tiJ,taJ->tai", P, self.g)
        f = np.bincount(self.dofs.ravel(), weights=fe.reshape(-1), minlength=self.ndof)
        K = None
        if want_tangent:
            ke = self.volume[:, None, None, None, None] * np.einsum("taJ,tiJkL,tbL->taibk", self.g, A, self.g, optimize=True)
            K = sp.csr_matrix((ke.reshape(-1), (self.rows, self.cols)), shape=(self.ndof, self.ndof))
        return float(np.sum(self.volume * W)), f, K


def check_tangent(law="neo-hookean", seed=1):
    """(A against central differences of P, P against central differences of W): largest relative errors."""
    rng = np.random.default_rng(seed)
    F = np.eye(3)[None] + 0.3 * rng.standard_normal((4, 3, 3))
    F[np.linalg.det(F) < 0] *= -1
    mu, lam = lame(20e3, 0.45)
    _, P, A = _stress_and_tangent(F, mu, lam, law)
    h = 1e-6
    num = np.zeros_like(A)
    for k in range(3):
        for L in range(3):
            Fp, Fm = F.copy(), F.copy()
            Fp[:, k, L] += h
            Fm[:, k, L] -= h
            num[:, :, :, k, L] = (_stress_and_tangent(Fp, mu, lam, law, False)[1] - _stress_and_tangent(Fm, mu, lam, law, False)[1]) / (2 * h)
    # P against the energy as well
    numP = np.zeros_like(P)
    for k in range(3):
        for L in range(3):
            Fp, Fm = F.copy(), F.copy()
            Fp[:, k, L] += h
            Fm[:, k, L] -= h
            numP[:, k, L] = (_stress_and_tangent(Fp, mu, lam, law, False)[0] - _stress_and_tangent(Fm, mu, lam, law, False)[0]) / (2 * h)
    return float(np.max(np.abs(num - A)) / np.max(np.abs(A))), float(np.max(np.abs(numP - P)) / np.max(np.abs(P)))


class NotConverged(RuntimeError):
    pass


def newton(solid, x, free, tol_force, max_iter=40, log=None):
    """Equilibrate the free DOFs of positions x [V,3] (modified in place).

    free: boolean mask [3V]. Converged when the largest free residual is
    below tol_force (N). Returns the number of tangent solves."""
    xf = x.reshape(-1)
    E0, f, _ = solid.forces(x, want_tangent=False)
    for it in range(max_iter + 1):
        r = f[free]
        rnorm = np.max(np.abs(r))
        if log:
            log(f"    it {it}: |r|max = {rnorm:.3e} N, energy = {E0:.9e} J")
        if rnorm < tol_force:
            return it
        if it == max_iter:
            break
        _, _, K = solid.forces(x)
        try:
            dx = spla.splu(K[free][:, free].tocsc(), permc_spec="COLAMD").solve(-r)
        except RuntimeError as e:  # singular tangent
            raise NotConverged(f"singular tangent: {e}")
        # Backtracking: Armijo on the energy when dx is a descent direction,
        # else (tangent not positive definite) any finite step that lowers the residual.
        slope = float(r @ dx)
        alpha = 1.0
        base = xf[free].copy()
        for _ in range(30):
            xf[free] = base + alpha * dx
            E1, f1, _ = solid.forces(x, want_tangent=False)
            if math.isfinite(E1):
                if slope < 0 and E1 <= E0 + 1e-4 * alpha * slope:
                    break
                if slope >= 0 and np.max(np.abs(f1[free])) < rnorm:
                    break
                # Round-off floor: the energy cannot resolve the last digits.
                if np.max(np.abs(f1[free])) < 1e-3 * rnorm:
                    break
            alpha *= 0.5
        else:
            xf[free] = base
            raise NotConverged("line search failed")
        E0, f = E1, f1
    raise NotConverged(f"no convergence in {max_iter} iterations")


def solve_path(solid, fixed, grasped, target, params, step=None, max_step=None, tol_force=1e-10, log=None):
    """Follow the imposed motion and return the reactions at the requested parameters.

    fixed, grasped: vertex index arrays (disjoint). target(s) -> [len(grasped),3]
    positions of the grasped vertices at load parameter s (target(0) = rest).
    params: increasing parameters (e.g. angles in rad) at which to report.
    step: the initial increment (default: the first parameter, at most max_step);
    max_step: the largest increment (default: 1/12 of the last parameter).
    Returns a list of dicts: param, force (the sum over the grasped vertices
    of the force on the body, N), iterations, steps, seconds."""
    x = solid.X.copy()
    free = np.ones(solid.ndof, dtype=bool)
    for v in np.concatenate([fixed, grasped]):
        free[3 * v : 3 * v + 3] = False
    gd = (3 * np.asarray(grasped)[:, None] + np.arange(3)).ravel()
    s = 0.0
    params = list(params)
    hmax = max_step if max_step else params[-1] / 12
    h = step if step else min(params[0], hmax)
    out = []
    t0 = time.perf_counter()
    total_it, nsteps = 0, 0
    while params:
        s_next = min(s + h, params[0])
        # Predictor: the tangent (linearized) response to the grasped vertices'
        # increment, from the converged state x.
        x_try = x.copy()
        dg = (target(s_next) - x[grasped]).reshape(-1)
        _, _, K = solid.forces(x)
        dxf = spla.splu(K[free][:, free].tocsc(), permc_spec="COLAMD").solve(-(K[free][:, gd] @ dg))
        x_try.reshape(-1)[free] += dxf
        x_try[grasped] = target(s_next)
        try:
            if not np.isfinite(solid.energy(x_try)):
                x_try = x.copy()
                x_try[grasped] = target(s_next)
                if not np.isfinite(solid.energy(x_try)):
                    raise NotConverged("imposed step inverts an element")
            it = newton(solid, x_try, free, tol_force, log=log)
        except NotConverged as e:
            if log:
                log(f"  step to {s_next:.5g} failed ({e}); halving")
            h /= 2
            if h < 1e-7 * params[-1]:
                raise
            continue
        total_it += it
        nsteps += 1
        x, s = x_try, s_next
        if log:
            log(f"  s = {s:.6g}: {it} Newton iterations")
        if s == params[0]:
            f = solid.forces(x, False)[1]
            force = f[gd].reshape(-1, 3).sum(axis=0)
            out.append(dict(param=s, force=force, iterations=total_it, steps=nsteps, seconds=time.perf_counter() - t0, x=x.copy()))
            params.pop(0)
        h = min(h * (1.5 if it <= 4 else 1.0), hmax)
    return out


def linear_reaction(solid, fixed, grasped, d):
    """Small-strain FE: the summed force on the grasped vertices for imposed displacements d [n,3],
    the other vertices force-free (the tangent at the reference state is linear elasticity)."""
    _, _, K = solid.forces(solid.X.copy())
    free = np.ones(solid.ndof, dtype=bool)
    for v in np.concatenate([fixed, grasped]):
        free[3 * v : 3 * v + 3] = False
    gd = (3 * np.asarray(grasped)[:, None] + np.arange(3)).ravel()
    u = np.zeros(solid.ndof)
    u[gd] = np.asarray(d).ravel()
    rhs = -(K[free][:, gd] @ u[gd])
    u[free] = spla.splu(K[free][:, free].tocsc(), permc_spec="COLAMD").solve(rhs)
    f = K @ u
    return f[gd].reshape(-1, 3).sum(axis=0)
