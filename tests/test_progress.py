"""Progress reports stay readable when standard error is not a terminal."""

from __future__ import annotations

import io
import sys

import pytest

from mifaces.runtime.progress import EVERY_ITEM, LineProgress, progress


def _lines(monkeypatch, **kwargs) -> list[str]:
    stream = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)
    for _ in progress(**kwargs):
        pass
    text = stream.getvalue()
    assert "\r" not in text
    return text.splitlines()


def test_short_loops_report_every_item(monkeypatch):
    lines = _lines(monkeypatch, iterable=range(6), desc="reflectance samples", unit="photo")
    assert len(lines) == 6
    assert lines[0].startswith("reflectance samples: 1/6 photo")
    assert lines[-1].startswith("reflectance samples: 6/6 photo") and lines[-1].endswith("done")


def test_long_loops_report_tenths(monkeypatch):
    lines = _lines(monkeypatch, iterable=range(1000), desc="fit", unit="it")
    assert 10 <= len(lines) <= 11
    assert lines[-1].startswith("fit: 1000/1000 it")


def test_disabled_progress_is_silent(monkeypatch):
    assert _lines(monkeypatch, iterable=range(3), desc="x", enabled=False) == []


def test_manual_updates_and_postfix():
    stream = io.StringIO()
    bar = LineProgress(desc="render", unit="pass", total=EVERY_ITEM + 75, stream=stream)
    bar.set_postfix_str("skin: 100 samples")
    for _ in range(EVERY_ITEM + 75):
        bar.update()
    bar.close()
    bar.close()  # closing twice writes once
    lines = stream.getvalue().splitlines()
    assert len(lines) == 10 and all("(skin: 100 samples)" in line for line in lines)


@pytest.mark.parametrize("tty", [True, False])
def test_terminal_gets_a_bar(monkeypatch, tty):
    class Stream(io.StringIO):
        def isatty(self):
            return tty

    monkeypatch.setattr(sys, "stderr", Stream())
    bar = progress(range(2), desc="x")
    assert isinstance(bar, LineProgress) != tty
