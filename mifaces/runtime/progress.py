"""Progress of long work, readable on a terminal and in a log file alike.

On a terminal, :func:`progress` is a ``tqdm`` bar on standard error. When
standard error is not a terminal (a redirected log, a batch job, a test
runner) bar redraws would fill the log with carriage returns, so it writes
plain lines instead: one per finished item for short loops (photographs,
regions, render passes), one per tenth of the work for long ones, and a
closing line with the time taken.
"""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

#: Loops of at most this many items report every item when not on a terminal.
EVERY_ITEM = 25


def _on_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # closed or replaced streams
        return False


class LineProgress:
    """The line-per-step form of :func:`progress` (same interface as the part
    of ``tqdm`` that mifaces uses: iteration, ``update``, ``set_postfix_str``,
    ``close``)."""

    def __init__(self, iterable=None, desc: str = "", unit: str = "it", total: int | None = None,
                 stream=None, enabled: bool = True):
        self.iterable = iterable
        self.desc, self.unit = desc, unit
        self.total = total if total is not None else (len(iterable) if hasattr(iterable, "__len__") else None)
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.count = 0
        self.postfix = ""
        self.start = time.perf_counter()
        self.closed = False
        step = 1 if self.total is None or self.total <= EVERY_ITEM else max(1, self.total // 10)
        self._step, self._next = step, step

    def _write(self, text: str) -> None:
        if self.enabled:
            print(text, file=self.stream, flush=True)

    def _line(self) -> str:
        of = f"/{self.total}" if self.total is not None else ""
        postfix = f" ({self.postfix})" if self.postfix else ""
        return f"{self.desc}: {self.count}{of} {self.unit} {time.perf_counter() - self.start:.1f} s{postfix}"

    def update(self, n: int = 1) -> None:
        self.count += n
        done = self.total is not None and self.count >= self.total
        if self.count >= self._next and not done:
            self._write(self._line())
            while self._next <= self.count:
                self._next += self._step

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        self.postfix = text

    def set_postfix(self, ordered_dict=None, refresh: bool = True, **values) -> None:
        values = {**(ordered_dict or {}), **values}
        self.postfix = ", ".join(f"{k}={v}" for k, v in values.items())

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._write(self._line() + (" done" if self.total is None or self.count >= self.total else ""))

    def __iter__(self):
        try:
            for item in self.iterable:
                yield item
                self.update()
        finally:
            self.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress(iterable=None, desc: str = "", unit: str = "it", total: int | None = None, enabled: bool = True,
             leave: bool = True, detail: bool = False):
    """Report progress over ``iterable`` (or, without one, of ``total`` steps
    advanced by ``update``): a tqdm bar on a terminal, else plain lines (see
    the module docstring). ``enabled=False`` reports nothing; ``detail=True``
    marks an inner loop (the iterations of one photograph's fit, the passes of
    one render), shown as a bar on a terminal and left out of logs, where the
    enclosing loop's lines say enough."""
    if enabled and _on_terminal(sys.stderr):
        return tqdm(iterable, desc=desc, unit=unit, total=total, leave=leave)
    return LineProgress(iterable, desc, unit, total, enabled=enabled and not detail)


__all__ = ["progress", "LineProgress"]
