"""The README stays true: its API tour runs and CI's commands are the README's."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_api_tour_runs(capsys):
    text = (ROOT / "README.md").read_text()
    code = re.search(r"```python\n(import bsfjax.*?)```", text, re.S).group(1)
    code = code.replace("bsfjax.example_pair()", "bsfjax.example_pair(levels=2)")
    code = code.replace("random_indicators(src, 100", "random_indicators(src, 10")
    exec(compile(code, "README.md", "exec"), {})
    printed = [float(x) for x in capsys.readouterr().out.split()]
    assert len(printed) == 2 and all(0 < e < 1 for e in printed)


def test_ci_runs_the_readme_commands():
    text = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    for marker in ("ci:main", "ci:test"):
        block = text.split(f"<!-- {marker} -->", 1)[1]
        cmd = next(ln for ln in block.splitlines() if ln.startswith("python"))
        assert "pip install" in cmd
    assert "ci:main" in ci and "ci:test" in ci
    assert "bsfjax demo" in text.split("<!-- ci:main -->", 1)[1].split("```", 2)[1]
