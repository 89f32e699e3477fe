"""A quasi-static mass-spring rod in numpy: a model written in Python that
surgbench runs, scores and reports like its Rust models.

The rod is a chain of n + 1 point masses (and a massless ghost node at
the clamp, below) joined by axial springs
k = EA/h (h = L/n) with an angular spring at every interior node whose
energy is (EI/h)(1 - cos phi), phi the turning angle between the two edges
there. For small phi this is EI phi^2 / (2h), the bending energy
int EI kappa^2 / 2 ds of a rod with curvature phi/h over one edge length
(the discrete curvature of a polygon, e.g. Bergou et al., "Discrete elastic
rods", SIGGRAPH 2008, Sec. 4.2). Gravity acts on lumped masses rho A h
(half at the ends). The clamp holds two nodes, the base and a ghost node
one edge behind it along the clamp's tangent, as DER clamps its rod. The
base node's angle is then between the clamp tangent and the first edge,
about kappa h / 2, and it stands for the bending of the half edge [0, h/2]
only, so its spring is 2 EI / h: (EI / 2) (2 phi / h)^2 (h / 2) = EI phi^2 / h.
(With EI / h there, the rod behaves as if clamped h/2 behind the base, and
the tip error falls at first order only: 21 %, 10 %, 5 % at 10, 20, 40
segments.)

Each `step` finds the static equilibrium under the load of that instant
by Newton's method on the total potential energy (the stiffness matrix by
central differences of the analytic forces), so a static scene settles in
a few steps; velocities are displacement over the step. It models a rod
without twist, contact or flow, and says so through its capabilities: a
scene that needs more is `unsupported` with the reason.

On `cantilever-gravity` its tip converges to Euler-Bernoulli at second
order (1.0e-2, 2.5e-3, 6.2e-4 at 10, 20, 40 segments). Register it with
`register()`; then `surgbench.run_one("cantilever-gravity",
"py-mass-spring")`. SI units throughout.
"""

import numpy as np

import surgbench


class MassSpringRod:
    """Point masses, axial springs and angular springs; static Newton solve."""

    #: Newton iterations at most per step, and the tolerance on the largest
    #: node update (m) relative to the rod length.
    max_newton = 25
    tol = 1e-13

    def build(self, scene):
        if len(scene.rods) != 1 or scene.tissues:
            raise surgbench.Unsupported("the mass-spring rod runs scenes with one rod and no tissue")
        rod = scene.rods[0]
        if len(rod["sections"]) != 1:
            raise surgbench.Unsupported("the mass-spring rod has one section (uniform material)")
        sec = rod["sections"][0]
        n = int(scene.settings.get("segments", 20))
        self.L = rod["length"]
        self.h = self.L / n
        self.k_axial = sec["youngs_modulus"] * sec["area"] / self.h
        # Angular springs at the base node and the n - 1 nodes past it.
        self.k_bend = np.full(n, sec["youngs_modulus"] * sec["second_moment"] / self.h)
        self.k_bend[0] *= 2.0
        base = rod["base"]
        # Arclength from the clamp: the ghost node at -h, the base at 0.
        s = np.arange(-1, n + 1) * self.h
        local = np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=1)
        self.rest = local @ base[:3, :3].T + base[:3, 3]
        self.s = s
        self.x = self.rest.copy()
        self.v = np.zeros_like(self.x)
        # Lumped masses of the rod on [0, L]; the ghost node has none.
        m = np.full(n + 2, sec["density"] * sec["area"] * self.h)
        m[0] = 0.0
        m[1] *= 0.5
        m[-1] *= 0.5
        self.weight = m[:, None] * scene.gravity[None, :]
        self.tip_force = rod["tip_force"]
        self.free = np.arange(2, n + 2)

    def energy(self, x):
        """Elastic energy and the potential of gravity and the tip load (J)."""
        e = np.diff(x, axis=0)
        le = np.linalg.norm(e, axis=1)
        stretch = 0.5 * self.k_axial * np.sum((le - self.h) ** 2)
        t = e / le[:, None]
        cos_phi = np.sum(t[:-1] * t[1:], axis=1)
        bend = np.sum(self.k_bend * (1.0 - cos_phi))
        external = -np.sum(self.weight * x) - self.tip_force @ x[-1]
        return stretch + bend, external

    def forces(self, x):
        """Minus the gradient of the total potential, per node (N)."""
        e = np.diff(x, axis=0)
        le = np.linalg.norm(e, axis=1)
        t = e / le[:, None]
        f = np.zeros_like(x)
        # Axial springs: dE/de = k (|e| - h) t.
        g_e = self.k_axial * (le - self.h)[:, None] * t
        # Angular springs: d(t_a . t_b)/de_a = (t_b - (t_a . t_b) t_a) / |e_a|.
        ta, tb = t[:-1], t[1:]
        c = np.sum(ta * tb, axis=1)[:, None]
        k = self.k_bend[:, None]
        g_e[:-1] -= k * (tb - c * ta) / le[:-1, None]
        g_e[1:] -= k * (ta - c * tb) / le[1:, None]
        # e_i = x_{i+1} - x_i.
        f[1:] -= g_e
        f[:-1] += g_e
        f += self.weight
        f[-1] += self.tip_force
        return f

    def step(self, dt, command):
        x = self.x.copy()
        free = self.free
        dof = 3 * len(free)
        eps = 1e-7 * self.h
        iters = 0
        for iters in range(1, self.max_newton + 1):
            r = self.forces(x)[free].ravel()
            K = np.empty((dof, dof))
            for j in range(dof):
                xp, xm = x.copy(), x.copy()
                node, axis = free[j // 3], j % 3
                xp[node, axis] += eps
                xm[node, axis] -= eps
                K[:, j] = -(self.forces(xp)[free] - self.forces(xm)[free]).ravel() / (2 * eps)
            dx = np.linalg.solve(0.5 * (K + K.T), r)
            x[free] += dx.reshape(-1, 3)
            if np.max(np.abs(dx)) < self.tol * self.L:
                break
        self.v = (x - self.x) / dt
        self.x = x
        return {"iterations": iters, "converged": iters < self.max_newton}

    def observe(self):
        f = self.forces(self.x)
        held = f[:2]
        # About the clamp: the base node, index 1 (the ghost node is 0).
        torque = np.cross(self.x[:2] - self.x[1], held).sum(axis=0)
        elastic, external = self.energy(self.x)
        return {
            "rods": [
                {
                    "nodes": self.x,
                    "velocities": self.v,
                    "rest": self.rest,
                    "arclength": self.s,
                }
            ],
            "hand_force": held.sum(axis=0),
            "hand_torque": torque,
            "energy": {"kinetic": 0.0, "elastic": elastic, "external": external},
        }


def register():
    """Register the model as `py-mass-spring` (once per process)."""
    surgbench.register_model(
        MassSpringRod,
        id="py-mass-spring",
        description="quasi-static mass-spring rod in numpy (axial and angular springs, Newton solve)",
        family="rod",
        capabilities=["rod", "tip-force"],
        defaults={"segments": 20, "dt": 1e-3},
    )
