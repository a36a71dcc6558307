"""Writing outputs atomically, result sets as units, and reading/writing images.

Every file mifaces writes goes through :func:`atomic_path` or :func:`atomic_write`: the data lands in
a temporary file beside the target and is renamed over it only once complete,
so an interrupted run never leaves a half-written output and never destroys
one written earlier.

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

Images are numpy arrays of shape (H, W) or (H, W, C), float32 linear values
for EXR and display-referred [0, 1] values (sRGB-encoded here) for PNG.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

from .version import VERSION

#: Largest image side and pixel count mifaces reads, renders or simulates
#: (8192² pixels: 0.8 GiB as float32 RGB); checked before any allocation.
MAX_IMAGE_SIDE = 16384
MAX_IMAGE_PIXELS = 8192 * 8192
#: Largest number of samples one render pass traces (Mitsuba's wavefront:
#: width x height x spp must stay below 2^32).
MAX_RENDER_SAMPLES = 2 ** 32 - 1
#: The file a result set's folder holds, written last (:func:`result_set`).
SET_MANIFEST = ".mifaces-set.json"
#: Environment variable for tests only: the path of a flag file. Where set,
#: :func:`result_set` creates that file (holding the name of the point,
#: ``'staged'`` or ``'swapping'``) at each point of its write window and waits
#: while it exists, so that a test can kill the process exactly there
#: (:func:`pause_for_test`). Unset, it costs one dictionary look-up per set.
TEST_PAUSE_ENV = "MIFACES_TEST_PAUSE_IN_WRITE"


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


class ResultSetError(ValueError):
    """A result folder whose files do not belong together (a mixed or
    damaged set), or one that is not to be written over."""


# --------------------------------------------------------------------------------------------
# Checks before any work
# --------------------------------------------------------------------------------------------
def check_image_size(width, height, what: str = "image") -> tuple[int, int]:
    """``(width, height)`` as ints, or a ``ValueError`` saying the limit
    (:data:`MAX_IMAGE_SIDE`, :data:`MAX_IMAGE_PIXELS`): for a size read from a
    file's header or asked for by a user, before anything is allocated."""
    if isinstance(width, bool) or isinstance(height, bool):
        raise ValueError(f"{what}: width and height must be numbers, got {width!r} x {height!r}")
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise ValueError(f"{what}: size must be positive, got {width}x{height}")
    if max(width, height) > MAX_IMAGE_SIDE or width * height > MAX_IMAGE_PIXELS:
        raise ValueError(f"{what}: {width}x{height} pixels is larger than mifaces handles (at most "
                         f"{MAX_IMAGE_SIDE} pixels a side and {MAX_IMAGE_PIXELS} pixels, e.g. 8192x8192)")
    return width, height


def check_render_size(width: int, height: int, spp: int, what: str = "render") -> None:
    """A ``ValueError`` unless an image of ``width`` x ``height`` at ``spp``
    samples per pixel fits the image limits and one Mitsuba pass
    (:data:`MAX_RENDER_SAMPLES`)."""
    check_image_size(width, height, what)
    if isinstance(spp, bool) or int(spp) < 1:
        raise ValueError(f"{what}: samples per pixel must be a positive integer, got {spp!r}")
    if width * height * int(spp) > MAX_RENDER_SAMPLES:
        raise ValueError(f"{what}: {width}x{height} pixels at {spp} spp are {width * height * int(spp)} samples, "
                         f"more than one render pass traces ({MAX_RENDER_SAMPLES}); lower the spp or the size")


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


def _as_hwc(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image, dtype=np.float32)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3:
        raise ValueError(f"image must have shape (H, W) or (H, W, C), got {image.shape}")
    return image


def write_exr(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write a linear float image as OpenEXR (float32 channels Y, RGB or RGBA)."""
    import OpenEXR

    image = _as_hwc(image)
    names = {1: "Y", 3: "RGB", 4: "RGBA"}.get(image.shape[2])
    if names is None:
        raise ValueError(f"EXR images need 1, 3 or 4 channels, got {image.shape[2]}")
    channels = {n: np.ascontiguousarray(image[:, :, i]) for i, n in enumerate(names)}
    with atomic_path(path) as tmp:
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     channels).write(tmp)


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file as a float32 array (H, W) or (H, W, C), channels
    in the order Y, or R, G, B(, A). The size in the header is checked
    (:func:`check_image_size`) before the pixels are read."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"EXR image not found: {path}")
    with OpenEXR.File(str(path), header_only=True) as f:  # the size, before any pixel is allocated
        (x0, y0), (x1, y1) = (np.asarray(corner, np.int64) for corner in f.header()["dataWindow"])
    check_image_size(x1 - x0 + 1, y1 - y0 + 1, path.name)
    with OpenEXR.File(str(path), separate_channels=True) as f:
        channels = f.channels()
        order = [c for c in ("R", "G", "B", "A") if c in channels] or sorted(channels)
        planes = [np.asarray(channels[c].pixels, dtype=np.float32) for c in order]
    return planes[0] if len(planes) == 1 else np.stack(planes, axis=-1)


def encode_png(image: np.ndarray, srgb: bool = True) -> bytes:
    """An image with values in [0, 1] ((H, W), (H, W, 3) or (H, W, 4)) as the
    bytes of an 8-bit PNG, colour channels sRGB-encoded unless ``srgb`` is
    False (then written as they are); an alpha channel is always linear."""
    import io

    import colour
    from PIL import Image

    image = _as_hwc(image)
    if image.shape[2] not in (1, 3, 4):
        raise ValueError(f"PNG images need 1, 3 or 4 channels, got {image.shape[2]}")
    image = np.clip(np.nan_to_num(image), 0.0, 1.0)
    if srgb:
        colours = min(image.shape[2], 3)
        image = np.concatenate([colour.cctf_encoding(image[:, :, :colours], function="sRGB"),
                                image[:, :, colours:]], axis=2)
    data = np.round(image * 255.0).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(data[:, :, 0] if data.shape[2] == 1 else data).save(buffer, format="PNG")
    return buffer.getvalue()


def write_png(path: str | os.PathLike, image: np.ndarray, srgb: bool = True) -> None:
    """Write an image with values in [0, 1] as 8-bit PNG, atomically (:func:`encode_png`)."""
    data = encode_png(image, srgb)
    with atomic_write(path) as f:
        f.write(data)


# --------------------------------------------------------------------------------------------
# Result sets: several files as one unit
# --------------------------------------------------------------------------------------------
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
