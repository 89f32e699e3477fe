"""surgbench from Python: run comparisons, read results as numpy arrays,
step any model, and score a model written in Python.

    import surgbench
    surgbench.scenarios()                       # ids, parameters, units, ranges
    r = surgbench.run_one("cantilever-gravity", "der", settings={"segments": 40})
    r.status, r.errors["tip_error_rel"], r.observables["hand_fz"], r.final_state
    sim = surgbench.Simulation("cantilever-gravity", "der"); sim.step(100); sim.state()
    surgbench.run("standard", quick=True, out="reports/out/py")   # the CLI's report

Everything runs the same Rust code as the `surgbench` command line (the
command line itself is `python -m surgbench`). SI units throughout: m, kg,
s, N, Pa. Scenarios that read data or comparison files find them in the
surgbench checkout the current folder is in, or in $SURGBENCH_ROOT.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

from . import _surgbench
from ._surgbench import (
    Diverged,
    RunResult,
    SceneView,
    Simulation,
    SimulationError,
    Unsupported,
    UsageError,
    models,
    run_one,
    scenarios,
)

__all__ = [
    "Diverged",
    "RunResult",
    "SceneView",
    "Simulation",
    "SimulationError",
    "Unsupported",
    "UsageError",
    "models",
    "register_model",
    "run",
    "run_one",
    "scenarios",
]

#: The Python models this process registered, for its child processes
#: (`surgbench.run` and the batch's `run-one` children import them again).
_ENV_MODELS = "SURGBENCH_PY_MODELS"
#: Set in a child process while it imports the models of its parent.
_ENV_CHILD = "SURGBENCH_LOADING_MODELS"

_registered: dict[str, type] = {}


def register_model(
    cls,
    id: str,
    description: str,
    family: str = "rod",
    capabilities=("rod",),
    defaults: dict | None = None,
) -> None:
    """Register a model class written in Python under `id`.

    The class is built with no arguments, then driven through three methods:

    - `build(scene)`: `scene` is a `SceneView` (bodies, materials, loads,
      gravity, timeline, vessel distance) with the resolved `settings`
      (`segments`, `dt`, ...). Raise `surgbench.Unsupported(reason)` for a
      scene the model cannot run.
    - `step(dt, command)`: advance by `dt` (s) under `command`
      (`insertion` m, `rotation` rad, `load` 1); return `None` or
      `{"iterations": int, "residual": float, "converged": bool}`. Raise
      `surgbench.Diverged(reason)` when the state is no longer usable.
    - `observe()`: a dict with `rods` (each `nodes`, `velocities`, `rest`
      as (n, 3) arrays in m and m/s, `arclength` (n,) m from the clamp,
      optional `frames` (n-1, 3, 3)), optional `tissues` (`nodes`, `rest`,
      `velocities`), `hand_force` (N, what the bodies exert on the hand),
      `hand_torque` (N m, about the clamp), `energy` (`kinetic`, `elastic`,
      `external`, J), `contacts` and `time` (s).

    Any other exception is a bug of the model: its run is `failed` with the
    message. `capabilities` names what the model can do (as `surgbench
    list` prints them); a scene needing more is `unsupported`. `defaults`
    gives the common settings and must include `dt` (s). Reports show the
    model as Python. The class must be importable by a child process: put
    it in a module, or guard a script's top level with
    `if __name__ == "__main__":` (the module is imported again, as
    multiprocessing does).
    """
    if _registered.get(id) is cls:
        return
    _surgbench.register_model(cls, id, description, family, list(capabilities), dict(defaults or {}))
    _registered[id] = cls
    entry = {
        "id": id,
        "module": cls.__module__,
        "qualname": cls.__qualname__,
        "file": inspect.getsourcefile(cls) or "",
        "path": list(sys.path),
        "description": description,
        "family": family,
        "capabilities": list(capabilities),
        "defaults": dict(defaults or {}),
    }
    entries = [e for e in json.loads(os.environ.get(_ENV_MODELS, "[]")) if e["id"] != id]
    os.environ[_ENV_MODELS] = json.dumps(entries + [entry])


def _load_class(entry: dict):
    """The class a parent process registered, imported again here."""
    for p in entry.get("path", []):
        if p not in sys.path:
            sys.path.append(p)
    module = None
    if entry["module"] != "__main__":
        try:
            module = importlib.import_module(entry["module"])
        except ImportError:
            module = None
    if module is None:
        name = "__surgbench_main__"
        module = sys.modules.get(name)
        if module is None:
            spec = importlib.util.spec_from_file_location(name, entry["file"])
            if spec is None or spec.loader is None:
                raise ImportError(f"cannot import the module of model `{entry['id']}` from {entry['file']!r}")
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
    obj = module
    for part in entry["qualname"].split("."):
        obj = getattr(obj, part)
    return obj


def _register_inherited() -> None:
    """Register, in a child process, the Python models its parent did."""
    entries = json.loads(os.environ.get(_ENV_MODELS, "[]"))
    if not entries:
        return
    os.environ[_ENV_CHILD] = "1"
    try:
        for e in entries:
            cls = _load_class(e)
            if e["id"] not in _registered:
                register_model(cls, e["id"], e["description"], e["family"], e["capabilities"], e["defaults"])
    finally:
        os.environ.pop(_ENV_CHILD, None)


def run(
    comparison: str = "standard",
    quick: bool = False,
    out: str | os.PathLike | None = None,
    models: list[str] | None = None,
    threads: int | None = None,
    repeats: int | None = None,
    timeout: float | None = None,
    force: bool = False,
    quiet: bool = True,
) -> Path | None:
    """Run a comparison and write its report, as `surgbench run` does (each
    run isolated in a child process; the Python models registered here run
    too). Returns `out` as a path (`None`: the CLI's default folder,
    reports/out/latest in the project root); raises `UsageError` on bad input (the
    CLI's exit 2) and `RuntimeError` when the run fails."""
    if os.environ.get(_ENV_CHILD):
        raise RuntimeError(
            "surgbench.run() was called while a child process imported a model's module: "
            'guard the script\'s top level with `if __name__ == "__main__":`'
        )
    argv = [sys.executable, "-m", "surgbench", "run", comparison]
    if quick:
        argv.append("--quick")
    if out is not None:
        argv += ["--out", os.fspath(out)]
    if models:
        argv += ["--models", ",".join(models)]
    if threads is not None:
        argv += ["--threads", str(threads)]
    if repeats is not None:
        argv += ["--repeats", str(repeats)]
    if timeout is not None:
        argv += ["--timeout", str(timeout)]
    if force:
        argv.append("--force")
    if quiet:
        argv.append("--quiet")
    code = subprocess.run(argv).returncode
    if code == 2:
        raise UsageError(f"surgbench run {comparison}: bad input (see the message above)")
    if code != 0:
        raise RuntimeError(f"surgbench run {comparison} exited with {code}")
    return Path(out) if out is not None else None
