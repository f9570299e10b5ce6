"""The ``bsfjax`` command line."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="bsfjax",
        description="Binary Sparse Frames: sparse representation and transfer of step functions "
                    "(segmentations, part labels, region indicators) between shapes.",
    )
    parser.add_argument("--version", action="version", version=f"bsfjax {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    p = sub.add_parser("spectrum", help="compute and cache the Laplace-Beltrami spectrum of a mesh")
    p.add_argument("mesh", help="mesh file (OFF, PLY, OBJ, STL, ...)")
    p.add_argument("-k", type=int, default=100, help="number of eigenpairs (default 100)")
    p.add_argument("--out", required=True, help="output .npz with evals, evecs, mass")
    p.set_defaults(func=_cmd_spectrum)
    return parser


def _cmd_spectrum(args) -> int:
    import numpy as np

    from ._files import atomic_path
    from .mesh import load_mesh
    from .spectrum import spectrum

    mesh = load_mesh(args.mesh)
    spec = spectrum(mesh, args.k)
    with atomic_path(args.out) as tmp:
        np.savez(tmp, evals=spec.evals, evecs=spec.evecs, mass=spec.mass)
    print(f"{args.mesh}: {mesh.n_vertices} vertices, k={args.k}, "
          f"lambda_2={spec.evals[1] if spec.k > 1 else 0:.6g}, wrote {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:  # bad input: one line, no traceback
        print(f"bsfjax {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
