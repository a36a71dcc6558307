"""Results kept by the content of their inputs: the pipeline asks for the same rasterization of the
face's texture space, or the same texture of its region borders, for every render and every set of
samples; a :class:`ContentCache` computes each once.

Keys are digests of the inputs' bytes (arrays) and reprs (everything else), so equal inputs hit
whatever object holds them. Results are shared: their arrays are made read-only.
"""

from __future__ import annotations

import dataclasses
import hashlib
import threading
from collections import OrderedDict
from collections.abc import Callable

import numpy as np


class ContentCache:
    """The last ``size`` results of a function, keyed by the content of its inputs.

    >>> cache = ContentCache(2)
    >>> cache.get((np.arange(3), 4), lambda: np.zeros(2)).flags.writeable
    False
    """

    def __init__(self, size: int):
        if size < 1:
            raise ValueError(f"a cache holds at least one result, got size {size}")
        self.size = size
        self._items: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    @staticmethod
    def key(parts) -> str:
        """The digest of ``parts``: arrays by dtype, shape and bytes, anything else by its repr."""
        digest = hashlib.blake2b(digest_size=16)
        for part in parts:
            if isinstance(part, np.ndarray):
                array = np.ascontiguousarray(part)
                digest.update(f"{array.dtype.str}{array.shape}".encode())
                digest.update(array.tobytes())
            else:
                digest.update(repr(part).encode())
            digest.update(b"|")
        return digest.hexdigest()

    def get(self, parts, compute: Callable[[], object]):
        """The result for inputs ``parts``: the kept one, or ``compute()``'s, kept."""
        key = self.key(parts)
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
        value = _read_only(compute())
        with self._lock:
            self._items[key] = value
            while len(self._items) > self.size:
                self._items.popitem(last=False)
        return value

    def clear(self) -> None:
        with self._lock:
            self._items.clear()


def _read_only(value):
    """``value`` with its arrays (itself, a dataclass's fields, a tuple's or a dict's items) read-only."""
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
    elif dataclasses.is_dataclass(value):
        for field in dataclasses.fields(value):
            _read_only(getattr(value, field.name))
    elif isinstance(value, (tuple, list)):
        for item in value:
            _read_only(item)
    elif isinstance(value, dict):
        for item in value.values():
            _read_only(item)
    return value
