"""Free vibration of a block clamped at its base: scikit-fem reference.

A box [0, LX] x [0, LY] x [0, LZ] (m), LX < LY so that the first mode is a
single sway in x (a cube's first two modes are a degenerate pair), base
z = 0 clamped, every other face free, LINEAR elasticity (the surgbench scene
starts the block at an amplitude of 0.5 % of its height, where large-strain
laws differ by O(amplitude^2)). The generalised eigenproblem

    K phi = omega^2 M phi

(consistent mass) is solved on quadratic (P2) tetrahedra at three meshes,
(2, 3, 4) k cells for k = 1, 2, 4, by shift-invert Lanczos (ARPACK) about
zero. The reference is the finest mesh; the two coarser ones give the
observed order and a Richardson estimate of the finest mesh's own error,
written to provenance.toml (the clamped base edges make the stress singular,
so the order is below P2's nominal 4 for eigenvalues).

Writes
  `frequencies.csv`: k, cells along z, dofs, omega_1..omega_3 (rad/s) per mesh;
  `mode.csv`: the first mode (finest mesh) at every node of the structured
  grid with (16, 24, 32) intervals -- the nodes of every block mesh the
  surgbench scene builds, levels 0..3 -- one row per node, x fastest, then
  y, then z (node (i, j, k) at (i LX/16, j LY/24, k LZ/32) is row
  i + 17 j + 17 * 25 k), as phi_x, phi_y, phi_z scaled so that phi_x = 1 at
  the top centre (LX/2, LY/2, LZ). The P2 field is evaluated there exactly
  (skfem probes), not interpolated.

Usage: python block_vibration.py OUTDIR
"""

import sys
import os
import numpy as np
import scipy
import scipy.sparse.linalg as sla
import skfem
from skfem import MeshTet, ElementTetP2, ElementVector, Basis, BilinearForm, asm
from skfem.helpers import dot
from skfem.models.elasticity import linear_elasticity, lame_parameters

LX, LY, LZ = 0.01, 0.015, 0.02  # m
E, NU, RHO = 5.0e3, 0.3, 1000.0  # Pa, -, kg/m^3
MESHES = (1, 2, 4)  # k: (2k, 3k, 4k) cells
GRID = (16, 24, 32)  # intervals of the output grid (surgbench mesh level 3)
MODES = 3


@BilinearForm
def mass(u, v, w):
    return RHO * dot(u, v)


def solve(k):
    """First MODES angular frequencies (rad/s), the basis and the first mode."""
    m = MeshTet.init_tensor(
        np.linspace(0, LX, 2 * k + 1), np.linspace(0, LY, 3 * k + 1), np.linspace(0, LZ, 4 * k + 1)
    )
    e = ElementVector(ElementTetP2())
    # Stiffness: products of P2 gradients, degree 2; mass: degree 4.
    K = asm(linear_elasticity(*lame_parameters(E, NU)), Basis(m, e, intorder=2))
    ib = Basis(m, e, intorder=4)
    M = asm(mass, ib)
    clamped = ib.get_dofs(lambda x: np.abs(x[2]) < 1e-12 * LZ).all()
    free = np.setdiff1d(np.arange(K.shape[0]), clamped)
    KI = K[free][:, free].tocsc()
    MI = M[free][:, free].tocsc()
    lu = sla.splu(KI, permc_spec="MMD_AT_PLUS_A")
    # Shift-invert about 0: the largest eigenvalues mu of K^-1 M are
    # 1 / omega^2 of the lowest modes. A fixed start vector: deterministic.
    op = sla.LinearOperator(KI.shape, matvec=lambda b: lu.solve(MI @ b), dtype=float)
    mu, vecs = sla.eigs(op, k=MODES, which="LM", v0=np.ones(KI.shape[0]), tol=1e-14)
    order = np.argsort(-mu.real)
    omega = np.sqrt(1.0 / mu.real[order])
    phi = np.zeros(K.shape[0])
    phi[free] = vecs[:, order[0]].real
    residual = np.linalg.norm(KI @ phi[free] - omega[0] ** 2 * (MI @ phi[free])) / np.linalg.norm(
        KI @ phi[free]
    )
    return omega, ib, phi, K.shape[0], residual


def main(out):
    rows, finest = [], None
    for k in MESHES:
        omega, ib, phi, dofs, residual = solve(k)
        rows.append((k, 4 * k, dofs, omega))
        finest = (ib, phi, omega, dofs, residual)
        print(f"block-vibration k={k}: {dofs} dofs, omega {np.array2string(omega, precision=6)} rad/s")
    ib, phi, omega, dofs, residual = finest
    g = [np.linspace(0, L, n + 1) for L, n in zip((LX, LY, LZ), GRID)]
    # x fastest, then y, then z (the order of the Rust reader).
    z, y, x = np.meshgrid(g[2], g[1], g[0], indexing="ij")
    pts = np.vstack([x.ravel(), y.ravel(), z.ravel()])
    top = np.array([[LX / 2], [LY / 2], [LZ]])
    n = pts.shape[1]
    vals = (ib.probes(pts) @ phi).reshape(3, n)
    top_x = (ib.probes(top) @ phi)[0]
    vals /= top_x
    # Observed order and Richardson estimate of the finest mesh's error
    # (meshes halve h: omega_h - omega ~ C h^p).
    w = [r[3][0] for r in rows]
    p = np.log((w[0] - w[1]) / (w[1] - w[2])) / np.log(2.0)
    extrapolated = w[2] - (w[1] - w[2]) / (2.0**p - 1.0)
    err = abs(w[2] - extrapolated) / extrapolated
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "frequencies.csv"), "w") as fh:
        fh.write("k,cells_z,dofs," + ",".join(f"omega_{i + 1}_rad_s" for i in range(MODES)) + "\n")
        for k, cz, d, om in rows:
            fh.write(f"{k},{cz},{d}," + ",".join(f"{o:.10e}" for o in om) + "\n")
    with open(os.path.join(out, "mode.csv"), "w") as fh:
        fh.write("phi_x,phi_y,phi_z\n")
        vals[vals == 0.0] = 0.0  # no "-0"
        for i in range(n):
            fh.write(f"{vals[0, i]:.7e},{vals[1, i]:.7e},{vals[2, i]:.7e}\n")
    with open(os.path.join(out, "provenance.toml"), "w") as fh:
        fh.write(f"omega_1_rad_s = {omega[0]:.10e}  # finest mesh: the reference\n")
        fh.write(f"period_s = {2 * np.pi / omega[0]:.10e}\n")
        fh.write(f"observed_order = {p:.3f}  # of omega_1 in h, from k = 1, 2, 4\n")
        fh.write(f"omega_1_extrapolated_rad_s = {extrapolated:.10e}  # Richardson, with the observed order\n")
        fh.write(f"reference_error_estimate_rel = {err:.3e}  # |finest - extrapolated| / extrapolated\n")
        fh.write(f"eigen_relative_residual = {residual:.3e}\n")
        fh.write(f"dofs = {dofs}\n")
        fh.write(
            f'versions = {{ scikit-fem = "{skfem.__version__}", numpy = "{np.__version__}", scipy = "{scipy.__version__}" }}\n'
        )
    print(
        f"block-vibration: omega_1 {omega[0]:.8e} rad/s (period {2 * np.pi / omega[0]:.6e} s), "
        f"order {p:.2f}, error estimate {err:.2e}, residual {residual:.1e}"
    )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
