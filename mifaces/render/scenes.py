"""The Mitsuba scenes shipped with mifaces (the repository's ``scenes/``)."""

from __future__ import annotations

from pathlib import Path

#: Folder of the shipped scene files.
SCENES = Path(__file__).resolve().parents[2] / "scenes"


def scene_path(name: str) -> Path:
    """Path of the shipped scene ``name`` (``'sphere'``, ``'gallery'``)."""
    path = SCENES / f"{name}.xml"
    if not path.is_file():
        known = sorted(p.stem for p in SCENES.glob("*.xml"))
        raise FileNotFoundError(f"no shipped scene {name!r} (looked for {path}); shipped: {known}")
    return path
