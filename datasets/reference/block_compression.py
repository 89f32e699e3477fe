"""Block compression between bonded plates: scikit-fem reference.

Cube of edge L, bottom face (z = 0) clamped, top face (z = L) bonded to a
rigid plate moved down by `strain * L` (u_x = u_y = 0 there), sides free.
Constitutive law: LINEAR elasticity (small strain). The force is therefore
exactly linear in the strain; at 20 % compression a large-strain law
(corotational, neo-Hookean) differs by several percent, so compare large-strain
models to this curve only at small strain, or read it as the small-strain
tangent. Quadratic (P2) tetrahedra on a structured mesh.

Writes `block-compression.csv`: strain, top displacement (m), compressive
force on the plate (N, positive).

Usage: python block_compression.py OUTDIR
"""

import sys
import os
import numpy as np
import scipy
import skfem
from skfem import MeshTet, ElementTetP2, ElementVector, Basis, asm, solve, condense
from skfem.models.elasticity import linear_elasticity, lame_parameters

L = 0.01  # m
E, NU = 5.0e3, 0.3  # Pa, -
N = 10  # cells per edge
STRAINS = np.linspace(0.0, 0.2, 11)


def main(out):
    g = np.linspace(0, L, N + 1)
    m = MeshTet.init_tensor(g, g, g)
    e = ElementVector(ElementTetP2())
    ib = Basis(m, e, intorder=4)
    K = asm(linear_elasticity(*lame_parameters(E, NU)), ib)
    tol = 1e-12 * L
    bottom = ib.get_dofs(lambda x: np.abs(x[2]) < tol).all()
    top = ib.get_dofs(lambda x: np.abs(x[2] - L) < tol)
    top_z = top.all('u^3')
    D = np.unique(np.concatenate([bottom, top.all()]))
    # Unit compression (strain 1) then scale: the problem is linear.
    x = np.zeros(K.shape[0])
    x[top_z] = -L
    u = solve(*condense(K, np.zeros(K.shape[0]), x=x, D=D))
    r = K @ u
    free = np.setdiff1d(np.arange(K.shape[0]), D)
    res = np.linalg.norm(r[free]) / np.linalg.norm(r[top_z])
    k_unit = -r[top_z].sum()  # force the plate applies downwards, per unit strain
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "block-compression.csv"), "w") as fh:
        fh.write("strain,top_displacement_m,force_n\n")
        for s in STRAINS:
            fh.write(f"{s:.4f},{-s * L:.6e},{k_unit * s:.9e}\n")
    with open(os.path.join(out, "provenance.toml"), "w") as fh:
        fh.write(f"force_per_unit_strain_n = {k_unit:.9e}\n")
        fh.write(f"uniaxial_stress_estimate_n = {E * L * L:.6e}  # E A, for scale\n")
        fh.write(f"solver_relative_residual = {res:.3e}\n")
        fh.write(f"dofs = {K.shape[0]}\n")
        fh.write(f"versions = {{ scikit-fem = \"{skfem.__version__}\", numpy = \"{np.__version__}\", scipy = \"{scipy.__version__}\" }}\n")
    print(f"block-compression: {K.shape[0]} dofs, force per unit strain {k_unit:.6e} N, residual {res:.1e}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
