#!/usr/bin/env python3
"""Compare two surgbench results.csv files bit for bit, timings excepted.

Usage: compare-results.py A/results.csv B/results.csv

Both files must have the same rows in the same order and, in every column
except the timing ones (wall-clock figures that differ from run to run and
machine to machine: the fixed ones below and a model's timing diagnostics,
`diag_*_ms_mean`, e.g. the needle's time per step by phase) and `host`, the
very same text: results.csv writes each
number in its shortest round-trip form, so equal text is equal bits.
Exit 0 when they agree, 1 (with the differences listed) when they do not.
"""
import csv
import sys

# Wall-clock and memory figures: they change from run to run.
TIMING = {
    "ms_per_step_median",
    "ms_per_step_p95",
    "ms_per_step_max",
    "steps_per_s",
    "real_time_factor",
    "peak_rss_mb",
    "build_ms",
    "solve_wall_s",
    "host",
}


def is_timing(column):
    """A wall-clock column: a fixed one, or a model's timing diagnostic."""
    return column in TIMING or (column.startswith("diag_") and column.endswith("_ms_mean"))


def read(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return rows


def main():
    if len(sys.argv) != 3:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    a, b = (read(p) for p in sys.argv[1:])
    problems = []
    if len(a) != len(b):
        problems.append(f"{len(a)} rows in {sys.argv[1]}, {len(b)} in {sys.argv[2]}")
    cols_a = {c for c in a[0].keys() if not is_timing(c)} if a else set()
    cols_b = {c for c in b[0].keys() if not is_timing(c)} if b else set()
    if cols_a != cols_b:
        problems.append(f"columns differ: only in A {sorted(cols_a - cols_b)}, only in B {sorted(cols_b - cols_a)}")
    compared = 0
    for i, (ra, rb) in enumerate(zip(a, b), start=2):
        for c in sorted(cols_a & cols_b):
            compared += 1
            if ra[c] != rb[c]:
                what = f"{ra['scenario']} / {ra['model']} [{ra['fidelity']}]"
                problems.append(f"line {i} ({what}), column {c}: {ra[c]!r} vs {rb[c]!r}")
    if problems:
        print(f"results differ ({len(problems)} differences):")
        for p in problems[:50]:
            print("  " + p)
        return 1
    print(f"results agree: {len(a)} rows, {len(cols_a)} columns compared bit for bit ({compared} cells), timings excepted")
    return 0


if __name__ == "__main__":
    sys.exit(main())
