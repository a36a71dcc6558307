"""Where a result came from: the provenance every JSON in ``validation/results/`` records.

``write_result(path, data, seeds=..., subjects=..., inputs=...)`` writes ``data`` as JSON (atomically)
with a ``provenance`` entry beside the script's own keys:

- ``commit``: the commit the script ran at (``git rev-parse HEAD``) and ``dirty``: whether the files
  the script depends on differed from that commit when it ran;
- ``command``: the command line, as a person would retype it from the repository's root;
- ``date``: when it ran (UTC);
- ``seeds`` and ``subjects``: the captures it ran on (what ``validation/roles.py`` judges);
- ``inputs``: the SHA-256 of every data file it read from outside the code (model data, ``../shared``);
- ``code``: one SHA-256 over every repository file the script depends on: itself and the modules of
  ``mifaces``, the plugins and ``validation/`` it imports, directly or not, with the data files of their
  packages (``dependencies``, ``code_hash``; ``import mifaces`` alone loads most of the library);
- ``packages``: the versions of Python and of the numerical packages (``PACKAGES``): a rerun in a fresh
  environment may install newer ones, which can move the last digits of a fit.
  ``reproduce.py`` calls a result *stale* when this hash no longer matches the tree's.

A script adds its inputs by path; ``SHARED`` and ``MODEL_DATA`` name the usual ones.
"""

from __future__ import annotations

import ast
import datetime
import hashlib
import json
import shlex
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
VALIDATION = REPO / "validation"
RESULTS = VALIDATION / "results"
SHARED = REPO.parent / "shared"


def file_hash(path: Path) -> str:
    """SHA-256 of a file's bytes; of a folder, over its files' names and hashes (sorted)."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_dir():
        for item in sorted(p for p in path.rglob("*") if p.is_file()):
            digest.update(f"{item.relative_to(path)}\0{file_hash(item)}\n".encode())
        return digest.hexdigest()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _module_file(name: str) -> Path | None:
    """The repository file of a module of ``mifaces`` or of ``validation/`` (None for anything else)."""
    parts = name.split(".")
    if parts[0] == "mifaces" and len(parts) > 1 and parts[1] == "plugins":
        parts = ["plugins", *parts[2:]]  # the plugins package lives in plugins/
    elif parts[0] != "mifaces":
        candidate = VALIDATION / f"{parts[0]}.py"
        return candidate if len(parts) == 1 and candidate.is_file() else None
    base = REPO.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _imports(path: Path) -> set[str]:
    """The absolute names of the modules ``path`` imports (relative imports resolved; ``from a import b``
    yields ``a`` and ``a.b``)."""
    rel = path.relative_to(REPO).with_suffix("")
    package = list(rel.parts[:-1]) if rel.name != "__init__" else list(rel.parts[:-1])
    if package[:1] == ["plugins"]:
        package = ["mifaces", *package]
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package[:len(package) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
    return names


def dependencies(script: Path) -> list[Path]:
    """Every repository file a validation script's results depend on (sorted, repository-relative): the
    script, the modules of ``mifaces`` (plugins included) and of ``validation/`` that it imports, directly
    or through each other (with the ``__init__`` of every package on the way), and the data files that
    sit in those packages' folders (the built-in model's)."""
    files: set[Path] = set()
    todo = [Path(script).resolve()]
    while todo:
        path = todo.pop()
        if path in files:
            continue
        files.add(path)
        for name in _imports(path):
            parts = name.split(".")
            for k in range(1, len(parts) + 1):  # the packages on the way: their __init__ runs too
                found = _module_file(".".join(parts[:k]))
                if found is not None and found not in files:
                    todo.append(found)
    for package in {p.parent for p in files if p.name == "__init__.py"}:
        for path in package.rglob("*"):  # data files, down to the next package
            owner = next(f for f in path.parents if (f / "__init__.py").is_file() or f == package)
            if path.is_file() and path.suffix not in (".py", ".pyc") and owner == package:
                files.add(path)
    return sorted(p.relative_to(REPO) for p in files)


def code_hash(script: Path) -> str:
    """One SHA-256 over the contents and names of ``dependencies(script)``."""
    digest = hashlib.sha256()
    for rel in dependencies(script):
        digest.update(str(rel).encode() + b"\0" + file_hash(REPO / rel).encode() + b"\n")
    return digest.hexdigest()


def _git(*args: str) -> str | None:
    try:
        return subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def dirty(paths: list[Path]) -> bool | None:
    """Whether any of ``paths`` differs from the commit checked out (None where git cannot tell)."""
    out = _git("status", "--porcelain", "--", *map(str, paths))
    return None if out is None else bool(out)


def command_line(argv: list[str] | None = None) -> str:
    argv = list(sys.argv if argv is None else argv)
    script = Path(argv[0]).resolve() if argv else None
    if script is not None and script.is_file() and REPO in script.parents:
        argv[0] = str(script.relative_to(REPO))
    return "python " + shlex.join(argv)


def provenance(script: str | Path, *, seeds=None, subjects=None, inputs=(), argv=None) -> dict:
    script = Path(script).resolve()
    deps = dependencies(script)
    return {
        "commit": _git("rev-parse", "HEAD"),
        "dirty": dirty(deps),
        "command": command_line(argv),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "seeds": None if seeds is None else [int(s) for s in seeds],
        "subjects": None if subjects is None else [str(s) for s in subjects],
        "inputs": {_display(Path(p)): file_hash(Path(p)) for p in inputs},
        "code": code_hash(script),
        "packages": packages(),
    }


#: The packages whose version can move a result's last digits (a fresh ``pip install`` picks the newest).
PACKAGES = ("numpy", "scipy", "drjit", "mitsuba", "trimesh", "scikit-image")


def packages() -> dict:
    """The installed versions of :data:`PACKAGES` and Python's (None for one not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    def get(name):
        try:
            return version(name)
        except PackageNotFoundError:
            return None
    return {"python": ".".join(map(str, sys.version_info[:3])), **{name: get(name) for name in PACKAGES}}


def _display(path: Path) -> str:
    path = path.resolve()
    for root, name in ((REPO, ""), (SHARED, "../shared/")):
        if root in path.parents:
            return name + str(path.relative_to(root))
    return str(path)


def write_json(path: str | Path, data) -> None:
    """Write ``data`` as JSON to ``path`` atomically (``mifaces.io.atomic``)."""
    import mifaces  # noqa: F401  (first: it points Dr.Jit at a working libLLVM)  # isort: skip
    from mifaces.io.atomic import write_json as atomic_json

    atomic_json(path, data)


def write_result(path: str | Path, data: dict, *, script: str | Path | None = None, seeds=None, subjects=None,
                 inputs=(), argv=None) -> dict:
    """Write a validation result with its ``provenance`` (see the module docstring); returns what was written.

    ``script`` defaults to the running ``__main__``'s file.
    """
    if script is None:
        script = sys.modules["__main__"].__file__
    data = dict(data)
    data["provenance"] = provenance(script, seeds=seeds, subjects=subjects, inputs=inputs, argv=argv)
    write_json(path, data)
    return data
