"""The `bsfjax` command (`python -m bsfjax.cli` runs it too): `bsfjax --help` lists its commands."""

import sys

from ._cli import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
