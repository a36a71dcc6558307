"""Checking names and paths before use: names from manifests that become file
names (:func:`check_name`), files named relative to a folder
(:func:`resolve_inside`), and output folders (:func:`check_writable`)."""

from __future__ import annotations

import errno
import os
import re
import tempfile
from pathlib import Path

#: A name that may become a file name: letters, digits and ``._+-``, not
#: starting with a dot, at most 100 characters.
SAFE_NAME = re.compile(r"[A-Za-z0-9_+-][A-Za-z0-9._+-]{0,99}")


def check_name(name, what: str = "name", reserved=()) -> str:
    """``name`` if it can name a file of its own (:data:`SAFE_NAME`, none of
    ``reserved``, compared without case); a ``ValueError`` naming ``what``
    otherwise. Names from manifests become file names: ``../x`` or ``/x``
    would write outside the output folder."""
    if not isinstance(name, str) or not SAFE_NAME.fullmatch(name):
        raise ValueError(f"{what} {name!r} cannot name a file: use letters, digits and ._+- (not a leading dot), "
                         "at most 100 characters")
    if name.lower() in {r.lower() for r in reserved}:
        raise ValueError(f"{what} {name!r} is reserved (it would overwrite {name}'s file of another kind)")
    return name


def check_writable(folder: str | os.PathLike) -> Path:
    """``folder`` if files can be created in it (or, where it does not
    exist yet, in its nearest existing parent): a cheap probe at the start of
    a command, so that an unwritable output fails before the work, not after.

    Raises
    ------
    OSError
        ``NotADirectoryError`` where a file stands in the way,
        ``PermissionError`` (or the probe's error) where nothing can be written.
    """
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        if existing.is_symlink():
            raise NotADirectoryError(f"cannot write {folder}: {existing} is a dangling symbolic link")
        existing = existing.parent
    if not existing.is_dir():
        raise NotADirectoryError(f"cannot write {folder}: {existing} is not a folder")
    try:
        with tempfile.TemporaryFile(dir=existing, prefix=".mifaces-probe-"):
            pass
    except OSError as error:
        raise PermissionError(f"cannot write to {folder}: {error.strerror or error}") from None
    return folder


def resolve_inside(root: str | os.PathLike, relative: str, allow_outside: bool = False) -> Path:
    """The file ``relative`` names inside folder ``root``, checked: a
    ``ValueError`` for an absolute path, a ``..`` that leaves ``root``, or a
    symbolic link resolving outside it (unless ``allow_outside``), and an
    ``OSError`` naming a symbolic-link loop as such."""
    root = Path(root)
    if not allow_outside and (Path(relative).is_absolute() or os.path.isabs(relative)):
        raise ValueError(f"{relative!r} is an absolute path; files of {root} must be named relative to it")
    path = root / relative
    try:
        resolved = path.resolve(strict=False)
        if path.is_symlink() or path.exists():
            resolved = path.resolve(strict=True)
    except RuntimeError:  # Python < 3.13 reports a loop this way
        raise OSError(f"{relative}: symbolic link loop (a link that leads back to itself)") from None
    except OSError as error:
        if error.errno == errno.ELOOP:
            raise OSError(f"{relative}: symbolic link loop (a link that leads back to itself)") from None
        if path.is_symlink():  # dangling: missing, reported by the caller
            return path
        raise
    if not allow_outside:
        base = root.resolve()
        if resolved != base and base not in resolved.parents:
            raise ValueError(f"{relative!r} lies outside {root} (it resolves to {resolved})")
    return path
