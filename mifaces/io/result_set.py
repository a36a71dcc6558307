"""Result sets: several files that belong together, written as one unit.

A command that writes several files that belong together (a capture, a
fitted BRDF, fitted shapes) writes them as one *result set*
(:func:`result_set`): into a temporary sibling folder, with a set manifest
(:data:`SET_MANIFEST`: what the set is, its options, mifaces' version, each
file's SHA-256) written last, then swapped in by renaming. A reader never
sees two generations mixed (:func:`verify_set` checks the checksums), a
killed run leaves nothing in the result folder, and the next run cleans up or
finishes (:func:`recover_set`) what it left beside it. Writing over a result
set needs ``force``; a folder holding files mifaces did not write as a set
(a real capture's photographs) is never written over.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

from .atomic import write_json
from .paths import check_writable
from ..version import VERSION

#: The file a result set's folder holds, written last (:func:`result_set`).
SET_MANIFEST = ".mifaces-set.json"
#: Environment variable for tests only: the path of a flag file. Where set,
#: :func:`result_set` creates that file (holding the name of the point,
#: ``'staged'`` or ``'swapping'``) at each point of its write window and waits
#: while it exists, so that a test can kill the process exactly there
#: (:func:`pause_for_test`). Unset, it costs one dictionary look-up per set.
TEST_PAUSE_ENV = "MIFACES_TEST_PAUSE_IN_WRITE"


class ResultSetError(ValueError):
    """A result folder whose files do not belong together (a mixed or
    damaged set), or one that is not to be written over."""


@dataclass(frozen=True)
class ResultTarget:
    """Where a result set goes: its ``folder``, and whether a set of the same kind there is replaced
    (``force``; :func:`check_result_target`).

    Attributes
    ----------
    folder : Path
    force : bool
        Replace a set of the same kind that ``folder`` holds (else a ``FileExistsError``).
    """

    folder: Path
    force: bool = False

    def __post_init__(self):
        object.__setattr__(self, "folder", Path(self.folder))

    @classmethod
    def of(cls, out: str | os.PathLike | ResultTarget) -> ResultTarget:
        """``out`` as a target: a :class:`ResultTarget` as it is, a path as one that replaces nothing."""
        return out if isinstance(out, cls) else cls(out)


def file_sha256(path: str | os.PathLike) -> str:
    """The SHA-256 of file ``path`` (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _set_files(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``folder`` but the set manifest."""
    return {p.relative_to(folder).as_posix(): file_sha256(p) for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != SET_MANIFEST}


def read_set(folder: str | os.PathLike) -> dict | None:
    """The set manifest of result folder ``folder``, or None where it has
    none (written by an older mifaces, or not by mifaces)."""
    path = Path(folder) / SET_MANIFEST
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (ValueError, OSError) as error:
        raise ResultSetError(f"{folder}: damaged result-set manifest {SET_MANIFEST}: {error}") from None
    if not isinstance(data, dict) or not isinstance(data.get("files"), dict):
        raise ResultSetError(f"{folder}: damaged result-set manifest {SET_MANIFEST}")
    return data


def verify_set(folder: str | os.PathLike, kind: str, names=None) -> dict | None:
    """Check that the files of result folder ``folder`` (those in ``names``,
    default all) are the ones its set manifest lists: same SHA-256, none
    missing. Returns the manifest, or None for a folder without one.

    Raises
    ------
    ResultSetError
        A set of another kind, or files changed, replaced or missing since
        the set was written: a mixed set.
    """
    folder = Path(folder)
    data = read_set(folder)
    if data is None:
        return None
    if data.get("kind") != kind:
        raise ResultSetError(f"{folder}: holds a {data.get('kind')!r} result set, not a {kind!r} one")
    listed = data["files"]
    for name in (listed if names is None else names):
        if name not in listed:
            raise ResultSetError(f"{folder}: {name} is not part of the result set written there (a file from "
                                 f"another run)")
        path = folder / name
        if not path.is_file():
            raise ResultSetError(f"{folder}: {name} of the result set is missing")
        if file_sha256(path) != listed[name]:
            raise ResultSetError(f"{folder}: {name} is not the file written with the rest of the set (changed or "
                                 f"from another run); mixed outputs are refused, write the set again")
    return data


def _leftovers(out: Path) -> list[Path]:
    """Staging and replaced folders of earlier runs beside ``out`` whose process has ended."""
    found = []
    for path in out.parent.glob(f".{out.name}.*-*"):
        tag, _, rest = path.name[len(out.name) + 2:].partition("-")
        pid = rest.split("-")[0]
        if tag not in ("new", "old") or not pid.isdigit():
            continue
        if int(pid) != os.getpid():
            try:
                os.kill(int(pid), 0)
                continue  # a run still at work
            except ProcessLookupError:
                pass
            except PermissionError:
                continue
        found.append(path)
    return found


def recover_set(out: str | os.PathLike) -> None:
    """Tidy what a killed run left beside result folder ``out``: a complete
    staged set (with its manifest) whose swap was cut short between its two
    renames is moved in, the folder it replaced restored where no complete
    set is, every other leftover removed."""
    out = Path(out)
    if not out.parent.is_dir():
        return
    leftovers = _leftovers(out)
    if not out.exists():
        complete = [p for p in leftovers if p.name.startswith(f".{out.name}.new-") and (p / SET_MANIFEST).is_file()]
        replaced = [p for p in leftovers if p.name.startswith(f".{out.name}.old-")]
        for candidate in complete + replaced:
            os.rename(candidate, out)
            leftovers.remove(candidate)
            break
    for path in leftovers:
        shutil.rmtree(path, ignore_errors=True)


def check_result_target(out: str | os.PathLike, kind: str, force: bool = False) -> Path:
    """Whether :func:`result_set` may write a ``kind`` set into ``out``: it
    can be written (:func:`check_writable`), and it is absent, empty, or
    holds a set of that kind and ``force`` is given. Tidies a killed run's
    leftovers first (:func:`recover_set`). For commands to call before their
    work; :func:`result_set` calls it again.

    Raises
    ------
    FileExistsError
        ``out`` holds a ``kind`` set and ``force`` is False.
    ResultSetError
        ``out`` holds files mifaces did not write as a set, or another kind of set.
    OSError
        ``out`` cannot be written.

    Returns
    -------
    Path
        ``out``, in every case that may be written (absent, empty, a set to replace).
    """
    out = Path(out)
    check_writable(out)
    recover_set(out)
    if not out.exists():
        return out
    if not out.is_dir():
        raise NotADirectoryError(f"{out} is not a folder")
    content = sorted(p.name for p in out.iterdir())
    if not content:
        return out  # an empty folder: nothing to lose, the set takes its place
    data = read_set(out)
    if data is None:
        shown = ", ".join(content[:5]) + (", ..." if len(content) > 5 else "")
        raise ResultSetError(f"{out} holds files mifaces did not write as a result set ({shown}); it is not "
                             "written over, even with force: choose another folder or empty this one")
    if data.get("kind") != kind:
        raise ResultSetError(f"{out} holds a {data.get('kind')!r} result, not a {kind!r} one; choose another folder")
    if not force:
        raise FileExistsError(f"{out} holds a {kind} already; use force=True (--force) to replace it")
    return out


def pause_for_test(point: str) -> None:
    """Where :data:`TEST_PAUSE_ENV` names a flag file, create it holding
    ``point`` and wait until it is removed (a test then kills the process,
    or removes the file to let it go on); else return at once."""
    flag = os.environ.get(TEST_PAUSE_ENV)
    if not flag:
        return
    staged = f"{flag}.{os.getpid()}.tmp"
    Path(staged).write_text(point)
    os.replace(staged, flag)  # the test reads the point's name whole
    while os.path.exists(flag):
        time.sleep(0.01)


@contextlib.contextmanager
def result_set(out: str | os.PathLike, kind: str, *, force: bool = False, info: dict | None = None):
    """Write a set of files that belong together as one unit into folder ``out``.

    Yields a temporary sibling folder to write the files into; on success the
    set manifest (``kind``, ``info``, mifaces' version, each file's SHA-256)
    is written there last and the folder takes the place of ``out`` (two
    renames: ``out`` aside, the new one in; the old one then removed). On an
    exception or a kill nothing changes in ``out``; the next call tidies up
    (:func:`recover_set`).

    Parameters
    ----------
    out : path
    kind : str
        What the set is (``'capture'``, ``'brdf'``, ``'shapes'``): a folder of
        another kind is never written over.
    force : bool
        Replace a set of the same kind that ``out`` holds (else a
        ``FileExistsError``). A folder holding files mifaces did not write as
        a set is never replaced (:class:`ResultSetError`).
    info : dict, optional
        Inputs and options to record in the manifest.
    """
    out = check_result_target(out, kind, force)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.parent / f".{out.name}.new-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    staging.mkdir()
    try:
        yield staging
        manifest = {"kind": kind, "mifaces": VERSION, "info": info or {}, "files": _set_files(staging)}
        write_json(staging / SET_MANIFEST, manifest)
        _mode = os.umask(0)
        os.umask(_mode)
        os.chmod(staging, 0o777 & ~_mode)
        pause_for_test("staged")  # the set complete beside out, out untouched
        if out.exists():
            old = out.parent / f".{out.name}.old-{os.getpid()}-{uuid.uuid4().hex[:8]}"
            os.rename(out, old)
            pause_for_test("swapping")  # out set aside, the new set not yet in its place
            os.rename(staging, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
