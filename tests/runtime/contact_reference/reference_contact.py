#!/usr/bin/python3
"""A finite-element contact solution of a rigid sphere pressed into an organ,
written from the physics in numpy/scipy: it shares no code with palpate.

The problem (docs/model/contact-reference.md, "An independent check of the contact"): the
organ is the tetrahedral mesh of a compliance file, linear elastic on P1
tetrahedra (E, nu per tetrahedron), its attached vertices fixed. A rigid,
frictionless sphere of radius r, centre c, is pushed into it. The
displacement u minimizes the elastic energy 1/2 u^T K u subject to the
deformed surface staying outside the sphere:

    |y - c| >= r  for every point y of every deformed surface triangle.

Each surface triangle is sampled on a barycentric lattice of level s (its
vertices, points on its edges, points inside; shared points kept once);
sample i is x_i + u_i = sum_k w_ik (X_k + U_k). With the outward normal of
the sphere at the sample, n_i = (y_i - c) / |y_i - c|, held fixed, the
condition becomes linear, n_i . (x_i + u_i - c) >= r (the tangent plane of
the sphere bounds it, so this is never weaker than |y_i - c| >= r), and the
normals are re-estimated from the solution until they stop changing (a
fixed point). Depths are taken in order, each starting from the previous
one's deformed surface.

Each linearized problem is solved exactly. Only the vertices of the
triangles near the sphere carry forces; their compliance block
C = E^T K^-1 E (E selects their degrees of freedom) comes from one sparse LU
factorization of K (scipy's SuperLU) and one solve per column. With
C = R R^T and u = R v, the problem is the least-distance program

    minimize |v|^2  subject to  (H R) v >= b,    b_i = r - n_i . (x_i - c)

(H: rows n_i^T w_ik over the vertices), solved by Lawson and Hanson's
reduction to non-negative least squares (Solving Least Squares Problems,
1974, ch. 23): y = NNLS([ (HR)^T ; b^T ], [0 ... 0 1]), then
lambda = y / (1 - b.y) >= 0 are the contact forces (N), u = C H^T lambda.
The total force on the organ is sum_i lambda_i n_i.

Checks reported with each answer: the fixed-point iterations, the largest
linearized gap violation and complementarity product, the deepest
penetration of the sphere into the exactly computed deformed triangles
(closest point of each triangle, between the samples), and the agreement of
C with the stored compliance G on the same vertices (the same model).

Usage: reference_contact.py MODEL.h5 --point X,Y,Z --normal NX,NY,NZ
           --radius-mm R --depths-mm 1,2,3 [--level 8] [--json OUT]
           [--palpate build/tests/palpate_sphere_press]  (also palpate's answer, and a table)
"""
import argparse
import json
import subprocess
import sys

import h5py
import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse
import scipy.sparse.linalg


# ---- the organ ---------------------------------------------------------------------

class Organ:
    """The mesh, materials and attachment of a compliance file, and its
    stiffness K over the free degrees of freedom (3 per free vertex)."""

    def __init__(self, path):
        with h5py.File(path, "r") as f:
            self.X = f["mesh/vertices"][()]                      # (V, 3) m
            self.tets = f["mesh/tetrahedra"][()].astype(np.int64)  # (T, 4)
            material = f["mesh/tetrahedron_material"][()]
            E = f["material/young_modulus_pa"][()][material]     # (T,) Pa
            nu = f["material/poisson_ratio"][()][material]
            fixed = f["mesh/fixed_vertex_ids"][()]
            self.compliance_ids = f["compliance/vertex_ids"][()]
        self.path = path
        V = len(self.X)
        self.fixed = np.zeros(V, bool)
        self.fixed[fixed] = True
        # Free vertex v owns DOFs 3 dof_vertex[v] + (0, 1, 2); fixed ones none.
        self.dof_vertex = np.full(V, -1, np.int64)
        free = np.flatnonzero(~self.fixed)
        self.dof_vertex[free] = np.arange(len(free))
        self.ndof = 3 * len(free)
        self.K = self._stiffness(E, nu)
        self.lu = scipy.sparse.linalg.splu(self.K, permc_spec="MMD_AT_PLUS_A",
                                           diag_pivot_thresh=0.0,
                                           options={"SymmetricMode": True})
        self.triangles = self._boundary()
        self._columns = {}

    def _stiffness(self, E, nu):
        """K = sum over tetrahedra of V B^T D B (engineering strains
        exx, eyy, ezz, gyz, gxz, gxy; D isotropic with the Lame moduli)."""
        P = self.X[self.tets]                                   # (T, 4, 3)
        A = np.concatenate([np.ones((len(P), 4, 1)), P], axis=2)  # rows [1 x y z]
        volume = np.abs(np.linalg.det(A)) / 6
        # Column i of A^-1 holds the coefficients of barycentric coordinate i:
        # its gradient is rows 1..3.
        grad = np.linalg.inv(A)[:, 1:, :]                       # (T, 3, 4)
        T = len(P)
        B = np.zeros((T, 6, 12))
        for i in range(4):
            gx, gy, gz = grad[:, 0, i], grad[:, 1, i], grad[:, 2, i]
            c = 3 * i
            B[:, 0, c] = gx
            B[:, 1, c + 1] = gy
            B[:, 2, c + 2] = gz
            B[:, 3, c + 1], B[:, 3, c + 2] = gz, gy
            B[:, 4, c], B[:, 4, c + 2] = gz, gx
            B[:, 5, c], B[:, 5, c + 1] = gy, gx
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))
        mu = E / (2 * (1 + nu))
        D = np.zeros((T, 6, 6))
        D[:, :3, :3] = lam[:, None, None]
        for a in range(3):
            D[:, a, a] += 2 * mu
            D[:, 3 + a, 3 + a] = mu
        Ke = volume[:, None, None] * np.einsum("tki,tkl,tlj->tij", B, D, B)
        dof = (3 * self.dof_vertex[self.tets][:, :, None] + np.arange(3)).reshape(T, 12)
        dof[np.repeat(self.fixed[self.tets], 3, axis=1)] = -1
        rows = np.broadcast_to(dof[:, :, None], Ke.shape)
        cols = np.broadcast_to(dof[:, None, :], Ke.shape)
        keep = (rows >= 0) & (cols >= 0)
        K = scipy.sparse.coo_matrix((Ke[keep], (rows[keep], cols[keep])),
                                    shape=(self.ndof, self.ndof)).tocsc()
        K.sum_duplicates()
        return K

    def _boundary(self):
        """Faces that belong to exactly one tetrahedron (orientation unused)."""
        t = self.tets
        faces = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]])
        key = np.sort(faces, axis=1)
        _, first, count = np.unique(key, axis=0, return_index=True, return_counts=True)
        return faces[first[count == 1]]

    def columns(self, vertices):
        """K^-1 E for free @p vertices: (ndof, 3 len(vertices)), m/N, cached."""
        todo = [v for v in vertices if v not in self._columns]
        if todo:
            rhs = np.zeros((self.ndof, 3 * len(todo)))
            for j, v in enumerate(todo):
                for a in range(3):
                    rhs[3 * self.dof_vertex[v] + a, 3 * j + a] = 1.0
            Z = self.lu.solve(rhs)
            for j, v in enumerate(todo):
                self._columns[v] = Z[:, 3 * j:3 * j + 3]
        return np.hstack([self._columns[v] for v in vertices])

    def displacement(self, loads):
        """u of every vertex (V, 3) m under forces {vertex: 3-vector N}."""
        F = np.zeros(self.ndof)
        for v, f in loads.items():
            if not self.fixed[v]:
                F[3 * self.dof_vertex[v]:3 * self.dof_vertex[v] + 3] += f
        U = self.lu.solve(F)
        u = np.zeros_like(self.X)
        free = ~self.fixed
        u[free] = U.reshape(-1, 3)[self.dof_vertex[free]]
        return u


# ---- geometry -------------------------------------------------------------------------

def closest_points(p, a, b, c):
    """The point of each triangle (a[i], b[i], c[i]) closest to point p, by
    the Voronoi regions of its vertices, edges and face."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp, cp = p - b, p - c
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_face, w_face = vb / denom, vc / denom
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    q = a + v_face[:, None] * ab + w_face[:, None] * ac
    region = [
        ((d1 <= 0) & (d2 <= 0), a),
        ((d3 >= 0) & (d4 <= d3), b),
        ((d6 >= 0) & (d5 <= d6), c),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + t_ab[:, None] * ab),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + t_ac[:, None] * ac),
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + t_bc[:, None] * (c - b)),
    ]
    done = np.zeros(len(a), bool)
    for mask, point in region:
        m = mask & ~done
        q[m] = point[m]
        done |= m
    return q


def triangle_distances(p, a, b, c):
    """Distance from point p to each triangle (a[i], b[i], c[i])."""
    return np.linalg.norm(closest_points(p, a, b, c) - p, axis=1)


def surface_point(organ, x):
    """The point of the organ's rest surface closest to @p x."""
    t = organ.triangles
    q = closest_points(np.asarray(x, float), organ.X[t[:, 0]], organ.X[t[:, 1]], organ.X[t[:, 2]])
    return q[np.argmin(np.linalg.norm(q - x, axis=1))]


def lattice(level):
    """Barycentric weights (numerators over level) of the lattice points."""
    return [(i, j, level - i - j) for i in range(level + 1) for j in range(level + 1 - i)]


def least_distance(M, b):
    """min |v| subject to M v >= b, with its multipliers (Lawson-Hanson LDP
    by NNLS). Returns v, lambda >= 0 with v = M^T lambda."""
    m, n = M.shape
    Ematrix = np.vstack([M.T, b[None, :]])
    rhs = np.zeros(n + 1)
    rhs[n] = 1.0
    y, _ = scipy.optimize.nnls(Ematrix, rhs, maxiter=50 * m)
    residual = Ematrix @ y - rhs
    if abs(residual[n]) < 1e-14:
        raise RuntimeError("the linearized contact constraints are infeasible")
    scale = 1.0 - b @ y
    return M.T @ y / scale, y / scale


# ---- the press -----------------------------------------------------------------------

def press(organ, point, normal, radius, depths, level=8, refine=True, margin=None,
          max_iterations=200, tolerance=1e-10, max_rounds=60):
    """Presses the sphere along -normal from touching @p point; one answer per
    depth (m), in order. Lengths in m, forces in N.

    With @p refine, a triangle that the sphere still penetrates between the
    samples (its exact closest point to the centre is inside) gets that
    point as one more sample, and the depth is solved again, until no
    triangle is penetrated by more than 1e-5 r (or @p max_rounds)."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    point = np.asarray(point, float)
    margin = 0.5 * radius if margin is None else margin
    X = organ.X
    tris = organ.triangles
    u = np.zeros_like(X)          # the previous depth's displacement, every vertex
    answers = []
    previous = 0.0
    for depth in depths:
        c = point + (radius - depth) * normal
        # Triangles that can meet the sphere: deformed (previous depth), within
        # the margin plus the step; grown if the solution shows others inside.
        y = X + u
        dist = triangle_distances(c, y[tris[:, 0]], y[tris[:, 1]], y[tris[:, 2]])
        candidates = set(np.flatnonzero(dist < radius + margin + (depth - previous)).tolist())
        samples = {}
        for t in candidates:
            for weights in lattice(level):
                _add_sample(samples, tris[t], np.asarray(weights) / level)
        lattice_count = len(samples)
        rounds = 0
        while True:
            rounds += 1
            answer, u_new = _solve_depth(organ, c, radius, list(samples.values()), u,
                                         max_iterations, tolerance)
            y = X + u_new
            q = closest_points(c, y[tris[:, 0]], y[tris[:, 1]], y[tris[:, 2]])
            dist = np.linalg.norm(q - c, axis=1)
            inside = np.flatnonzero(dist < radius)
            outside = set(inside.tolist()) - candidates
            if outside:
                candidates |= outside
                for t in outside:
                    for weights in lattice(level):
                        _add_sample(samples, tris[t], np.asarray(weights) / level)
                continue
            deep = np.flatnonzero(dist < radius * (1 - 1e-5))
            if not refine or len(deep) == 0 or rounds >= max_rounds:
                break
            for t in deep:
                a, b, cc = y[tris[t]]
                vw = np.linalg.lstsq(np.column_stack([b - a, cc - a]), q[t] - a, rcond=None)[0]
                w = np.clip([1 - vw.sum(), vw[0], vw[1]], 0, 1)
                _add_sample(samples, tris[t], w / w.sum())
        penetration = radius - dist
        answer.update(depth_m=depth, centre_m=c.tolist(),
                      force_n=float(-np.dot(answer["force_vector_n"], normal)),
                      triangles=len(candidates), lattice_samples=lattice_count,
                      refinement_rounds=rounds,
                      max_penetration_m=float(max(penetration.max(), 0.0)))
        answers.append(answer)
        u = u_new
        previous = depth
    return answers


def _add_sample(samples, triangle, weights):
    """A point of a triangle, kept once: keyed by its vertices and weights
    (a point on a shared edge or vertex is the same from either side)."""
    key = tuple(sorted((int(v), round(float(w), 12)) for v, w in zip(triangle, weights)
                       if round(float(w), 12) > 0))
    samples.setdefault(key, key)


def _solve_depth(organ, c, radius, samples, u_start, max_iterations, tolerance):
    X = organ.X
    vertices = sorted({v for key in samples for v, _ in key if not organ.fixed[v]})
    slot = {v: k for k, v in enumerate(vertices)}
    m, nv = len(samples), len(vertices)
    W = np.zeros((m, nv))                         # weights on the free vertices
    x = np.zeros((m, 3))                          # rest position of each sample
    for i, key in enumerate(samples):
        for v, w in key:
            x[i] += w * X[v]
            if v in slot:
                W[i, slot[v]] += w
    fixed_only = ~W.any(axis=1)
    Z = organ.columns(vertices)
    dofs = (3 * organ.dof_vertex[vertices][:, None] + np.arange(3)).ravel()
    C = Z[dofs, :]
    C = 0.5 * (C + C.T)
    # Millimetres inside the solve: compliance mm/N, displacements mm.
    Cmm = 1e3 * C
    R = np.linalg.cholesky(Cmm)
    xs, cs, r = 1e3 * x, 1e3 * c, 1e3 * radius
    u_loc = 1e3 * u_start[vertices]               # (nv, 3) mm
    lam = np.zeros(m)
    n_prev = None
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        y = xs + W @ u_loc
        d = y - cs
        n = d / np.linalg.norm(d, axis=1)[:, None]
        H = (W[:, :, None] * n[:, None, :]).reshape(m, 3 * nv)
        b = r - np.einsum("ij,ij->i", n, xs - cs)
        rows = ~fixed_only
        if np.any(b[fixed_only] > 1e-9):
            raise RuntimeError("the sphere reaches a fixed part of the surface")
        v, lam_rows = least_distance(H[rows] @ R, b[rows])
        lam = np.zeros(m)
        lam[rows] = lam_rows
        u_loc = (R @ v).reshape(nv, 3)
        change = np.inf if n_prev is None else np.abs(n - n_prev).max()
        n_prev = n
        if change < tolerance:
            break
    gap = H @ (R @ v) - b                        # linearized gaps, mm
    f_loc = (H.T @ lam).reshape(nv, 3)           # N on each vertex
    loads = {v: f_loc[k] for k, v in enumerate(vertices)}
    u_all = organ.displacement(loads)
    consistency = np.abs(1e3 * u_all[vertices] - u_loc).max()
    answer = {
        "force_vector_n": (n.T @ lam).tolist(),
        "iterations": iterations,
        "normal_change": float(change),
        "samples": m,
        "vertices": nv,
        "active_samples": int((lam > 0).sum()),
        "max_gap_violation_m": float(max(-gap[~fixed_only].min(), 0.0)) * 1e-3,
        "max_complementarity_n_m": float(np.abs(lam * gap).max()) * 1e-3,
        "displacement_consistency_m": float(consistency) * 1e-3,
        "max_displacement_m": float(np.linalg.norm(u_all, axis=1).max()),
        "compliance_vertices": vertices,
        "compliance_block_m_per_n": C,
    }
    return answer, u_all


def compliance_agreement(organ, vertices, C):
    """max |C - G| / max |G| over the stored G's blocks of @p vertices."""
    index = {int(v): k for k, v in enumerate(organ.compliance_ids)}
    ranks = [index[v] for v in vertices]
    rows = (3 * np.asarray(ranks)[:, None] + np.arange(3)).ravel()
    order = np.argsort(rows)
    with h5py.File(organ.path, "r") as f:
        G_rows = f["compliance/G"][np.sort(rows), :].astype(np.float64)
    G = np.empty((len(rows), len(rows)))
    G[order, :] = G_rows[:, rows]
    return float(np.abs(C - G).max() / np.abs(G).max())


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model")
    parser.add_argument("--point", required=True,
                        help="x,y,z in m, moved onto the rest surface (its closest point)")
    parser.add_argument("--normal", required=True, help="outward; the sphere moves along -normal")
    parser.add_argument("--radius-mm", type=float, required=True)
    parser.add_argument("--depths-mm", required=True)
    parser.add_argument("--level", type=int, default=8, help="lattice level per triangle")
    parser.add_argument("--palpate", metavar="SPHERE_PRESS",
                        help="also run palpate_sphere_press and print the comparison")
    parser.add_argument("--json", help="write the answers here (default: stdout)")
    a = parser.parse_args(argv)

    def numbers(option, text, count=None):
        try:
            values = [float(s) for s in text.split(",")]
        except ValueError:
            values = []
        if not values or (count and len(values) != count) or not np.all(np.isfinite(values)):
            parser.error(f"{option} '{text}': expected {count or 'some'} numbers "
                         "separated by commas")
        return np.array(values)

    point = numbers("--point", a.point, 3)
    normal = numbers("--normal", a.normal, 3)
    depths = list(1e-3 * numbers("--depths-mm", a.depths_mm))
    if not (a.radius_mm > 0) or np.linalg.norm(normal) == 0 or min(depths) <= 0:
        parser.error("--radius-mm and the depths must be positive, --normal not zero")
    organ = Organ(a.model)
    point = surface_point(organ, point)
    print(f"point on the surface: {','.join(f'{v:.6f}' for v in point)} m", file=sys.stderr)
    answers = press(organ, point, normal, 1e-3 * a.radius_mm, depths, level=a.level)
    for ans in answers:
        ans["compliance_agreement"] = compliance_agreement(organ, ans.pop("compliance_vertices"),
                                                           ans.pop("compliance_block_m_per_n"))
        print(f"depth {1e3 * ans['depth_m']:.2f} mm: force {ans['force_n']:.5f} N, "
              f"{ans['iterations']} iterations, "
              f"{ans['active_samples']} of {ans['samples']} samples active, "
              f"penetration {1e6 * ans['max_penetration_m']:.2f} um, "
              f"G agreement {ans['compliance_agreement']:.1e}", file=sys.stderr)
    result = {"model": a.model, "level": a.level, "presses": answers}
    if a.palpate:
        out = subprocess.run([a.palpate, a.model, "--point", ",".join(repr(v) for v in point),
                              "--normal", ",".join(repr(v) for v in normal),
                              "--radius-mm", repr(a.radius_mm), "--depths-mm", a.depths_mm],
                             capture_output=True, text=True, check=True)
        result["palpate"] = json.loads(out.stdout)
        print("| depth (mm) | reference (N) | palpate (N), held min-max | difference |",
              file=sys.stderr)
        for p, q in zip(result["palpate"]["presses"], answers):
            print(f"| {1e3 * p['depth_m']:g} | {q['force_n']:.3f} | {p['force_n']:.3f} "
                  f"({p['force_min_n']:.3f}-{p['force_max_n']:.3f}) | "
                  f"{100 * (p['force_n'] / q['force_n'] - 1):+.1f} % |", file=sys.stderr)
    text = json.dumps(result, indent=1)
    if a.json:
        with open(a.json, "w") as f:
            f.write(text)
    else:
        print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
