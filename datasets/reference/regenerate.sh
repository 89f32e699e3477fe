#!/usr/bin/env bash
# Regenerate every scikit-fem reference into a temporary folder and compare
# with the committed CSVs. Exit non-zero on drift (|new - old| > RTOL * max|old|
# per column) or on any failure. Usage: datasets/reference/regenerate.sh
# Env: VENV (default: a temporary venv), PYTHON (default python3), RTOL (1e-6),
#      UPDATE=1 copies the new files over the committed ones instead of failing.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
py="${PYTHON:-python3}"
rtol="${RTOL:-1e-6}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
venv="${VENV:-$tmp/venv}"
if [ ! -x "$venv/bin/python" ]; then
  "$py" -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check -r "$here/requirements.txt"
fi
status=0
for pair in "lame_tube.py:lame-tube" "block_compression.py:block-compression" "wall_punch.py:wall-punch" "wall_indentation.py:wall-indentation" "block_vibration.py:block-vibration"; do
  script="${pair%%:*}"; name="${pair##*:}"
  "$venv/bin/python" "$here/$script" "$tmp/$name"
  for csv in "$here/$name"/*.csv; do
    new="$tmp/$name/$(basename "$csv")"
    if [ "${UPDATE:-0}" = "1" ]; then
      cp "$tmp/$name"/* "$here/$name/"
      continue
    fi
    if ! "$venv/bin/python" - "$csv" "$new" "$rtol" <<'PYEOF'
import sys, numpy as np
old = np.loadtxt(sys.argv[1], delimiter=",", skiprows=1, ndmin=2)
new = np.loadtxt(sys.argv[2], delimiter=",", skiprows=1, ndmin=2)
rtol = float(sys.argv[3])
if old.shape != new.shape:
    sys.exit(f"{sys.argv[1]}: shape {old.shape} -> {new.shape}")
scale = np.maximum(np.abs(old).max(axis=0), 1e-300)
drift = (np.abs(new - old) / scale).max(axis=0)
print(f"{sys.argv[1]}: max drift per column {np.array2string(drift, precision=2)} (rtol {rtol})")
sys.exit(1 if (drift > rtol).any() else 0)
PYEOF
    then
      echo "DRIFT: $csv" >&2
      status=1
    fi
  done
done
exit $status
