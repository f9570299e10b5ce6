"""``bsfjax example``, ``demo`` and ``spectrum``."""

from __future__ import annotations

from pathlib import Path

from ._io import CLIError


def _cmd_example(args) -> int:
    from .._util import write_text_atomic
    from ._demo import example_landmarks
    from .._mesh import example_pair
    from .._mesh import save_mesh

    if not 1 <= args.levels <= 4:
        raise CLIError(f"--levels must be in [1, 4], got {args.levels}")
    pair = example_pair(levels=args.levels)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save_mesh(out / "source.ply", pair.source)
    save_mesh(out / "target.ply", pair.target)
    lines = lambda a: "\n".join(str(int(x)) for x in a) + "\n"  # noqa: E731
    write_text_atomic(out / "labels.txt", lines(pair.labels))
    write_text_atomic(out / "target_labels.txt", lines(pair.labels[pair.p2p]))
    write_text_atomic(out / "p2p.txt", lines(pair.p2p))
    lm = ",".join(str(int(i)) for i in example_landmarks(pair))
    write_text_atomic(out / "landmarks.txt", f"{lm}:{lm}\n")
    print(f"wrote the built-in pair ({pair.source.n_vertices} vertices, "
          f"{len(pair.label_names)} parts: {', '.join(pair.label_names)}) to {out}/:\n"
          "  source.ply, target.ply    the two poses (vertex i <-> vertex i)\n"
          "  labels.txt                part label per source vertex\n"
          "  target_labels.txt         ground-truth part label per target vertex\n"
          "  p2p.txt                   ground-truth point map (source vertex per target vertex)\n"
          "  landmarks.txt             one landmark per part, 'source:target'\n"
          f"try:\n  bsfjax transfer {out}/source.ply {out}/target.ply --labels {out}/labels.txt "
          f"--landmarks {lm}:{lm} --truth {out}/target_labels.txt --out labels_out.txt "
          "--mesh-out coloured.ply")
    return 0


def _cmd_demo(args) -> int:
    from ._demo import format_table, run_demo

    print("bsfjax demo: the whole pipeline on the built-in example pair", flush=True)
    results = run_demo(args.out, k=args.k, n_functions=args.functions, seed=args.seed,
                       figures=not args.no_figures)
    print()
    print(format_table(results))
    print(f"\nwrote {Path(args.out) / 'results.json'}"
          + (f" and {len(results.get('figures', []))} PNG figures" if not args.no_figures else ""))
    return 0


def _cmd_spectrum(args) -> int:
    import numpy as np

    from .._util import atomic_path
    from .._mesh import load_mesh
    from .._spectral import spectrum

    if Path(args.out).suffix != ".npz":
        raise CLIError(f"--out {args.out}: use a .npz file name")
    mesh = load_mesh(args.mesh)
    spec = spectrum(mesh, args.k, method=args.method)
    # one row per row of the mesh file: NaN eigenvector rows and zero mass where the reader
    # dropped a row (an unreferenced vertex), so the rows never shift
    evecs = mesh.to_file_rows(np.asarray(spec.evecs))
    mass = mesh.to_file_rows(np.asarray(spec.mass), fill=0.0)
    with atomic_path(args.out) as tmp, open(tmp, "wb") as fh:  # a handle: savez adds no suffix
        np.savez(fh, evals=spec.evals, evecs=evecs, mass=mass)
    dropped = mesh.dropped_rows
    print(f"{args.mesh}: {mesh.n_vertices} vertices, k={args.k}, method={args.method}, "
          f"lambda_2={spec.evals[1] if spec.k > 1 else 0:.6g}, wrote {args.out}"
          + (f" ({dropped} file rows without a surface: NaN rows, zero mass)" if dropped else ""))
    return 0
