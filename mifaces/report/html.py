"""``report.html``: the measurement report as a page to open in a browser.

The report's tables (per model and region the fitted parameters, fit status
and loss; per model the training and validation errors) and pictures
(``report.png``, ``report_training.png``, and ``report_lights.png`` where lights were
estimated, referenced relatively), and an
interactive 3D view of the fitted face: the exported ``.glb``
(:func:`mifaces.export.export_face`) in Google's ``<model-viewer>``, turnable
(``camera-controls``) under its built-in neutral studio lighting. Nothing is
loaded from the internet: the viewer's script is vendored in the package
(``mifaces/web``, with its licences) and copied beside the page, and the
model is inlined as a data URI, because browsers refuse to fetch local
files from a page opened from disk.
"""

from __future__ import annotations

import base64
import html
import shutil
from importlib import resources
from pathlib import Path

from ..io.atomic import atomic_write
from ..light_estimation.unknown import LIGHTS_PICTURE

#: The vendored viewer and its licences (``mifaces/web``), copied beside the page.
VIEWER = "model-viewer-umd.min.js"
LICENCES = ("LICENSE.model-viewer", "LICENSE.three", "LICENSE.lit")
#: Size of the 3D view on the page (CSS pixels).
VIEW_SIZE = (640, 560)

_STYLE = """body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; background: #fff; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.5em; text-align: left; }
th { background: #f2f2f2; }
model-viewer { width: %dpx; height: %dpx; background: #fff; display: block; }
img { max-width: 100%%; }""" % VIEW_SIZE


def _cell(value) -> str:
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(f"{v:.3g}" for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.4g}"
    return html.escape(str(value))


def _table(header: list[str], rows: list[list]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def copy_viewer(folder: Path) -> None:
    """Copy the vendored viewer script and its licences into ``folder`` (each atomically)."""
    web = resources.files("mifaces") / "web"
    for name in (VIEWER, *LICENCES):
        with resources.as_file(web / name) as source, atomic_write(folder / name) as f, open(source, "rb") as g:
            shutil.copyfileobj(g, f)


def report_html(report: dict, glb: Path | None, model: str | None, pictures: list[str]) -> str:
    """The page's text (module docstring): ``glb`` the face to show (inlined), ``model`` its BRDF model,
    ``pictures`` the report's PNGs (names relative to the page)."""
    parts = ["<!doctype html>", '<html lang="en"><head><meta charset="utf-8">',
             "<title>mifaces measurement report</title>", f"<style>{_STYLE}</style>",
             f'<script src="{VIEWER}"></script>', "</head><body>", "<h1>mifaces measurement report</h1>",
             f"<p>Capture <code>{html.escape(str(report['capture']))}</code>: {report['measurements']} photographs, "
             f"geometry {html.escape(str(report['geometry']))}, texture {report['resolution']}².</p>"]
    if glb is not None:
        data = base64.b64encode(Path(glb).read_bytes()).decode("ascii")
        parts += [f"<h2>The fitted face ({html.escape(model)}), exported as glTF</h2>",
                  f'<model-viewer id="face" src="data:model/gltf-binary;base64,{data}" camera-controls '
                  'environment-image="neutral" shadow-intensity="0.6" exposure="1.0" interaction-prompt="none" '
                  f'camera-orbit="15deg 80deg auto" alt="the fitted face, {html.escape(model)}">'
                  '<div slot="progress-bar"></div></model-viewer>',
                  f"<p>Drag to turn the face. The file: <a href=\"{Path(glb).name}\">{Path(glb).name}</a> "
                  "(<code>mifaces export</code>).</p>"]
    rows = []
    for name, entry in report["models"].items():
        for region, params in entry["regions"].items():
            fit = entry["fit"][region]
            rows.append([name, region, fit["samples"], fit["status"],
                         ", ".join(f"{k} {_cell(v)}" for k, v in params.items()), fit["loss"]])
    parts += ["<h2>Fitted BRDFs</h2>", _table(["model", "region", "samples", "status", "parameters", "loss"], rows)]
    rows = []
    for name, entry in report["models"].items():
        v = entry.get("validation") or {}
        rows.append([name, f"{100 * entry['training_rmse']:.2f}%",
                     f"{100 * v['heldout_rmse']:.2f}%" if "heldout_rmse" in v else "n/a",
                     f"{100 * v['environment_rmse']:.2f}%" if "environment_rmse" in v else "n/a",
                     f"{v['albedo_rmse']:.4f}" if "albedo_rmse" in v else "n/a"])
    parts += ["<h2>Errors</h2>", _table(["model", "training RMSE (first photograph)", "held-out-light RMSE",
                                         "environment RMSE", "albedo RMSE"], rows)]
    for picture in pictures:
        parts.append(f'<h2>{html.escape(picture)}</h2><img src="{html.escape(picture)}" alt="{html.escape(picture)}">')
    parts += ["<p>Times (s): " + ", ".join(f"{k} {v:.1f}" for k, v in report["seconds"].items()) + "</p>",
              "</body></html>", ""]
    return "\n".join(parts)


def write_html(path, report: dict, glb: Path | None = None, model: str | None = None) -> Path:
    """Write ``report.html`` at ``path`` (and the viewer beside it), atomically; the pictures
    are the ``report*.png`` beside it."""
    path = Path(path)
    pictures = [name for name in ("report.png", "report_training.png", LIGHTS_PICTURE) if (path.parent / name).is_file()]
    if glb is not None:
        copy_viewer(path.parent)
    with atomic_write(path, "w") as f:
        f.write(report_html(report, glb, model, pictures))
    return path


__all__ = ["VIEWER", "VIEW_SIZE", "report_html", "write_html", "copy_viewer"]
