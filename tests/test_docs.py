"""The documentation site builds with ``mkdocs build --strict`` (every cross-reference and link
resolves), a planted broken reference fails that build, every public name is documented on
exactly one API page, and the generated module map of docs/architecture.md is current."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import bsfjax

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
API = DOCS / "api"
PUBLIC_MODULES = {"experiments", "plot", "cli"}  # documented whole on their own API pages


def _needs_mkdocs():
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        if importlib.util.find_spec(module.split(".")[0]) is None or (
                "." in module and importlib.util.find_spec(module) is None):
            pytest.skip(f"{module} is not installed (pip install 'bsfjax[docs]')")


def _build(config: Path, site: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)


def _copy_of_the_site(tmp_path: Path) -> tuple[Path, Path]:
    """docs/ and mkdocs.yml copied into tmp_path (the API still read from this checkout)."""
    import yaml

    docs = tmp_path / "docs"
    shutil.copytree(DOCS, docs, ignore=shutil.ignore_patterns("__pycache__"))
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    config["docs_dir"] = str(docs)
    for plugin in config["plugins"]:
        if isinstance(plugin, dict) and "mkdocstrings" in plugin:
            plugin["mkdocstrings"]["handlers"]["python"]["paths"] = [str(ROOT)]
    path = tmp_path / "mkdocs.yml"
    path.write_text(yaml.safe_dump(config, sort_keys=False, allow_unicode=True), encoding="utf-8")
    return path, docs


def test_the_site_builds_strictly(tmp_path):
    _needs_mkdocs()
    result = _build(ROOT / "mkdocs.yml", tmp_path / "site")
    assert result.returncode == 0, result.stdout + result.stderr
    html = "".join(p.read_text(encoding="utf-8")
                   for p in (tmp_path / "site" / "api").rglob("index.html"))
    missing = [name for name in bsfjax.__all__ if f'id="bsfjax.{name}"' not in html]
    assert not missing, f"public names without a heading on the API pages: {missing}"


def test_a_broken_reference_or_link_fails_the_build(tmp_path):
    _needs_mkdocs()
    config, docs = _copy_of_the_site(tmp_path)
    page = docs / "api" / "index.md"
    original = page.read_text(encoding="utf-8")

    page.write_text(original + "\nSee [this][bsfjax.no_such_name].\n", encoding="utf-8")
    result = _build(config, tmp_path / "site")
    assert result.returncode != 0
    assert "bsfjax.no_such_name" in result.stdout + result.stderr

    page.write_text(original + "\nSee [this page](no-such-page.md).\n", encoding="utf-8")
    result = _build(config, tmp_path / "site")
    assert result.returncode != 0
    assert "no-such-page.md" in result.stdout + result.stderr


def _api_entries() -> dict[str, list[str]]:
    """``::: bsfjax.X`` identifiers of the API pages -> the pages that render them."""
    entries: dict[str, list[str]] = {}
    for page in sorted(API.glob("*.md")):
        for ident in re.findall(r"^:::\s*(bsfjax(?:\.\w+)*)\s*$", page.read_text(encoding="utf-8"),
                                flags=re.MULTILINE):
            entries.setdefault(ident, []).append(page.name)
    return entries


def test_every_public_name_is_on_exactly_one_api_page():
    entries = _api_entries()
    problems = [f"bsfjax.{name}: on {entries.get(f'bsfjax.{name}', [])}"
                for name in bsfjax.__all__ if len(entries.get(f"bsfjax.{name}", [])) != 1]
    assert not problems, "each public name needs one ::: entry on docs/api/*.md:\n" + "\n".join(
        problems)
    public = {f"bsfjax.{name}" for name in set(bsfjax.__all__) | PUBLIC_MODULES}
    stale = sorted(ident for ident in entries if ident not in public)
    assert not stale, f"API pages document names that are not public: {stale}"


def test_docstring_cross_references_name_public_objects():
    """``[text][bsfjax.X]`` in the package's docstrings: X is public (else plain ``code``), so
    that a reference resolves on whichever page the docstring is rendered."""
    public = set(bsfjax.__all__) | PUBLIC_MODULES
    bad = []
    for path in sorted((ROOT / "bsfjax").rglob("*.py")):
        for ident in re.findall(r"\]\[bsfjax\.(\w+)(?:\.\w+)*\]", path.read_text(encoding="utf-8")):
            if ident not in public:
                bad.append(f"{path.relative_to(ROOT)}: bsfjax.{ident}")
    assert not bad, "cross-references to names outside bsfjax.__all__:\n" + "\n".join(bad)


def _gen_architecture():
    spec = importlib.util.spec_from_file_location("gen_architecture", DOCS / "gen_architecture.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_module_map_is_current():
    gen = _gen_architecture()
    text = gen.DOC.read_text(encoding="utf-8")
    assert gen.rewrite(text, gen.render()) == text, (
        "docs/architecture.md's module map is out of date: run python docs/gen_architecture.py")


def test_a_moved_module_changes_the_module_map(tmp_path):
    gen = _gen_architecture()
    pkg = tmp_path / "bsfjax"
    shutil.copytree(ROOT / "bsfjax", pkg, ignore=shutil.ignore_patterns("__pycache__"))
    assert gen.render(pkg) == gen.render()
    (pkg / "_spectral" / "_laplacian.py").rename(pkg / "_mesh" / "_laplacian.py")
    moved = gen.render(pkg)
    assert moved != gen.render()
    mesh_part = moved.split("### Layer 2")[1].split("### Layer 3")[0]
    assert "- `_laplacian.py`" in mesh_part
