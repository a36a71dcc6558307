"""Writing outputs atomically.

Every file mifaces writes goes through :func:`atomic_path` or :func:`atomic_write`: the data lands in
a temporary file beside the target and is renamed over it only once complete,
so an interrupted run never leaves a half-written output and never destroys
one written earlier. Several files that belong together are written as one
result set (:mod:`mifaces.io.result_set`).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path beside ``path``; move it to ``path`` on success.

    For libraries that write to a file name. The parent folder is created if
    needed. On an exception the temporary file is removed and ``path`` is left
    as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 would outlive the rename
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def save_figure(fig, path: str | os.PathLike, dpi: int | None = 110) -> None:
    """Write a Matplotlib figure as a PNG at ``path``, atomically (:func:`atomic_path`), and
    close it (``dpi`` None: the figure's own)."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", **({} if dpi is None else {"dpi": dpi}))
    finally:
        plt.close(fig)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb"):
    """Open a file for writing that appears at ``path`` only once complete.

    Yields
    ------
    file object
        Opened with ``mode`` (``'wb'`` or ``'w'``).
    """
    with atomic_path(path) as tmp, open(tmp, mode) as f:
        yield f
        f.flush()
        os.fsync(f.fileno())


def write_json(path: str | os.PathLike, data) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_write(path, "w") as f:
        json.dump(data, f, indent=2, sort_keys=False)
        f.write("\n")
