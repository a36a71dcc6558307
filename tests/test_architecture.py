"""The code's structure as docs/architecture.md states it: no import cycle among mifaces'
modules (imports inside functions and package ``__init__``s counted), imports inside functions
only for the optional or slow dependencies it names, no module over 500 lines, and every
``mifaces.…`` name the page mentions exists."""

from __future__ import annotations

import importlib
import importlib.util
import re
from pathlib import Path

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("import_scan", ROOT / "tools" / "import_scan.py")
import_scan = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(import_scan)

#: Imports allowed inside functions (docs/architecture.md, "Rules the code keeps"): optional or heavy
#: dependencies, and two slow imports only some calls need.
INNER_ALLOWED = ("matplotlib", "dlib", "face_recognition_models", "h5py", "eos", "pxr", "colour", "trimesh")
#: Package-internal imports allowed inside functions: Dask's slow import, only for `mifaces batch`.
INNER_INTERNAL = {("mifaces.cli.commands", "from ..pipeline.batch import Cluster, measure_batch")}


def test_no_import_cycle():
    graph, _ = import_scan.scan()
    assert "mifaces.reflectance.estimate" in graph and "mifaces.plugins" in graph
    assert import_scan.cycles(graph) == []


def test_a_cycle_is_found():
    """The scan sees a cycle through a package root (the check above can fail)."""
    graph = {"mifaces": {"mifaces.a"}, "mifaces.a": {"mifaces.b"}, "mifaces.b": {"mifaces"}, "mifaces.c": set()}
    assert import_scan.cycles(graph) == [["mifaces", "mifaces.a", "mifaces.b"]]


def test_imports_inside_functions_are_the_allowed_ones():
    _, inner = import_scan.scan()
    odd = [(name, statement) for name, statements in inner.items() for statement in statements
           if (name, statement) not in INNER_INTERNAL
           and not re.match(rf"(import|from) ({'|'.join(INNER_ALLOWED)})\b", statement)]
    assert odd == []


def test_no_module_over_the_limit():
    assert import_scan.long_modules() == {}


def _exists(name: str) -> bool:
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for attribute in parts[k:]:
            if not hasattr(obj, attribute):
                return False
            obj = getattr(obj, attribute)
        return True
    return False


def test_the_names_docs_architecture_mentions_exist():
    text = (ROOT / "docs" / "architecture.md").read_text()
    names = sorted(set(re.findall(r"`(mifaces(?:\.\w+)+)", text)))
    assert len(names) > 40
    assert [name for name in names if not _exists(name)] == []


@pytest.mark.parametrize("page", sorted(str(p.relative_to(ROOT)) for p in [*ROOT.glob("docs/*.md"), ROOT / "README.md",
                                                                            ROOT / "validation" / "README.md"]))
def test_the_names_the_documentation_mentions_exist(page):
    names = sorted(set(re.findall(r"(mifaces(?:\.\w+)+)", (ROOT / page).read_text())))
    assert [name for name in names if not _exists(name)] == []
