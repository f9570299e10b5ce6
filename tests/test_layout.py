"""The layer contract of tests/layout.py holds for the package, and the checker catches each
kind of breach when one is planted in a copy of the package."""

import shutil
from pathlib import Path

import pytest

import bsfjax

from .layout import LAYERS, MAX_LINES, check_package

PKG = Path(bsfjax.__file__).parent


def test_the_package_keeps_the_layer_contract():
    assert check_package(PKG) == []


def test_every_sub_package_has_a_layer_and_a_docstring():
    subs = {p.parent.name for p in PKG.glob("*/__init__.py")}
    assert subs == {pkg for layer in LAYERS for pkg in layer}
    for name in subs:
        doc = (PKG / name / "__init__.py").read_text().lstrip()
        assert doc.startswith(('"""', 'r"""')), f"{name}/__init__.py has no docstring"


@pytest.fixture
def copy(tmp_path):
    dst = tmp_path / "bsfjax"
    shutil.copytree(PKG, dst, ignore=shutil.ignore_patterns("__pycache__"))
    assert check_package(dst) == check_package(PKG)  # the copy checks as the package does
    return dst


def _new_problems(copy: Path) -> list[str]:
    """The breaches in the copy that the package itself does not have (the planted ones)."""
    before = set(check_package(PKG))
    return [p for p in check_package(copy) if p not in before]


def _first_module(pkg_dir: Path) -> Path:
    return sorted(p for p in pkg_dir.glob("_*.py") if p.name != "__init__.py")[0]


def _plant(path: Path, line: str) -> None:
    path.write_text(path.read_text() + "\n\ndef _planted():\n    " + line + "\n")


def test_an_upward_import_is_caught(copy):
    _plant(_first_module(copy / "_mesh"), "from .._pipeline import transfer_labels")
    problems = _new_problems(copy)  # (an upward import also closes circles: each is said)
    assert any("_mesh imports _pipeline (upward" in p for p in problems), problems


def test_a_sideways_import_is_caught(copy):
    _plant(_first_module(copy / "_frame"), "from .._maps import fmap_to_p2p")
    problems = _new_problems(copy)
    assert len(problems) == 1 and "(sideways" in problems[0]


def test_a_private_module_across_sub_packages_is_caught(copy):
    spectrum_module = _first_module(copy / "_spectral").stem
    _plant(_first_module(copy / "_sampling"), f"from .._spectral.{spectrum_module} import x")
    problems = _new_problems(copy)
    assert any("private module bsfjax._spectral." in p for p in problems), problems


def test_a_private_name_across_sub_packages_is_caught(copy):
    _plant(_first_module(copy / "_maps"), "from .._spectral import _hidden")
    problems = _new_problems(copy)
    assert len(problems) == 1 and "private name(s) _hidden" in problems[0]


def test_an_import_circle_is_caught(copy):
    errors, files = copy / "_util" / "_errors.py", copy / "_util" / "_files.py"
    assert "from ._errors import" in files.read_text()  # _files imports _errors ...
    _plant(errors, "from ._files import atomic_path")  # ... and now the other way round
    problems = _new_problems(copy)
    assert problems == ["import circle: _util._errors -> _util._files"]


def test_a_long_module_is_caught(copy):
    path = _first_module(copy / "_coding")
    path.write_text(path.read_text() + "\n" * (MAX_LINES + 1))
    problems = _new_problems(copy)
    assert len(problems) == 1 and f"more than {MAX_LINES}" in problems[0]
