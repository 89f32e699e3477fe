"""Static solve timing: surgbench's fem at its defaults against scikit-fem P1
on the same Lamé tube mesh, one after the other in one run (issue 20).

The mesh is the one `surgbench run-one --scenario lame-tube` builds at the
given mesh level (rebuilt here node for node: the quarter tube sector of
`mesh::tube_sector`, radius fastest, then angle, then height, each lattice
cell split into the same six tetrahedra), so both codes solve the same
discrete problem: linear tetrahedra, symmetry planes, plane-strain ends and
the internal pressure. scikit-fem solves linear elasticity with the
pressure as a dead load (P1), twice: with scipy's direct sparse solve
(spsolve) and with conjugate gradients preconditioned by pyamg's smoothed
aggregation (rigid-body modes as the near-null space, relative residual
1e-8: its error agrees with the direct solve's, printed to 9 digits);
surgbench's fem its default corotational law with the scene's pressure, a
follower load on the deformed wall: at u(a)/a = 4.4e-3 the two solutions
differ by 0.46 % of the largest displacement (measured node by node at
level 2), which moves the RMS error against the linear closed form between
1.2 % and 1.5 %, both the P1 mesh's error. Both are scored by the scenario's
primary metric, the RMS radial displacement error over all nodes relative
to u(a) of the closed form (Timoshenko and Goodier, Sec. 28, plane strain).

Times are wall-clock on whatever machine runs this: run it on a quiet one.
scikit-fem's time is assembly plus solve, the faster of two runs each (the
first call in a process also pays for imports and caches, which would
flatter surgbench); surgbench's is given as the solve (`solve_wall_s`, the
static step) and as build plus solve.

Usage: python static_solve_timing.py SURGBENCH_BINARY [MESH_LEVEL]
"""

import json
import subprocess
import sys
import tempfile
import time

import numpy as np
import pyamg
import skfem
from scipy.sparse.linalg import cg
from skfem import Basis, ElementTetP1, ElementVector, FacetBasis, LinearForm, MeshTet, asm, condense, solve
from skfem.helpers import dot
from skfem.models.elasticity import lame_parameters, linear_elasticity

# The tube: a = 2 mm, b = 3.5 mm, 5 mm long, E = 0.8 MPa, nu = 0.45, 1.6 kPa.
A, B, H = 0.002, 0.0035, 0.005
E, NU, P = 8e5, 0.45, 1600.0
KUHN = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]


def tube_mesh(level):
    """Nodes (3, N) and tets (4, T) of the scenario's mesh at `level`."""
    n_r = 2 << level
    n_t = 3 * n_r
    n_z = min(max(int(round(H / ((B - A) / n_r))), 1), 4 * n_r)
    i, j, k = np.meshgrid(np.arange(n_r + 1), np.arange(n_t + 1), np.arange(n_z + 1), indexing="ij")
    i, j, k = (a.transpose(2, 1, 0).ravel() for a in (i, j, k))  # radius fastest, then angle, then z
    r = A + (B - A) * i / n_r
    th = 0.5 * np.pi * j / n_t
    x = np.where(j == n_t, 0.0, r * np.cos(th))
    y = np.where(j == 0, 0.0, r * np.sin(th))
    p = np.vstack([x, y, H * k / n_z])

    def node(a, b, c):
        return a + (n_r + 1) * (b + (n_t + 1) * c)

    tets = []
    for c in range(n_z):
        for b in range(n_t):
            for a in range(n_r):
                corner = [node(a + (q & 1), b + ((q >> 1) & 1), c + ((q >> 2) & 1)) for q in range(8)]
                for t in KUHN:
                    tet = [corner[q] for q in t]
                    e = p[:, tet[1:]] - p[:, [tet[0]]]
                    if np.linalg.det(e) < 0:
                        tet[2], tet[3] = tet[3], tet[2]
                    tets.append(tet)
    return p, np.array(tets).T


def exact(r):
    return P * A**2 / (E * (B**2 - A**2)) * ((1 + NU) * (1 - 2 * NU) * r + (1 + NU) * B**2 / r)


def rms_radial_error(p, u):
    r = np.hypot(p[0], p[1])
    ur = (u[0] * p[0] + u[1] * p[1]) / r
    return np.sqrt(np.mean((ur - exact(r)) ** 2)) / exact(A)


def rigid_body_modes(ib):
    """(dofs, 6): the three translations and three rotations of the body at
    every DOF, the near-null space smoothed aggregation builds on."""
    x = ib.doflocs
    comp = np.zeros(x.shape[1], dtype=int)
    for k in range(3):
        comp[ib.nodal_dofs[k]] = k
    modes = np.zeros((x.shape[1], 6))
    for k in range(3):
        modes[comp == k, k] = 1.0
    # Rotation about axis a: displacement e_a x r.
    for a in range(3):
        r = np.zeros(3)
        r[a] = 1.0
        for k in range(3):
            on = comp == k
            modes[on, 3 + a] = np.cross(r, x[:, on].T)[:, k]
    return modes


def scikit_fem(p, t, amg):
    """Assembly plus solve of the tube by scikit-fem: (seconds, error, dofs);
    direct solve, or AMG-preconditioned CG when `amg`."""
    start = time.perf_counter()
    m = MeshTet(p, t)
    e = ElementVector(ElementTetP1())
    ib = Basis(m, e)
    K = asm(linear_elasticity(*lame_parameters(E, NU)), ib)
    mid = m.p[:, m.facets].mean(axis=1)
    fb = FacetBasis(m, e, facets=np.nonzero(np.hypot(mid[0], mid[1]) < A + 1e-9)[0])

    @LinearForm
    def pressure(v, w):
        return -P * dot(w.n, v)

    f = asm(pressure, fb)
    tol = 1e-12
    D = np.unique(np.concatenate([
        ib.get_dofs(lambda x: np.abs(x[1]) < tol).all("u^2"),
        ib.get_dofs(lambda x: np.abs(x[0]) < tol).all("u^1"),
        ib.get_dofs(lambda x: np.abs(x[2]) < tol).all("u^3"),
        ib.get_dofs(lambda x: np.abs(x[2] - H) < tol).all("u^3"),
    ]))
    if amg:
        Kc, fc, u, free = condense(K, f, D=D)
        rbm = rigid_body_modes(ib)[free]
        ml = pyamg.smoothed_aggregation_solver(Kc, B=rbm)
        uc, info = cg(Kc, fc, rtol=1e-8, M=ml.aspreconditioner())
        if info != 0:
            raise RuntimeError(f"AMG-CG did not converge ({info})")
        u = u.copy()
        u[free] = uc
    else:
        u = solve(*condense(K, f, D=D))
    seconds = time.perf_counter() - start
    # The nodal DOFs of each component, (3, N) in the mesh's node order.
    return seconds, rms_radial_error(p, u[ib.nodal_dofs]), K.shape[0]


def surgbench(exe, level):
    with tempfile.TemporaryDirectory() as d:
        out = f"{d}/run"
        params = {"inner_radius": A, "outer_radius": B, "height": H, "youngs_modulus": E,
                  "poisson_ratio": NU, "pressure": P}
        cmd = [exe, "run-one", "--scenario", "lame-tube", "--model", "fem", "--fidelity", f"mesh_level={level}",
               "--out", out, "--quiet"]
        for k, v in params.items():
            cmd += ["--param", f"{k}={v!r}"]
        subprocess.run(cmd, check=True)
        with open(f"{out}/summary.json") as fh:
            s = json.load(fh)
    return s["solve_wall_s"], s["build_ms"] / 1e3, s["errors"]["rms_radial_error_rel"], s["status"]


def main():
    exe = sys.argv[1]
    level = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    p, t = tube_mesh(level)
    print(f"Lamé tube, mesh level {level}: {p.shape[1]} nodes, {t.shape[1]} tets")
    solve_s, build_s, err_sb, status = surgbench(exe, level)
    print(f"surgbench fem (defaults): solve {solve_s:.3f} s, build + solve {build_s + solve_s:.3f} s, "
          f"rms radial error {err_sb:.4e} ({status})")
    for amg, name in ((False, "direct (spsolve)"), (True, "AMG-CG (pyamg smoothed aggregation, rtol 1e-8)")):
        runs = [scikit_fem(p, t, amg) for _ in range(2)]
        sk_s = min(r[0] for r in runs)
        _, err_sk, dofs = runs[-1]
        print(f"scikit-fem P1 {name}: {sk_s:.3f} s (assembly + solve, faster of "
              f"{', '.join(f'{r[0]:.3f}' for r in runs)} s; {dofs} dofs), rms radial error {err_sk:.8e}")
        print(f"  time ratio surgbench / scikit-fem {name.split()[0]}: solve {solve_s / sk_s:.3f}, "
              f"build + solve {(build_s + solve_s) / sk_s:.3f}")


if __name__ == "__main__":
    main()
