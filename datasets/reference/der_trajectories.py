"""Converged DER tip trajectories that `arch-insertion`, `flow-drift` and
`coronary-beating` score every rod model against (default parameters only), computed through
the Python bindings (README "From Python"): DER runs each scene at two
resolutions (segments N and 2N, time step dt and dt/2); the finer run is
written to <scenario>/tip_trajectory.csv and the largest distance between
the two tip trajectories is its stated discretization error (in the CSV's
comment header and meta.toml). A run that does not end `ok` writes nothing
for that scenario.

Usage: python datasets/reference/der_trajectories.py [scenario...]
Env: SEGMENTS (default 80), DT (default 5e-4 s).
Not run by CI (minutes of compute); rerun after a change to DER or to these
scenes, and commit the result. SI units (m, s).
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

import surgbench

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def tip_trajectory(scenario: str, segments: int, dt: float):
    """DER's sampled tip trajectory: times (s) and tip positions (m)."""
    r = surgbench.run_one(scenario, "der", settings={"segments": segments, "dt": dt})
    if r.status != "ok":
        raise RuntimeError(f"{scenario}: DER at segments={segments} dt={dt} ended {r.status!r}: {r.reason!r}")
    o = r.observables
    return o["t"], np.stack([o["tip_x"], o["tip_y"], o["tip_z"]], axis=1)


def at(t_src, p_src, t):
    """The trajectory (t_src, p_src) linearly interpolated at times t, held
    at its first and last samples outside its span."""
    return np.stack([np.interp(t, t_src, p_src[:, k]) for k in range(3)], axis=1)


def write(out: Path, scenario: str, n: int, dt: str, n2: int, dt2: float, commit: str) -> str:
    """Run both resolutions, write the two files; `dt` as given (text)."""
    t_a, p_a = tip_trajectory(scenario, n, float(dt))
    t_b, p_b = tip_trajectory(scenario, n2, dt2)
    diff = float(np.max(np.linalg.norm(p_b - at(t_a, p_a, t_b), axis=1)))
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "tip_trajectory.csv", "w") as f:
        f.write(f"# converged DER tip trajectory for `{scenario}` (default parameters), m and s\n")
        f.write(f"# fine: segments={n2} dt={dt2}; coarse: segments={n} dt={dt}; commit {commit}\n")
        f.write(f"# max |tip_fine(t) - tip_coarse(t)| = {diff:.3e} m (the reference's discretization error)\n")
        f.write("t,x,y,z\n")
        for t, p in zip(t_b.tolist(), p_b.tolist()):
            f.write(f"{t!r},{p[0]!r},{p[1]!r},{p[2]!r}\n")
    with open(out / "meta.toml", "w") as f:
        f.write(f'scenario = "{scenario}"\nmodel = "der"\nfine = {{ segments = {n2}, dt = {dt2} }}\n')
        f.write(f'coarse = {{ segments = {n}, dt = {dt} }}\ncommit = "{commit}"\n')
        f.write(f"max_tip_difference_m = {diff:.6e}\n")
        f.write('command = "datasets/reference/der_trajectories.py"\n')
    return f"{scenario}: {len(t_b)} samples, coarse-fine max tip distance {diff:.3e} m"


def main(argv: list[str]) -> int:
    scenarios = argv or ["arch-insertion", "flow-drift", "coronary-beating"]
    n = int(os.environ.get("SEGMENTS", "80"))
    dt = os.environ.get("DT", "5e-4")
    n2, dt2 = 2 * n, float(dt) / 2
    commit = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip() or "unknown"
    status = 0
    for sc in scenarios:
        try:
            print(write(HERE / sc, sc, n, dt, n2, dt2, commit))
        except RuntimeError as e:
            print(e, file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
