"""Two models on one scene, error against time: a notebook-style example.

    python python/examples/compare.py                       # der vs the numpy mass-spring rod
    python python/examples/compare.py --scenario cantilever-tip-load --models der,pbd-rod --out tip.png

Each model runs through `surgbench.run_one`, the same runner, watchdogs and
scoring as `surgbench run-one`; the plot is the scene's primary error
(`observables["error"]`, relative, against the scene's reference) over
simulated time, with each run's summary in the legend. Run it from the
surgbench checkout (or set SURGBENCH_ROOT). The Python model of
`mass_spring.py` (beside this file) is registered first, so it can be one
of the two.
"""

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import mass_spring  # noqa: E402

import surgbench  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="cantilever-gravity")
    ap.add_argument("--models", default="der,py-mass-spring", help="two or more model ids, comma-separated")
    ap.add_argument("--segments", type=int, default=20)
    ap.add_argument("--out", default="compare.png", help="the figure (PNG or SVG)")
    args = ap.parse_args()

    mass_spring.register()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for model in args.models.split(","):
        r = surgbench.run_one(args.scenario, model, settings={"segments": args.segments})
        print(r)
        if r.status != "ok":
            continue
        t, err = r.observables["t"], r.observables["error"]
        label = f"{model}: {r.primary_error} {r.primary:.2e} at the end, {r.ms_per_step_median:.3f} ms/step"
        ax.semilogy(t, err, label=label)
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("primary error (relative)")
    ax.set_title(f"{args.scenario}, {args.segments} segments")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
