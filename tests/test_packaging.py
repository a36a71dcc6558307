"""The installed package holds every module of the source tree: pyproject.toml's package list
names each folder of ``mifaces/`` that is a package (a wheel built from a stale list leaves a
subpackage out, and only a non-editable install would notice)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_is_installed():
    text = (ROOT / "pyproject.toml").read_text()  # tomllib is Python 3.11's; we support 3.10
    listed = set(ast.literal_eval(re.search(r"^packages = (\[.*?\])", text, re.M | re.S).group(1)))
    package_dirs = set(re.findall(r'^"([\w.]+)" = "', text.split("[tool.setuptools.package-dir]")[1], re.M))
    found = {".".join(init.parent.relative_to(ROOT).parts) for init in (ROOT / "mifaces").rglob("__init__.py")}
    assert found - listed == set(), f"packages missing from pyproject.toml: {sorted(found - listed)}"
    stale = listed - found - package_dirs
    assert stale == set(), f"pyproject.toml lists packages that do not exist: {sorted(stale)}"
