"""mifaces' version, from the installed package's metadata (``pyproject.toml`` is its one source)."""

from importlib.metadata import PackageNotFoundError, version

try:
    VERSION = version("mifaces")
except PackageNotFoundError:  # a source tree on sys.path that was never installed
    VERSION = "unknown"

__all__ = ["VERSION"]
