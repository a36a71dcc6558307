"""Collecting a manifest's problems, each named with its place, for one
:class:`~mifaces.capture.CaptureError` that lists them all."""

from __future__ import annotations

import math

import numpy as np


class Problems(list):
    """Collects validation messages; each names where in the manifest it is.
    ``allow_outside``: whether image paths may leave the capture folder."""

    allow_outside = False

    def objects(self, data, key: str, what: str):
        """Yield ``(index, entry, where)`` for the objects of the non-empty list
        ``data[key]``, recording a problem for a missing list or a non-object."""
        entries = data.get(key)
        if not isinstance(entries, list) or not entries:
            self.append(f"{key}: need a non-empty list{what}")
            return
        for i, entry in enumerate(entries):
            where = f"{key}[{i}]"
            if not isinstance(entry, dict):
                self.append(f"{where}: must be an object")
                continue
            yield i, entry, where

    def unique(self, key: str, names: list[str]) -> None:
        """Record a problem for each name used more than once in ``data[key]``."""
        for name in {n for n in names if names.count(n) > 1}:
            self.append(f"{key}: name {name!r} used more than once")

    def need(self, obj, key, where, kind=None):
        if not isinstance(obj, dict) or key not in obj:
            self.append(f"{where}: missing '{key}'")
            return None
        value = obj[key]
        if kind is not None and isinstance(value, bool) and bool not in (kind if isinstance(kind, tuple) else (kind,)):
            self.append(f"{where}.{key}: must be a number, not {value!r}")
            return None
        if kind is not None and not isinstance(value, kind):
            names = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
            self.append(f"{where}.{key}: must be {names}, got {type(value).__name__} {value!r}"[:300])
            return None
        return value

    def number(self, obj, key, where, positive=False, default=None, required=True):
        if isinstance(obj, dict) and key not in obj and not required:
            return default
        value = self.need(obj, key, where, (int, float))
        if value is None or isinstance(value, bool):
            if isinstance(value, bool):
                self.append(f"{where}.{key}: must be a number, got {value!r}")
            return None
        if not math.isfinite(value) or (positive and value <= 0):
            self.append(f"{where}.{key}: must be a finite{' positive' if positive else ''} number, got {value!r}")
            return None
        return float(value)

    def vector(self, obj, key, where, length, required=True, default=None, positive=False, scalar_ok=False):
        if isinstance(obj, dict) and key not in obj and not required:
            return default
        value = self.need(obj, key, where)
        if value is None:
            return None
        if scalar_ok and isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value] * length
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            self.append(f"{where}.{key}: must be a list of {length} numbers, got {value!r}"[:300])
            return None
        if a.shape != (length,) if isinstance(length, int) else a.shape != length:
            self.append(f"{where}.{key}: must have shape {length}, got {a.shape}")
            return None
        if not np.all(np.isfinite(a)) or (positive and np.any(a <= 0)):
            self.append(f"{where}.{key}: must be finite{' and positive' if positive else ''}, got {value!r}")
            return None
        return a
