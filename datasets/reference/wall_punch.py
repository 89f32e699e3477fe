"""Wall punch: a catheter tip as a bonded flat punch on a vessel wall; scikit-fem reference.

A sector of an artery wall (inner radius A, thickness T, length L, opening
ANGLE, axis along z, the sector spanning -ANGLE/2 <= theta <= ANGLE/2) is
indented at its centre (theta = 0, z = L/2) by a rigid flat-ended circular
punch of radius RP BONDED to the inner wall and moved radially outward (+x)
by the depth. The footprint rule, shared with the Rust scenario
(comparisons/src/scenarios/tissue.rs, `wall-punch`): every DOF whose
reference position lies on the inner surface with y^2 + (z - L/2)^2 <= RP^2
(1 + 1e-6) is prescribed u = (depth, 0, 0); for P2 this includes the midside
DOFs of the inner facets. The two ends (z = 0, L) and the two straight edges
(theta = +-ANGLE/2) are clamped; the outer surface is free.

The catheter tip of the issue is a sphere in unilateral contact: that is
`wall-indentation` (wall_indentation.py). This bonded punch is the linear
companion scene, kept for models without tissue contact and for the PBD
local-activation study (comparisons/pbd-hash.toml).

Constitutive law: LINEAR elasticity (small strain); the force is exactly
linear in the depth and proportional to E. Quadratic (P2) tetrahedra on a
tensor mesh graded towards the punch (uniform cells of H_FINE over the
footprint band, growing by GROWTH outside and through the wall), mapped to
the cylinder. The problem is symmetric about y = 0 and z = L/2, so a quarter
is solved (u_y = 0 on y = 0, u_z = 0 on z = L/2) and the force is four times
the quarter's. Two meshes (H_FINE and 2 H_FINE) are solved; their difference
is the stated mesh error (provenance.toml).

Writes `wall-punch.csv` (depth, punch force) and
`surface-profile.csv` (z, radial displacement of the inner wall along the
axial line theta = 0 per unit depth).

Usage: python wall_punch.py OUTDIR
       python wall_punch.py --half-space   (set-up check, see below)
"""

import sys
import os
import time
import numpy as np
import scipy
import scipy.sparse.linalg
import skfem
from skfem import MeshTet, ElementTetP2, ElementVector, Basis, asm, solve, condense
from skfem.models.elasticity import linear_elasticity, lame_parameters

A, T, L = 4.0e-3, 1.0e-3, 8.0e-3  # inner radius, wall thickness, length (m)
ANGLE = 2.0 * np.pi / 3.0  # sector opening (rad)
RP = 1.0e-3  # punch (catheter tip) radius (m)
ZC = L / 2  # punch centre height (m)
E, NU = 1.0e6, 0.45  # Pa, -
FOOT_TOL = 1e-6  # relative, inclusive: the footprint rule above
H_FINE = T / 8  # cell size over the footprint band, reference mesh (m): P2,
# so DOFs every T/16 there, twice as fine as the finest Rust level (P1, T/8)
GROWTH = 1.25  # cell growth factor away from the band and the inner wall
BAND = 1.25 * RP  # half-width of the uniformly fine band (m)
DEPTHS = np.linspace(0.0, 0.2 * T, 11)  # force-displacement rows (m)
PROBES_Z = np.linspace(0.0, L, 41)  # profile along theta = 0 (m)


def graded(length, fine, h):
    """Coordinates 0..length: uniform cells h over [0, fine], then cells
    growing by GROWTH, scaled to end exactly at `length`."""
    n = int(round(fine / h))
    x = h * np.arange(n + 1)
    rest = length - x[-1]
    sizes, s = [], h
    while sum(sizes) < rest:
        s *= GROWTH
        sizes.append(s)
    sizes = np.array(sizes) * rest / sum(sizes)
    return np.concatenate([x, x[-1] + np.cumsum(sizes)])


def direct(A, b, **_):
    return scipy.sparse.linalg.spsolve(A.tocsc(), b, permc_spec="MMD_AT_PLUS_A")


def solve_quarter(h, a=A, t=T, length=L, angle=ANGLE, clamp_outer=False):
    """Unit-depth solve on the quarter mesh of fine size h: stiffness (N/m),
    profile u_r / depth at PROBES_Z, dofs, residual, footprint x-DOFs and
    tets. Other geometries serve the half-space check."""
    zc = length / 2
    rr = a + graded(t, 0.0, h)
    ss = graded(a * angle / 2, BAND, h)  # arc length on the inner wall
    zz = zc + graded(length / 2, BAND, h)
    m0 = MeshTet.init_tensor(rr, ss, zz)
    th = m0.p[1] / a
    p = np.vstack([m0.p[0] * np.cos(th), m0.p[0] * np.sin(th), m0.p[2]])
    p[1, m0.p[1] == 0.0] = 0.0
    m = MeshTet(p, m0.t)
    ib = Basis(m, ElementVector(ElementTetP2()), intorder=2)
    K = asm(linear_elasticity(*lame_parameters(E, NU)), ib)
    x, y, z = ib.doflocs
    comp = np.empty(ib.N, dtype=int)
    for k in range(3):
        comp[ib.nodal_dofs[k]] = k
        comp[ib.edge_dofs[k]] = k
    tol = 1e-9 * a
    f = m.boundary_facets()
    inner_f = f[np.all(np.abs(np.hypot(*m.p[:2, m.facets[:, f]]) - a) < tol, axis=0)]
    inner = np.zeros(ib.N, dtype=bool)
    inner[ib.get_dofs(facets=inner_f).all()] = True
    foot = inner & (y**2 + (z - zc) ** 2 <= RP**2 * (1 + FOOT_TOL))
    edge = np.arctan2(y, x) >= angle / 2 - 1e-9
    clamp = edge | (np.abs(z - length) < tol) | foot
    if clamp_outer:
        clamp |= np.hypot(x, y) > a + t - tol
    sym = ((np.abs(y) < tol) & (comp == 1)) | ((np.abs(z - zc) < tol) & (comp == 2))
    D = np.nonzero(clamp | sym)[0]
    u0 = np.zeros(ib.N)
    u0[foot & (comp == 0)] = 1.0  # unit depth along +x
    # Direct solve; minimum-degree ordering on A + A^T suits the symmetric
    # matrix (2x faster than the default COLAMD here).
    u = solve(*condense(K, np.zeros(ib.N), x=u0, D=D), solver=direct)
    r = K @ u
    free = np.setdiff1d(np.arange(ib.N), D)
    fx = foot & (comp == 0)
    k = 4.0 * r[fx].sum()  # force the punch applies, +x, per unit depth
    res = np.linalg.norm(r[free]) / np.linalg.norm(r[fx])
    zq = zc + np.abs(PROBES_Z * length / L - zc)  # mirror onto the quarter
    # A hair inside the wall: probes on the boundary edge itself may miss.
    pts = np.vstack([np.full_like(zq, a * (1 + 1e-9)), np.zeros_like(zq), zq])
    n = len(zq)
    ur = (ib.probes(pts) @ u)[0:n]  # u_x = u_r on theta = 0
    n_foot = int(fx.sum())
    return k, ur, ib.N, res, n_foot, m.t.shape[1]


def half_space_check():
    """Sanity check of the set-up (not part of the reference; run with
    --half-space): the same bonded punch on a nearly flat (a = 1 m) block
    clamped at distance R from the punch on every side but the loaded face,
    for R = 8 and 16 punch radii, extrapolated linearly in 1/R (the leading
    finite-size term), against the bonded flat punch on a half-space,
    F = 4 G a d ln(3 - 4 nu) / (1 - 2 nu) (Mossakovskii 1954; Johnson 1985,
    Sec. 3.8, gives the frictionless F = 2 a E* d, 0.28 % lower at nu =
    0.45). Prints the ratios."""
    g = E / (2 * (1 + NU))
    bonded = 4 * g * RP * np.log(3 - 4 * NU) / (1 - 2 * NU)
    frictionless = 2 * RP * E / (1 - NU**2)
    ks = {}
    for n in (8, 16):
        r = n * RP
        ks[n] = solve_quarter(RP / 3, a=1.0, t=r, length=2 * r, angle=2 * r / 1.0, clamp_outer=True)[0]
        print(f"R = {n} a: k = {ks[n]:.6e} N/m = {ks[n] / bonded:.4f} x bonded half-space")
    k_inf = 2 * ks[16] - ks[8]
    print(
        f"extrapolated R -> inf: {k_inf:.6e} N/m = {k_inf / bonded:.4f} x bonded "
        f"({bonded:.6e}), {k_inf / frictionless:.4f} x frictionless 2 a E* ({frictionless:.6e})"
    )


def main(out):
    t0 = time.time()
    k, ur, dofs, res, n_foot, tets = solve_quarter(H_FINE)
    t1 = time.time()
    k2, ur2, dofs2, res2, _, _ = solve_quarter(2 * H_FINE)
    mesh_diff_k = abs(k2 - k) / k
    mesh_diff_u = np.abs(ur2 - ur).max()
    e_star = E / (1 - NU**2)
    boussinesq = 2 * RP * e_star  # frictionless flat punch on a half-space
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "wall-punch.csv"), "w") as fh:
        fh.write("depth_m,force_n\n")
        for d in DEPTHS:
            fh.write(f"{d:.6e},{k * d:.9e}\n")
    with open(os.path.join(out, "surface-profile.csv"), "w") as fh:
        fh.write("z_m,u_r_over_depth\n")
        for zi, ui in zip(PROBES_Z, ur):
            fh.write(f"{zi:.6e},{ui:.9e}\n")
    with open(os.path.join(out, "provenance.toml"), "w") as fh:
        fh.write(f"stiffness_n_per_m = {k:.9e}\n")
        fh.write(f"stiffness_coarse_mesh_n_per_m = {k2:.9e}  # H_FINE doubled\n")
        fh.write(f"mesh_difference_stiffness_rel = {mesh_diff_k:.3e}\n")
        fh.write(f"mesh_difference_profile_max = {mesh_diff_u:.3e}  # of u_r / depth\n")
        fh.write(f"boussinesq_half_space_n_per_m = {boussinesq:.6e}  # 2 RP E/(1-nu^2), for scale\n")
        fh.write(f"solver_relative_residual = {max(res, res2):.3e}\n")
        fh.write(f"dofs = {dofs}\n")
        fh.write(f"dofs_coarse = {dofs2}\n")
        fh.write(f"tets_quarter = {tets}\n")
        fh.write(f"footprint_x_dofs_quarter = {n_foot}\n")
        fh.write(
            f"versions = {{ scikit-fem = \"{skfem.__version__}\", numpy = \"{np.__version__}\", scipy = \"{scipy.__version__}\" }}\n"
        )
    print(
        f"wall-punch: {dofs} dofs ({t1 - t0:.1f} s), stiffness {k:.6e} N/m "
        f"({k / boussinesq:.4f} x Boussinesq), coarse mesh {k2:.6e} ({mesh_diff_k:.2e} rel), "
        f"profile diff {mesh_diff_u:.2e}, residual {max(res, res2):.1e}"
    )


if __name__ == "__main__":
    if "--half-space" in sys.argv:
        half_space_check()
    else:
        main(sys.argv[1] if len(sys.argv) > 1 else ".")
