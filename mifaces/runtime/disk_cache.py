"""mifaces' disk cache: a folder that a run wrote, kept for a later run that would write the same.

``mifaces measure`` with no capture simulates the built-in default capture, the same one every
time, and that takes a third of its run. The cache keeps such a folder under a key made of
everything the folder follows from: the inputs the caller names (a simulation's options), the
content of mifaces' own files (its code, its plugins and the built-in model's data), the versions of
Mitsuba, Dr.Jit and NumPy, and the Mitsuba variant. Any change to one of them is another key, so a
cached folder is never out of date; the cache keeps the :data:`KEEP` newest folders of each kind.

Where: ``$MIFACES_CACHE``, else ``$XDG_CACHE_HOME/mifaces``, else ``~/.cache/mifaces``. Deleting
that folder empties the cache; ``MIFACES_CACHE=off`` turns it off. A cache that cannot be written
(a read-only home, a full disk) costs a warning, never the run.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import os
import shutil
import uuid
import warnings
from pathlib import Path

import drjit
import mitsuba
import numpy

#: The environment variable naming the cache's folder (or :data:`OFF`).
ENV = "MIFACES_CACHE"
#: The value of :data:`ENV` that turns the cache off.
OFF = "off"
#: Folders kept per kind; the least recently used beyond it are removed.
KEEP = 4


def cache_root() -> Path | None:
    """The cache's folder (module docstring), or None where :data:`ENV` turns it off."""
    value = os.environ.get(ENV, "")
    if value.strip().lower() == OFF:
        return None
    if value:
        return Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "mifaces"


def _package_folders() -> list[Path]:
    root = Path(__file__).resolve().parents[1]
    folders = [root]
    # installed as mifaces.plugins from the source tree's plugins/ folder (found, not imported)
    plugin_folder = Path(importlib.util.find_spec("mifaces.plugins").origin).resolve().parent
    if root not in plugin_folder.parents:
        folders.append(plugin_folder)
    return folders


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A digest of mifaces' own files (every file of the package and its plugins but compiled
    bytecode) and of the versions of the libraries that compute with them."""
    digest = hashlib.blake2b(digest_size=16)
    for name, module in (("mitsuba", mitsuba), ("drjit", drjit), ("numpy", numpy)):
        digest.update(f"{name}={module.__version__};".encode())
    digest.update(f"variant={mitsuba.variant()};".encode())
    for folder in _package_folders():
        for path in sorted(folder.rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc":
                digest.update(path.relative_to(folder).as_posix().encode() + b"\0")
                digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_key(kind: str, inputs: dict) -> str:
    """The key of a ``kind`` folder made from ``inputs`` (a JSON object) by this code."""
    text = json.dumps({"kind": kind, "inputs": inputs, "code": code_fingerprint()}, sort_keys=True)
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()


def _folder(kind: str, inputs: dict) -> Path | None:
    root = cache_root()
    return None if root is None else root / kind / cache_key(kind, inputs)


def lookup(kind: str, inputs: dict) -> Path | None:
    """The cached ``kind`` folder made from ``inputs`` by this code, or None. A hit counts as a use
    (it is kept longest)."""
    folder = _folder(kind, inputs)
    if folder is None or not folder.is_dir():
        return None
    try:
        os.utime(folder)
    except OSError:
        pass
    return folder


def discard(folder: Path) -> None:
    """Remove a cached folder (one found damaged)."""
    shutil.rmtree(folder, ignore_errors=True)


def store(kind: str, inputs: dict, source: str | os.PathLike) -> Path | None:
    """Copy folder ``source``, made from ``inputs`` by this code, into the cache; its place there,
    or None where the cache is off or cannot be written (then with a warning)."""
    folder = _folder(kind, inputs)
    if folder is None:
        return None
    staging = folder.parent / f".{folder.name}.new-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        shutil.copytree(source, staging)
        try:
            os.rename(staging, folder)  # whole or not at all; a folder already there is the same
        except OSError:
            shutil.rmtree(staging, ignore_errors=True)
        _evict(folder.parent)
    except OSError as error:
        shutil.rmtree(staging, ignore_errors=True)
        warnings.warn(f"mifaces' cache ({folder.parent}) could not keep the {kind}: {error}; "
                      f"set {ENV} to a writable folder, or to {OFF!r}", RuntimeWarning, stacklevel=2)
        return None
    return folder


def _evict(kind_folder: Path) -> None:
    """Keep the :data:`KEEP` most recently used folders of one kind."""
    folders = [p for p in kind_folder.iterdir() if p.is_dir() and not p.name.startswith(".")]
    folders.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    for old in folders[KEEP:]:
        shutil.rmtree(old, ignore_errors=True)


__all__ = ["ENV", "OFF", "KEEP", "cache_root", "code_fingerprint", "cache_key", "lookup", "discard", "store"]
