"""`python -m surgbench ...`: the `surgbench` command line, with the Python
models of the parent process (`surgbench.run`) registered first."""

import sys

from . import _register_inherited, _surgbench


def main() -> int:
    _register_inherited()
    return _surgbench.cli(["surgbench", *sys.argv[1:]])


if __name__ == "__main__":
    sys.exit(main())
