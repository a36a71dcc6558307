"""Find a libLLVM that Dr.Jit's LLVM backend can load.

Dr.Jit 1.5 reads the environment variable ``DRJIT_LIBLLVM_PATH`` when its
LLVM backend starts; without it, it tries whatever ``libLLVM.so`` the dynamic
loader finds first. On Debian 12 that is the system LLVM 14 (too old, refused)
or 15 (accepted, but it crashes Dr.Jit 1.5 on real kernels). LLVM 16 and newer
work. This module looks for one, newest first, in the places a user without
root can have it:

1. the wheel ``karellen-llvm-core`` (a dependency of mifaces on Linux), which
   installs ``libLLVM.so.<major>`` into ``<prefix>/lib``;
2. Debian/Ubuntu packages ``libllvm16`` … (``/usr/lib/llvm-<N>/lib`` and
   ``/usr/lib/<triplet>/libLLVM-<N>.so``);
3. Homebrew's ``llvm`` on macOS.

A path the user set in ``DRJIT_LIBLLVM_PATH`` is always respected.
"""

from __future__ import annotations

import glob
import os
import re
import sys
from pathlib import Path

#: Oldest LLVM major version that Dr.Jit 1.5 runs reliably with.
MIN_VERSION = 16

ENV_VAR = "DRJIT_LIBLLVM_PATH"

INSTALL_HINT = (
    "Dr.Jit's LLVM backend needs libLLVM {min}+ and none was found. Install one "
    "without root with `pip install karellen-llvm-core`, or from Debian/Ubuntu "
    "with `apt install libllvm19`, or point the environment variable "
    f"{ENV_VAR} at a libLLVM.so of version {{min}} or newer."
).format(min=MIN_VERSION)


def _major_version(path: str) -> int | None:
    """LLVM major version read from a library file name, e.g. ``libLLVM.so.23.1``,
    ``libLLVM-19.so.1``, ``/usr/lib/llvm-19/lib/libLLVM.so``."""
    name = os.path.basename(path)
    for pattern in (r"libLLVM-(\d+)", r"libLLVM\.so\.(\d+)", r"libLLVM\.(\d+)\.dylib"):
        m = re.search(pattern, name)
        if m:
            return int(m.group(1))
    m = re.search(r"llvm[-@]?(\d+)", path)
    return int(m.group(1)) if m else None


def _candidate_paths() -> list[str]:
    prefixes = {sys.prefix, sys.base_prefix, os.path.dirname(os.path.dirname(sys.executable))}
    patterns = []
    for prefix in prefixes:
        patterns += [f"{prefix}/lib/libLLVM.so.*", f"{prefix}/lib/libLLVM-*.so*"]
    patterns += [
        "/usr/lib/llvm-*/lib/libLLVM.so*",
        "/usr/lib/llvm-*/lib/libLLVM-*.so*",
        "/usr/lib/*-linux-gnu/libLLVM-*.so*",
        "/usr/lib/*-linux-gnu/libLLVM.so.*",
        "/usr/lib64/libLLVM-*.so*",
        "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
        "/usr/local/opt/llvm/lib/libLLVM.dylib",
    ]
    found = []
    for pattern in patterns:
        found += glob.glob(pattern)
    return found


def find_libllvm(min_version: int = MIN_VERSION) -> str | None:
    """Path of the newest libLLVM of at least ``min_version`` on this machine.

    Returns
    -------
    str or None
        An absolute path, or ``None`` when there is no suitable library.
    """
    best: tuple[int, str] | None = None
    for path in _candidate_paths():
        version = _major_version(path)
        if version is None or version < min_version or not os.path.isfile(path):
            continue
        key = (version, path)
        if best is None or key > best:
            best = key
    return str(Path(best[1]).resolve()) if best else None


def configure() -> str | None:
    """Set ``DRJIT_LIBLLVM_PATH`` to a working libLLVM unless the user set it.

    Must run before Dr.Jit starts its LLVM backend. Returns the path in use,
    or ``None`` when none was found (the LLVM variants will then fail with
    :data:`INSTALL_HINT` from :func:`mifaces.set_variant`).
    """
    if os.environ.get(ENV_VAR):
        return os.environ[ENV_VAR]
    path = find_libllvm()
    if path is not None:
        os.environ[ENV_VAR] = path
    return path


def loaded_libllvm() -> str | None:
    """Path of the libLLVM mapped into this process, if any (Linux only)."""
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                if "libLLVM" in line:
                    return line.split()[-1]
    except OSError:
        pass
    return None


def check_loaded() -> None:
    """Fail clearly if Dr.Jit already loaded an LLVM that crashes it.

    Dr.Jit reads ``DRJIT_LIBLLVM_PATH`` when it is imported, so importing
    ``drjit`` or ``mitsuba`` before ``mifaces`` can load the system LLVM 15.
    """
    path = loaded_libllvm()
    version = _major_version(path) if path else None
    if version is not None and version < MIN_VERSION:
        better = find_libllvm()
        fix = (f"set {ENV_VAR}={better} in the environment" if better else INSTALL_HINT)
        raise ImportError(
            f"Dr.Jit was imported before mifaces and loaded {path} (LLVM {version}), which "
            f"crashes Dr.Jit's LLVM backend. Import mifaces before drjit and mitsuba, or {fix}.")
