"""Wall indentation by a spherical catheter tip: scikit-fem reference.

A sector of an artery wall (inner radius A, thickness T, length L, opening
ANGLE, axis along z, the sector spanning -ANGLE/2 <= theta <= ANGLE/2) is
indented at its centre (theta = 0, z = L/2) by a rigid frictionless sphere
of radius R_TIP inside the lumen. The sphere starts touching the inner wall
(centre (A - R_TIP, 0, L/2)) and moves radially outward (+x) by the depth.
The two ends (z = 0, L) and the two straight edges (theta = +-ANGLE/2) are
clamped; the outer surface and the rest of the inner surface are free.

Constitutive law: LINEAR elasticity (small strain). The contact is
unilateral and frictionless with the exact gap: a surface node x = X + u is
admissible when |x - c| >= R_TIP, the sphere pushes it along the normal
(x - c)/|x - c| with a force lambda >= 0, and lambda (|x - c| - R_TIP) = 0
(node-to-obstacle collocation at every DOF location of the inner wall,
vertices and P2 midside nodes; Kikuchi & Oden 1988, "Contact problems in
elasticity", ch. 5). The force is nonlinear in the depth (the footprint
grows) and, the geometry being fixed, exactly proportional to E.

Quadratic (P2) tetrahedra on the quarter (u_y = 0 on y = 0, u_z = 0 on
z = L/2; the force is four times the quarter's), a tensor mesh in
(r, arc length s on the inner wall, z) mapped to the cylinder. The map is
the one the Rust scenario's mesh levels use (comparisons/src/scenarios/
tissue.rs, `wall_sphere_mesh`): uniform through the wall, uniform over the
band [0, BAND] in s and in z - L/2 (half the cells), then cells growing
quadratically to the clamped edge. The reference is P2 on the map with
N_REF cells through the wall; a second solve with N_REF / 2 gives the stated
mesh error.

Solver. Elasticity is linear, so the inner-wall nodes near the tip
(|s|, |z - L/2| within CAND of the tip) are condensed: one sparse LU of the
free-free stiffness, the compliance C of those nodes from unit loads, then
per depth a sequence of linear complementarity problems: with the normals
n_i and gaps g_i at the current iterate, lambda >= 0 minimises
1/2 lambda.A.lambda + b.lambda, A = N^T C N, b = g - n.u (the gap
linearised in u), solved exactly by non-negative least squares (Lawson &
Hanson 1974) on the Cholesky factor of A; repeated until the displacement
changes by less than 1e-13 of the depth (the normals converge). Checks
written to provenance.toml: exact gaps of every inner-wall node after the
full solve (no node outside CAND penetrates), complementarity, and the
contact reaching at most 80 % of CAND.

Writes `wall-indentation.csv` (depth, force on the sphere along +x,
contact extent along z) and `surface-profile.csv` (depth, line, coordinate,
radial displacement of the inner wall: line 0 along z at theta = 0, line 1
around theta at z = L/2, over the whole sector by symmetry).

Usage: python wall_indentation.py OUTDIR
"""

import sys
import os
import time
import numpy as np
import scipy
import scipy.linalg
import scipy.optimize
import scipy.sparse.linalg
import skfem
from skfem import MeshTet, ElementTetP2, ElementVector, Basis, asm
from skfem.models.elasticity import linear_elasticity, lame_parameters

A, T, L = 4.0e-3, 1.0e-3, 8.0e-3  # inner radius, wall thickness, length (m)
ANGLE = 2.0 * np.pi / 3.0  # sector opening (rad)
R_TIP = 1.0e-3  # sphere (catheter tip) radius (m); a 6F catheter is 2 mm across
ZC = L / 2  # tip height (m)
E, NU = 1.0e6, 0.45  # Pa, -
BAND = 0.5e-3  # half-width of the uniform band around the tip (m)
KAPPA = 1.5  # radial grading: r = A + T (exp(KAPPA xi) - 1) / (exp(KAPPA) - 1)
N_REF = 6  # reference cells through the wall (P2): DOFs every 42 um at the tip
CAND = 0.6e-3  # contact candidates: inner-wall nodes with |s|, |z - ZC| <= CAND (m)
DEPTHS = np.linspace(0.0, 0.2 * T, 21)  # force-displacement rows (m)
PROFILE_DEPTHS_EVERY = 2  # surface profiles at every 2nd depth
PROBES_Z = np.linspace(0.0, L, 41)  # line 0: z along theta = 0 (m)
PROBES_TH = np.linspace(-ANGLE / 2, ANGLE / 2, 41)  # line 1: theta at z = ZC (rad)


def grading(n, band, length):
    """Coordinates 0..length of n cells (n even): uniform cells 2 band / n
    over [0, band], then rho(xi) = c xi + (length - c) ((xi - 1/2) / (1/2))^2,
    c = 2 band (xi = k / n)."""
    xi = np.linspace(0.0, 1.0, n + 1)
    c = 2.0 * band
    t = np.maximum((xi - 0.5) / 0.5, 0.0)
    return c * xi + (length - c) * t * t


def quarter_mesh(n_r):
    """Quarter of the sector: n_r cells through the wall (graded towards the
    inner wall), 2 n_r along the arc (0 <= s <= A ANGLE / 2) and along z
    (ZC <= z <= L), each with half its cells uniform over the band."""
    xi = np.linspace(0.0, 1.0, n_r + 1)
    rr = A + T * np.expm1(KAPPA * xi) / np.expm1(KAPPA)
    ss = grading(2 * n_r, BAND, A * ANGLE / 2)
    zz = ZC + grading(2 * n_r, BAND, L - ZC)
    m0 = MeshTet.init_tensor(rr, ss, zz)
    th = m0.p[1] / A
    p = np.vstack([m0.p[0] * np.cos(th), m0.p[0] * np.sin(th), m0.p[2]])
    p[1, m0.p[1] == 0.0] = 0.0
    return MeshTet(p, m0.t)


def solve(n_r):
    """Force curve, profiles and checks on the quarter mesh of n_r cells."""
    m = quarter_mesh(n_r)
    ib = Basis(m, ElementVector(ElementTetP2()), intorder=2)
    K = asm(linear_elasticity(*lame_parameters(E, NU)), ib).tocsr()
    x, y, z = ib.doflocs
    # DOF locations: one row per node (vertex or midside), its x, y, z DOFs.
    loc = np.hstack([np.vstack([ib.nodal_dofs[k] for k in range(3)]), np.vstack([ib.edge_dofs[k] for k in range(3)])]).T
    tol = 1e-9 * A
    r = np.hypot(x, y)
    th = np.arctan2(y, x)
    fixed = (th >= ANGLE / 2 - 1e-9) | (np.abs(z - L) < tol)
    comp = np.empty(ib.N, dtype=int)
    for k in range(3):
        comp[loc[:, k]] = k
    sym = ((np.abs(y) < tol) & (comp == 1)) | ((np.abs(z - ZC) < tol) & (comp == 2))
    free = np.nonzero(~(fixed | sym))[0]
    index = -np.ones(ib.N, dtype=int)
    index[free] = np.arange(len(free))
    t0 = time.time()
    lu = scipy.sparse.linalg.splu(K[free][:, free].tocsc(), permc_spec="MMD_AT_PLUS_A")
    print(f"n_r {n_r}: {ib.N} dofs, factor {time.time() - t0:.1f} s, fill {lu.L.nnz + lu.U.nnz}", flush=True)

    X = np.vstack([x[loc[:, 0]], y[loc[:, 0]], z[loc[:, 0]]]).T  # node positions
    on_inner = np.abs(np.hypot(X[:, 0], X[:, 1]) - A) < tol
    s_node = A * np.arctan2(X[:, 1], X[:, 0])
    cand = np.nonzero(on_inner & (s_node <= CAND) & (X[:, 2] - ZC <= CAND))[0]
    inner = np.nonzero(on_inner)[0]
    # Compliance of the candidates' free DOFs (unit loads).
    cdofs = loc[cand]  # (m, 3) global DOFs
    cfree = index[cdofs]  # -1 where held
    cols = cfree[cfree >= 0]
    rhs = np.zeros((len(free), len(cols)))
    rhs[cols, np.arange(len(cols))] = 1.0
    G = lu.solve(rhs)  # free x candidate-free
    mcand = len(cand)
    Cfull = np.zeros((3 * mcand, 3 * mcand))
    flat = cfree.ravel()
    sel = np.nonzero(flat >= 0)[0]
    Cfull[np.ix_(sel, sel)] = G[cols][:, np.arange(len(cols))]
    Cfull = 0.5 * (Cfull + Cfull.T)  # symmetric up to the LU's round-off
    Xc = X[cand]

    rows, profiles, checks = [], [], []
    lam = np.zeros(mcand)
    uc = np.zeros((mcand, 3))
    for di, d in enumerate(DEPTHS):
        c = np.array([A - R_TIP + d, 0.0, ZC])
        outer = 0
        while True:
            outer += 1
            xc = Xc + uc
            dist = np.linalg.norm(xc - c, axis=1)
            n = (xc - c) / dist[:, None]
            g = dist - R_TIP
            N = np.zeros((3 * mcand, mcand))
            N[3 * np.arange(mcand) + 0, np.arange(mcand)] = n[:, 0]
            N[3 * np.arange(mcand) + 1, np.arange(mcand)] = n[:, 1]
            N[3 * np.arange(mcand) + 2, np.arange(mcand)] = n[:, 2]
            Amat = N.T @ Cfull @ N
            b = g - np.einsum("ij,ij->i", n, uc)
            Lc = scipy.linalg.cholesky(Amat, lower=True)
            dvec = -scipy.linalg.solve_triangular(Lc, b, lower=True)
            lam, _ = scipy.optimize.nnls(Lc.T, dvec, maxiter=50 * mcand)
            unew = (Cfull @ (N @ lam)).reshape(mcand, 3)
            change = np.abs(unew - uc).max()
            uc = unew
            if change <= 1e-13 * max(d, T) or outer >= 100:
                break
        # Full displacement under the contact forces.
        f = np.zeros(len(free))
        fn = (N @ lam).reshape(mcand, 3)
        for k in range(3):
            ok = cfree[:, k] >= 0
            f[cfree[ok, k]] += fn[ok, k]
        u = np.zeros(ib.N)
        u[free] = lu.solve(f)
        xi = X[inner] + u[loc[inner]]
        gap_all = np.linalg.norm(xi - c, axis=1) - R_TIP
        active = lam > 0
        force = 4.0 * np.sum(lam * n[:, 0])
        ext_z = (Xc[active, 2] - ZC).max() if active.any() else 0.0
        ext_s = (A * np.arctan2(Xc[active, 1], Xc[active, 0])).max() if active.any() else 0.0
        lam_scale = max(lam.max(), 1e-300)
        gap_c = np.linalg.norm(Xc + uc - c, axis=1) - R_TIP
        checks.append(
            (
                outer,
                -min(gap_all.min(), 0.0) / max(d, 1e-300),
                np.abs(lam * gap_c).max() / (lam_scale * d) if d > 0 else 0.0,
                max(ext_z, ext_s) / CAND,
            )
        )
        rows.append((d, force, ext_z, ext_s))
        if di % PROFILE_DEPTHS_EVERY == 0:
            # Mirrored onto the quarter; the clamped ends pulled in by 1e-9
            # of their extent so the probes lie in the mesh.
            zq = np.minimum(ZC + np.abs(PROBES_Z - ZC), L * (1 - 1e-9))
            tq = np.minimum(np.abs(PROBES_TH), ANGLE / 2 * (1 - 1e-9))
            rr = A * (1 + 1e-9)  # a hair inside the wall
            p0 = np.vstack([np.full_like(zq, rr), np.zeros_like(zq), zq])
            p1 = np.vstack([rr * np.cos(tq), rr * np.sin(tq), np.full_like(tq, ZC)])
            u0 = ib.probes(p0) @ u
            u1 = ib.probes(p1) @ u
            ur0 = u0[0 : len(zq)]  # u_x = u_r on theta = 0
            nt = len(tq)
            ur1 = u1[0:nt] * np.cos(tq) + u1[nt : 2 * nt] * np.sin(tq)
            profiles.append((d, ur0, ur1))
    return dict(rows=rows, profiles=profiles, checks=checks, dofs=ib.N, tets=m.t.shape[1], cand=mcand)


def main(out):
    t0 = time.time()
    ref = solve(N_REF)
    t1 = time.time()
    coarse = solve(N_REF // 2)
    t2 = time.time()
    f = np.array([r[1] for r in ref["rows"]])
    f2 = np.array([r[1] for r in coarse["rows"]])
    # Mesh difference of the force relative to the force, over the nonzero depths.
    diff_f = np.abs(f2[1:] - f[1:]) / f[1:]
    diff_u = max(
        max(np.abs(a[1] - b[1]).max(), np.abs(a[2] - b[2]).max()) / max(a[0], 1e-300)
        for a, b in zip(ref["profiles"][1:], coarse["profiles"][1:])
    )
    checks = np.array(ref["checks"] + coarse["checks"])
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "wall-indentation.csv"), "w") as fh:
        fh.write("depth_m,force_n,contact_extent_z_m,contact_extent_arc_m\n")
        for d, fo, ez, es in ref["rows"]:
            fh.write(f"{d:.6e},{fo:.9e},{ez:.6e},{es:.6e}\n")
    with open(os.path.join(out, "surface-profile.csv"), "w") as fh:
        fh.write("depth_m,line,coordinate,u_r_m\n")
        for d, ur0, ur1 in ref["profiles"]:
            for zi, ui in zip(PROBES_Z, ur0):
                fh.write(f"{d:.6e},0,{zi:.6e},{ui:.9e}\n")
            for ti, ui in zip(PROBES_TH, ur1):
                fh.write(f"{d:.6e},1,{ti:.6e},{ui:.9e}\n")
    with open(os.path.join(out, "provenance.toml"), "w") as fh:
        fh.write(f"force_at_max_depth_n = {f[-1]:.9e}\n")
        fh.write(f"force_at_max_depth_coarse_mesh_n = {f2[-1]:.9e}  # N_REF halved\n")
        fh.write(f"mesh_difference_force_rel_max = {diff_f.max():.3e}  # over the nonzero depths\n")
        fh.write(f"mesh_difference_force_rel_at_max_depth = {diff_f[-1]:.3e}\n")
        fh.write(f"mesh_difference_profile_max_over_depth = {diff_u:.3e}\n")
        fh.write(f"contact_iterations_max = {int(checks[:, 0].max())}\n")
        fh.write(f"penetration_max_over_depth = {checks[:, 1].max():.3e}  # every inner-wall node\n")
        fh.write(f"complementarity_max = {checks[:, 2].max():.3e}  # lambda gap / (lambda_max depth)\n")
        fh.write(f"contact_extent_over_candidates_max = {checks[:, 3].max():.3f}\n")
        fh.write(f"dofs = {ref['dofs']}\n")
        fh.write(f"dofs_coarse = {coarse['dofs']}\n")
        fh.write(f"tets_quarter = {ref['tets']}\n")
        fh.write(f"contact_candidates_quarter = {ref['cand']}\n")
        fh.write(f"seconds = {{ reference = {t1 - t0:.1f}, coarse = {t2 - t1:.1f} }}\n")
        fh.write(
            f"versions = {{ scikit-fem = \"{skfem.__version__}\", numpy = \"{np.__version__}\", scipy = \"{scipy.__version__}\" }}\n"
        )
    bad = []
    if checks[:, 0].max() >= 100:
        bad.append("contact iteration did not converge")
    if checks[:, 1].max() > 1e-9:
        bad.append(f"a node penetrates the sphere by {checks[:, 1].max():.2e} of the depth")
    if checks[:, 3].max() > 0.8:
        bad.append("the contact reaches the edge of the candidate region: raise CAND")
    print(
        f"wall-indentation: {ref['dofs']} dofs ({t1 - t0:.1f} s), force at {DEPTHS[-1]:.1e} m {f[-1]:.6e} N, "
        f"coarse {f2[-1]:.6e} N, mesh difference max {diff_f.max():.2e}, profile {diff_u:.2e}, "
        f"checks {checks.max(axis=0)}"
    )
    if bad:
        sys.exit("wall-indentation: " + "; ".join(bad))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
