"""The docs' Python blocks stay true to the code: each parses, and each name it imports from lfrefract or
the simulator exists (the blocks that run end to end are run by test_readme.py and test_own_captures.py).
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md")])
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.M | re.S)


def _blocks(page: Path) -> list[tuple[int, str]]:
    text = page.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start()) + 1, m.group(1)) for m in _BLOCK.finditer(text)]


BLOCKS = [(page, line, code) for page in PAGES for line, code in _blocks(page)]


def test_the_docs_have_python_blocks():
    assert len(BLOCKS) >= 10


@pytest.mark.parametrize(("page", "line", "code"), BLOCKS, ids=[f"{p.name}:{n}" for p, n, _ in BLOCKS])
def test_block_parses_and_its_imports_exist(page, line, code):
    tree = ast.parse(code, filename=f"{page.name}:{line}")
    missing = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in ("lfrefract", "simulator"):
            try:
                module = importlib.import_module(node.module)
            except ImportError as exc:
                missing.append(f"{node.module} ({exc})")
                continue
            missing += [f"{node.module}.{a.name}" for a in node.names if not hasattr(module, a.name)]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] in ("lfrefract", "simulator"):
                    try:
                        importlib.import_module(alias.name)
                    except ImportError as exc:
                        missing.append(f"{alias.name} ({exc})")
    assert missing == [], f"{page.relative_to(ROOT)} line {line}"
