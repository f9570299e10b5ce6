"""The package's layer contract, and a checker for it (used by tests/test_layout.py and by
docs/gen_architecture.py).

bsfjax is a stack of private sub-packages, one per pipeline stage, and data flows upwards
through it: a module may import any module of its own sub-package, but another sub-package only
through that sub-package's public names (``from .._spectral import Spectrum``), never one of its
private modules or underscore names, and only a sub-package of a lower layer.  Imports inside
functions count.  No import circle, between modules or between sub-packages.  The top-level
modules (``bsfjax/__init__.py``, ``internal.py``, ``plot.py``, ``cli.py``) sit above every layer
and obey the same rule for what they import.
"""

from __future__ import annotations

import ast
from pathlib import Path

#: The layers, bottom to top.  Sub-packages in one layer are independent of each other.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("_util",),
    ("_mesh",),
    ("_spectral",),
    ("_sampling",),
    ("_frame", "_maps", "_metrics"),
    ("_coding",),
    ("_transfer",),
    ("_pipeline",),
    ("_plot",),
    ("experiments",),
    ("_cli",),
)
TOP = "<top>"  # the top-level modules: above every layer
MAX_LINES = 500

RANK = {pkg: i for i, layer in enumerate(LAYERS) for pkg in layer}
RANK[TOP] = len(LAYERS)


def _module_key(root: Path, path: Path) -> tuple[str, str]:
    """(sub-package or TOP, module name) of a file; a package's own ``__init__``."""
    rel = path.relative_to(root).with_suffix("").parts
    if len(rel) == 1:
        return TOP, rel[0]
    return rel[0], ".".join(rel[1:])


def _targets(root: Path, path: Path, node: ast.AST):
    """Every (absolute dotted module, imported names) an import node brings in, relative to the
    package root ``bsfjax``."""
    pkg_parts = list(path.relative_to(root).parent.parts)
    if isinstance(node, ast.ImportFrom):
        if node.level == 0:
            if node.module and node.module.split(".")[0] == root.name:
                yield node.module.split(".")[1:], [a.name for a in node.names]
            return
        base = pkg_parts[:len(pkg_parts) - (node.level - 1)] if node.level > 1 else pkg_parts
        if node.level - 1 > len(pkg_parts):
            return
        mod = base + (node.module.split(".") if node.module else [])
        yield mod, [a.name for a in node.names]
    elif isinstance(node, ast.Import):
        for a in node.names:
            parts = a.name.split(".")
            if parts[0] == root.name:
                yield parts[1:], []


def check_package(root: Path) -> list[str]:
    """Every breach of the layer contract in the package at ``root`` (a list of lines; empty
    when the package keeps it): imports upward or sideways between sub-packages, private
    modules or names taken across sub-packages, import circles, and modules over
    ``MAX_LINES`` lines."""
    root = Path(root)
    problems: list[str] = []
    files = sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)
    modules = {}
    for path in files:
        pkg, mod = _module_key(root, path)
        modules[(pkg, mod)] = path
    edges: dict[tuple[str, str], set[tuple[str, str]]] = {k: set() for k in modules}

    def node_of(parts: list[str]):
        """The module node that an absolute import path names (a package: its __init__)."""
        if not parts:
            return (TOP, "__init__")
        if len(parts) == 1:
            if (parts[0], "__init__") in modules:
                return (parts[0], "__init__")
            return (TOP, parts[0]) if (TOP, parts[0]) in modules else None
        key = (parts[0], ".".join(parts[1:]))
        if key in modules:
            return key
        key = (parts[0], ".".join(parts[1:]) + ".__init__")
        return key if key in modules else None

    for (pkg, mod), path in modules.items():
        text = path.read_text()
        n_lines = len(text.splitlines())
        where = path.relative_to(root.parent)
        if n_lines > MAX_LINES:
            problems.append(f"{where}: {n_lines} lines (more than {MAX_LINES})")
        for node in ast.walk(ast.parse(text)):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for parts, names in _targets(root, path, node):
                line = f"{where}:{node.lineno}"
                dotted = ".".join([root.name, *parts])
                # names may be modules (from . import _x): each is its own target
                targets = [parts]
                if isinstance(node, ast.ImportFrom):
                    sub = [parts + [n] for n in names if node_of(parts + [n]) is not None
                           and node_of(parts + [n]) != node_of(parts)]
                    targets = sub or [parts]
                for t in targets:
                    target = node_of(t)
                    if target is not None and target != (pkg, mod):
                        edges[(pkg, mod)].add(target)
                if not parts:  # the top-level package itself
                    if pkg != TOP:
                        problems.append(f"{line}: imports the top-level package {root.name} "
                                        "(upward)")
                    continue
                tpkg = parts[0] if (parts[0], "__init__") in modules else TOP
                if tpkg == pkg:
                    continue
                if tpkg == TOP:
                    if pkg != TOP:
                        problems.append(f"{line}: imports the top-level module {dotted} (upward)")
                    continue
                if RANK[tpkg] >= RANK[pkg]:
                    kind = "sideways" if RANK[tpkg] == RANK[pkg] else "upward"
                    problems.append(f"{line}: {pkg} imports {tpkg} ({kind}; layers: "
                                    f"{' < '.join('|'.join(layer) for layer in LAYERS)})")
                if len(parts) > 1:
                    problems.append(f"{line}: imports the private module {dotted} of another "
                                    f"sub-package (import from {root.name}.{tpkg})")
                private = [n for n in names if n.startswith("_")]
                if private:
                    problems.append(f"{line}: imports private name(s) {', '.join(private)} "
                                    f"from another sub-package {tpkg}")
    problems += [f"import circle: {' -> '.join(_fmt(n) for n in cycle)}"
                 for cycle in _cycles(edges)]
    return problems


def _fmt(node: tuple[str, str]) -> str:
    pkg, mod = node
    return mod if pkg == TOP else f"{pkg}.{mod}"


def _cycles(edges) -> list[list]:
    """The strongly connected components of more than one module (Tarjan), each as a list."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    import sys
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10_000))
    try:
        for v in list(edges):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    return out
