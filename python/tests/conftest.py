"""Shared setup of the bindings' tests: the checkout's root (scenarios read
their data from it), the CLI to compare against, and the example models on
the import path."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
os.environ.setdefault("SURGBENCH_ROOT", str(ROOT))
# The example models (python/examples) and this folder's test models are
# imported by name, here and in the child processes of a batch.
for p in (ROOT / "python" / "examples", Path(__file__).resolve().parent):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))


def cli_command() -> list[str]:
    """The `surgbench` binary to compare with: $SURGBENCH_BIN, else the
    release build in the checkout, else the bindings' own command line."""
    exe = os.environ.get("SURGBENCH_BIN")
    if exe:
        return [exe]
    built = ROOT / "target" / "release" / "surgbench"
    if built.is_file():
        return [str(built)]
    return [sys.executable, "-m", "surgbench"]


@pytest.fixture
def cli():
    """Run the command line; returns the completed process."""

    def run(*args: str, check: bool = True) -> subprocess.CompletedProcess:
        p = subprocess.run([*cli_command(), *args], capture_output=True, text=True)
        if check and p.returncode != 0:
            raise AssertionError(f"{' '.join(args)} exited {p.returncode}:\n{p.stderr}")
        return p

    return run
