"""An AST scan of mifaces' imports: the import cycles among its modules (imports inside
functions and package ``__init__``s counted, ``plugins/`` as ``mifaces.plugins``), the imports
left inside functions, and the modules over the length limit.

    python tools/import_scan.py          # prints the scan; exit status 1 if a cycle is found
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Source folder -> the package it installs as (pyproject's package-dir).
PACKAGES = {ROOT / "mifaces": "mifaces", ROOT / "plugins": "mifaces.plugins"}
#: Longest module, in lines.
MAX_LINES = 500


def modules() -> dict[str, tuple[Path, bool]]:
    """Dotted name -> (file, is a package ``__init__``)."""
    found = {}
    for folder, package in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            init = parts[-1] == "__init__"
            name = ".".join([package, *(parts[:-1] if init else parts)])
            found[name] = (path, init)
    return found


def _targets(node, name: str, init: bool, known) -> list[str]:
    """The modules an import statement of module ``name`` loads."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = name.split(".") if init else name.split(".")[:-1]
    if node.level:
        base = base[:len(base) - node.level + 1]
        module = ".".join(base) + (f".{node.module}" if node.module else "")
    else:
        module = node.module or ""
    # `from package import submodule` loads the submodule; `from package import name` the package
    return [f"{module}.{alias.name}" if f"{module}.{alias.name}" in known else module for alias in node.names]


def scan():
    """(graph, inner): module -> the mifaces modules it imports; module -> its imports inside functions."""
    known = modules()

    def resolve(target: str) -> str | None:
        while target and target not in known:
            target = target.rpartition(".")[0]
        return target or None

    graph = {name: set() for name in known}
    inner = {name: [] for name in known}
    for name, (path, init) in known.items():
        tree = ast.parse(path.read_text())
        top = {id(node) for node in tree.body}
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            if id(node) not in top:
                inner[name].append(ast.unparse(node))
            for target in _targets(node, name, init, known):
                found = resolve(target) if target.split(".")[0] == "mifaces" else None
                if found is None or found == name or (name.startswith(found + ".") and target != found):
                    continue  # outside mifaces, itself, or an ancestor package (initialised first)
                graph[name].add(found)
                parts = found.split(".")  # importing a.b.c runs a/__init__ and a/b/__init__ first
                for k in range(1, len(parts)):
                    ancestor = ".".join(parts[:k])
                    if ancestor in known and not name.startswith(ancestor + "."):
                        graph[name].add(ancestor)
    return graph, inner


def cycles(graph: dict[str, set]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def long_modules(limit: int = MAX_LINES) -> dict[str, int]:
    """Modules over ``limit`` lines."""
    return {name: n for name, (path, _) in modules().items() if (n := len(path.read_text().splitlines())) > limit}


def main() -> int:
    graph, inner = scan()
    found = cycles(graph)
    print(f"{len(graph)} modules, {sum(map(len, graph.values()))} imports among them; {len(found)} import cycle(s)")
    for component in found:
        print("  cycle:", ", ".join(component))
    print("imports inside functions:")
    for name in sorted(inner):
        for statement in inner[name]:
            print(f"  {name}: {statement}")
    print(f"modules over {MAX_LINES} lines: {long_modules() or 'none'}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
