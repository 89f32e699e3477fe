"""Lamé thick-walled tube under internal pressure: scikit-fem reference.

Quarter of a tube (0 <= theta <= pi/2) with symmetry conditions (u_y = 0 on
y = 0, u_x = 0 on x = 0), u_z = 0 on both ends (plane strain), pressure p on
the inner surface, linear elasticity, quadratic (P2) tetrahedra on a
structured mesh whose nodes lie on the circles. Writes the radial
displacement at probe radii (theta = pi/4, mid-height), the closed form

    u(r) = p a^2 / (E (b^2 - a^2)) ((1 + nu)(1 - 2 nu) r + (1 + nu) b^2 / r)

(Timoshenko and Goodier, Theory of Elasticity, 3rd ed., Sec. 28, plane
strain) and the relative error into the CSV and the provenance.

Usage: python lame_tube.py OUTDIR
"""

import sys
import os
import numpy as np
import scipy
import skfem
from skfem import MeshTet, ElementTetP2, ElementVector, Basis, FacetBasis, LinearForm, asm, solve, condense
from skfem.models.elasticity import linear_elasticity, lame_parameters
from skfem.helpers import dot

A, B, H = 0.01, 0.02, 0.005  # inner, outer radius, height (m)
E, NU, P = 1.0e4, 0.3, 100.0  # Pa, -, Pa
N_R, N_THETA, N_Z = 12, 24, 2  # cells; P2 on this mesh
PROBES = np.linspace(A, B, 11)


def exact(r):
    return P * A**2 / (E * (B**2 - A**2)) * ((1 + NU) * (1 - 2 * NU) * r + (1 + NU) * B**2 / r)


def main(out):
    m0 = MeshTet.init_tensor(np.linspace(0, 1, N_R + 1), np.linspace(0, 1, N_THETA + 1), np.linspace(0, 1, N_Z + 1))
    r = A + (B - A) * m0.p[0]
    th = 0.5 * np.pi * m0.p[1]
    p = np.vstack([r * np.cos(th), r * np.sin(th), H * m0.p[2]])
    p[0, np.isclose(m0.p[1], 1.0)] = 0.0
    p[1, np.isclose(m0.p[1], 0.0)] = 0.0
    m = MeshTet(p, m0.t)
    e = ElementVector(ElementTetP2())
    ib = Basis(m, e, intorder=4)
    K = asm(linear_elasticity(*lame_parameters(E, NU)), ib)
    mid = m.p[:, m.facets].mean(axis=1)
    inner = np.nonzero(np.hypot(mid[0], mid[1]) < A + 0.25 * (B - A) / N_R)[0]
    fb = FacetBasis(m, e, facets=inner, intorder=4)

    @LinearForm
    def pressure(v, w):
        return -P * dot(w.n, v)

    f = asm(pressure, fb)
    tol = 1e-12
    D = np.concatenate([
        ib.get_dofs(lambda x: np.abs(x[1]) < tol).all('u^2'),
        ib.get_dofs(lambda x: np.abs(x[0]) < tol).all('u^1'),
        ib.get_dofs(lambda x: np.abs(x[2]) < tol).all('u^3'),
        ib.get_dofs(lambda x: np.abs(x[2] - H) < tol).all('u^3'),
    ])
    u = solve(*condense(K, f, D=np.unique(D)))
    res = np.linalg.norm((K @ u - f)[np.setdiff1d(np.arange(K.shape[0]), D)]) / np.linalg.norm(f)
    th = np.pi / 4
    pts = np.vstack([PROBES * np.cos(th), PROBES * np.sin(th), np.full_like(PROBES, H / 2)])
    probes = ib.probes(pts)
    uv = (probes @ u)
    # probes on a vector basis return component blocks: [u^1 at pts; u^2; u^3]
    n = len(PROBES)
    ur = uv[0:n] * np.cos(th) + uv[n:2 * n] * np.sin(th)
    ue = exact(PROBES)
    rel = np.abs(ur - ue) / np.abs(ue).max()
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "lame-tube.csv"), "w") as fh:
        fh.write("r_m,u_r_fem_m,u_r_exact_m\n")
        for a, b, c in zip(PROBES, ur, ue):
            fh.write(f"{a:.6e},{b:.9e},{c:.9e}\n")
    with open(os.path.join(out, "provenance.toml"), "w") as fh:
        fh.write(f"max_relative_error_vs_closed_form = {rel.max():.3e}\n")
        fh.write(f"solver_relative_residual = {res:.3e}\n")
        fh.write(f"dofs = {K.shape[0]}\n")
        fh.write(f"versions = {{ scikit-fem = \"{skfem.__version__ if hasattr(skfem, '__version__') else 'see requirements.txt'}\", numpy = \"{np.__version__}\", scipy = \"{scipy.__version__}\" }}\n")
    print(f"lame-tube: {K.shape[0]} dofs, max rel error vs closed form {rel.max():.3e}, residual {res:.1e}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
