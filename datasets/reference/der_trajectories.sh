#!/usr/bin/env bash
# Compute the converged DER tip trajectories that `arch-insertion` and
# `flow-drift` score every rod model against (default parameters only):
# DER runs each scene at two resolutions (segments N and 2N, time step dt and
# dt/2); the finer run is written to <scenario>/tip_trajectory.csv and the
# largest distance between the two tip trajectories is its stated
# discretization error (in the CSV's comment header and meta.toml).
# A run that does not finish `ok` writes nothing for that scenario.
#
# Usage: datasets/reference/der_trajectories.sh [scenario...]
# Env: SURGBENCH (default: target/release/surgbench, built if missing),
#      SEGMENTS (default 80), DT (default 5e-4 s).
# Not run by CI (minutes of compute); rerun after a change to DER or to
# these scenes, and commit the result.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${SURGBENCH:-$root/target/release/surgbench}"
if [ ! -x "$bin" ]; then
  (cd "$root" && cargo build --release --quiet)
fi
n="${SEGMENTS:-80}"
dt="${DT:-5e-4}"
n2=$((2 * n))
dt2="$(python3 -c "print($dt / 2)")"
scenarios=("$@")
[ ${#scenarios[@]} -eq 0 ] && scenarios=(arch-insertion flow-drift)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
status=0
for sc in "${scenarios[@]}"; do
  "$bin" run-one --model der --scenario "$sc" --fidelity "segments=$n" --fidelity "dt=$dt" --out "$tmp/$sc-coarse" --quiet
  "$bin" run-one --model der --scenario "$sc" --fidelity "segments=$n2" --fidelity "dt=$dt2" --out "$tmp/$sc-fine" --quiet
  if ! python3 - "$tmp/$sc-coarse" "$tmp/$sc-fine" "$here/$sc" "$sc" "$n" "$dt" "$n2" "$dt2" \
      "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" <<'PYEOF'
import csv, json, math, os, sys
coarse, fine, out, sc, n, dt, n2, dt2, commit = sys.argv[1:]
def load(d):
    s = json.load(open(os.path.join(d, "summary.json")))
    if s.get("status") != "ok":
        sys.exit(f"{sc}: DER run in {d} ended {s.get('status')!r}: {s.get('reason')!r}; no reference written")
    rows = list(csv.DictReader(open(os.path.join(d, "observables.csv"))))
    return [(float(r["t"]), (float(r["tip_x"]), float(r["tip_y"]), float(r["tip_z"]))) for r in rows]
a, b = load(coarse), load(fine)
def at(tr, t):
    if t <= tr[0][0]:
        return tr[0][1]
    for (t0, p0), (t1, p1) in zip(tr, tr[1:]):
        if t0 <= t <= t1:
            w = (t - t0) / (t1 - t0)
            return tuple(p0[k] + w * (p1[k] - p0[k]) for k in range(3))
    return tr[-1][1]
diff = max(math.dist(p, at(a, t)) for t, p in b)
os.makedirs(out, exist_ok=True)
with open(os.path.join(out, "tip_trajectory.csv"), "w") as f:
    f.write(f"# converged DER tip trajectory for `{sc}` (default parameters), m and s\n")
    f.write(f"# fine: segments={n2} dt={dt2}; coarse: segments={n} dt={dt}; commit {commit}\n")
    f.write(f"# max |tip_fine(t) - tip_coarse(t)| = {diff:.3e} m (the reference's discretization error)\n")
    f.write("t,x,y,z\n")
    for t, p in b:
        f.write(f"{t!r},{p[0]!r},{p[1]!r},{p[2]!r}\n")
with open(os.path.join(out, "meta.toml"), "w") as f:
    f.write(f'scenario = "{sc}"\nmodel = "der"\nfine = {{ segments = {n2}, dt = {dt2} }}\n')
    f.write(f'coarse = {{ segments = {n}, dt = {dt} }}\ncommit = "{commit}"\n')
    f.write(f"max_tip_difference_m = {diff:.6e}\n")
    f.write('command = "datasets/reference/der_trajectories.sh"\n')
print(f"{sc}: {len(b)} samples, coarse-fine max tip distance {diff:.3e} m")
PYEOF
  then
    status=1
  fi
done
exit $status
