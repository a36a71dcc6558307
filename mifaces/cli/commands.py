"""The ``mifaces`` command line: a thin layer over the Python API.

Each command is one API call that a script could make. An option means the
same in every command: ``--face-model`` names the face model (``simulate``,
``fit-shape``, ``fit-brdf``, ``measure``, ``batch``, ``export``) and ``--brdf`` the BRDF model
(``simulate``'s ground truth, the model ``fit-brdf`` fits, the models
``measure`` and ``batch`` fit). ``--model``, which named the one or the
other, still works for one release with a deprecation message
(:func:`mifaces.cli.options.renamed`). The flags of an options value are made from
its fields, declared once (:func:`mifaces.cli.options.option_flags`): ``fit-brdf``,
``measure`` and ``batch`` take the fit's (:class:`~mifaces.reflectance.FitOptions`),
``measure`` and ``batch`` the main job's (:class:`~mifaces.options.measure.MeasureOptions`),
``simulate`` the simulation's (:class:`~mifaces.studio.options.SimulationOptions`) and ``render``
the render's (:class:`~mifaces.reflectance.RenderOptions`, its light a
:class:`~mifaces.lights.relighting.Relighting`).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import click

import mifaces

from ..brdf import NAMES as BRDF_MODELS
from ..capture import load_capture
from ..capture.ground_truth import ground_truth_folder
from ..export import export_face
from ..io.atomic import write_json
from ..io.paths import check_writable
from ..io.result_set import ResultTarget, check_result_target
from ..report.gallery import render_gallery
from ..importers.cli import export_calibration_command, import_
from ..capture.detector import NoFaceError, detect_landmarks
from .options import default, option_flags, renamed
from ..model import load_model
from ..options.measure import MeasureOptions
from ..pipeline.measure import measure as measure_capture
from ..shape.io import load_geometry
from ..reflectance import FitOptions, RenderOptions, fit_brdf as fit_brdf_model, render_fitted
from ..reflectance.io import KIND as BRDF_KIND, write_fitted
from ..refine import refine_estimate
from ..refine.shape_lit import refine_fits
from ..report.measurement import RANKED, format_value, ranking_sentence
from ..shape import ShapeOptions, fit_shape as fit_shapes
from ..shape.io import INDEX as SHAPES_INDEX, write_fit, write_index
from ..runtime.status import CONVERGED
from ..studio.options import SimulationOptions
from ..studio.simulate import simulate as simulate_capture



class Commands(click.Group):
    """The command group: the library's errors (bad input, missing files, a
    failed stage) end a command with their message and exit code 1, not a
    traceback."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except (ValueError, KeyError, OSError) as error:  # a programming error (TypeError, ...) keeps its traceback
            message = error.args[0] if isinstance(error, KeyError) and error.args else str(error)
            raise click.ClickException(str(message)) from None


@click.group(cls=Commands)
@click.option("--variant", default=None, help="Mitsuba variant (default: cuda_ad_rgb with a GPU, else llvm_ad_rgb).")
def main(variant: str | None) -> None:
    """Measure the reflectance of human faces from photographs."""
    # warnings read as messages on the command line, not as source excerpts
    warnings.formatwarning = lambda message, category, *args, **kwargs: f"warning: {message}\n"
    mifaces.set_variant(variant)


# Commands are added below, one per pipeline stage.


@main.command()
@click.option("--out", "out_dir", default=default(render_gallery, "out_dir"), show_default=True,
              type=click.Path(file_okay=False),
              help="Folder for gallery.exr and gallery.png.")
@click.option("--spp", default=default(render_gallery, "spp"), show_default=True, type=click.IntRange(1),
              help="Samples per pixel.")
@click.option("--size", default=(default(render_gallery, "width"), default(render_gallery, "height")),
              show_default=True, type=(click.IntRange(8), click.IntRange(8)),
              help="Image width and height.")
def gallery(out_dir: str, spp: int, size: tuple[int, int]) -> None:
    """Render the BSDF gallery: one sphere per plugin (phong, cooktorrance, ward, lafortune)."""
    result = render_gallery(out_dir, spp=spp, width=size[0], height=size[1])
    click.echo(f"rendered the gallery in {result['seconds']:.1f} s ({result['variant']}, {spp} spp)")
    click.echo(f"  {result['exr']}\n  {result['png']}")


@main.command()
@renamed("--model", "--face-model", "face_model")
@click.argument("out", type=click.Path(file_okay=False))
@option_flags(SimulationOptions)
@click.option("--force", is_flag=True, help="Replace a simulated capture at OUT (never a real one).")
def simulate(out: str, force: bool, options: SimulationOptions) -> None:
    """Simulate a capture session with ground truth into folder OUT (paper sec. 3)."""
    result = simulate_capture(out, options, force=force)
    lights = (f"the {options.environment} environment" if options.environment is not None
              else f"{result.lights} light{'s' * (result.lights != 1)}")
    click.echo(f"simulated {result.measurements} measurement{'s' * (result.measurements != 1)} under "
               f"{lights} in {result.seconds:.1f} s "
               f"({result.seconds_per_measurement:.1f} s per measurement)")
    click.echo(f"  capture:      {result.path}\n  ground truth: {ground_truth_folder(result.path)}")


@main.command("fit-shape")
@renamed("--model", "--face-model", "face_model")
@click.argument("capture", type=click.Path(exists=True))
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Folder for <measurement>.npy/.json and shapes.json.")
@click.option("--face-model", default=default(fit_shapes, "model"), show_default=True,
              help="Face model: 'builtin' or a model file (Surrey npz/bin, Basel mat/h5).")
@click.option("--measurements", multiple=True, help="Fit only these measurements (repeatable; default: all).")
@click.option("--iterations", default=None, type=click.FloatRange(min=0.01),
              help="Scale of the default iteration schedule (e.g. 0.25 for a quick fit).")
@click.option("--no-diffuse", is_flag=True, help="Ignore the companion diffuse-light pictures.")
@click.option("--fixed-focal", is_flag=True, help="Keep the calibrated focal length.")
@click.option("--force", is_flag=True, help="Write over the fits in --out (those not fitted again are kept).")
@option_flags(MeasureOptions, "refinement", only=("refine_shape",))
def fit_shape(capture: str, out_dir: str, face_model: str, measurements: tuple[str, ...], iterations: float | None,
              no_diffuse: bool, fixed_focal: bool, force: bool, refinement: MeasureOptions) -> None:
    """Fit the face model to every photograph of CAPTURE (paper sec. 4.2)."""
    check_writable(out_dir)
    if (Path(out_dir) / SHAPES_INDEX).exists() and not force:
        raise click.ClickException(f"{out_dir} holds fitted shapes already ({SHAPES_INDEX}); use --force to "
                                   "write over them")
    fits = fit_shapes(capture, face_model, measurements=list(measurements) or None, out=out_dir, iterations=iterations,
                      progress=True, options=ShapeOptions(use_diffuse=not no_diffuse, fit_focal=not fixed_focal))
    schedule = refinement.refine_shape
    if schedule is not None:
        loaded, model = load_capture(capture), load_model(face_model).truncated(load_model(face_model).fit_shape_modes)
        fits, refinement = refine_fits(loaded, fits, model, schedule=schedule)
        click.echo(f"shape refinement: {'kept' if refinement.accepted else 'not kept'}: {refinement.reason}")
        if refinement.accepted:
            for f in fits:
                write_fit(out_dir, f, model)
            write_index(out_dir, loaded, model, fits, model_source=face_model)
    for f in fits:
        click.echo(f"  {f.measurement}: {f.status:13s} landmarks {f.loss.get('feature_rms_px', float('nan')):.2f} px, "
                   f"{f.seconds:.1f} s")
    failed = [f.measurement for f in fits if f.status != CONVERGED]
    click.echo(f"wrote {out_dir}/shapes.json")
    if failed:
        raise click.ClickException(f"{len(failed)} fit(s) did not converge: {', '.join(failed)} (see their .json)")


@main.command("fit-brdf")
@renamed("--model", "--brdf", "brdf_model", type=click.Choice(BRDF_MODELS))
@click.argument("capture", type=click.Path(exists=True))
@click.option("--brdf", "brdf_model", default=default(fit_brdf_model, "model"), show_default=True,
              type=click.Choice(BRDF_MODELS), help="BRDF model to fit per region.")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Folder for brdf.json, albedo.exr and scene.xml.")
@click.option("--geometry", default=default(fit_brdf_model, "geometry"), show_default=True,
              help="'ground-truth' (a simulated capture's) or the folder mifaces fit-shape wrote.")
@click.option("--face-model", default=None, help="Face model of the geometry (default: the one it names).")
@click.option("--force", is_flag=True, help="Replace the fitted BRDF in --out.")
@option_flags(FitOptions)
@option_flags(MeasureOptions, "refinement", only=("refine",))
def fit_brdf(capture: str, brdf_model: str, out_dir: str, geometry: str, face_model: str | None, force: bool,
             options: FitOptions, refinement: MeasureOptions) -> None:
    """Fit a BRDF model per region to the photographs of CAPTURE (paper sec. 4.3-5.3)."""
    check_result_target(out_dir, BRDF_KIND, force)
    if not refinement.refine:
        estimate = fit_brdf_model(capture, brdf_model, geometry, face_model=face_model, options=options,
                                  out=ResultTarget(out_dir, force))
    else:  # the refinement, the next stage, before the result is written
        capture = load_capture(capture)
        face, shapes = load_geometry(capture, geometry, face_model)
        estimate = refine_estimate(fit_brdf_model(capture, brdf_model, shapes, face_model=face, options=options),
                                   capture, shapes, face)
        write_fitted(estimate, out_dir, capture, face, shapes, force=force)
    click.echo(f"fitted {estimate.model} to {estimate.samples} samples of {len(estimate.measurements)} "
               f"photographs in {estimate.seconds['total']:.1f} s")
    for name, fit_ in estimate.fits.items():
        params = ", ".join(f"{k}={format_value(v, list_digits=4)}" for k, v in fit_.params.items()
                           if k != "diffuse_reflectance")
        click.echo(f"  {name:9s} {fit_.samples:8d} samples  {fit_.status:10s} {params}")
    maps = "".join(f"{name}.exr, " for name, value in (("normals", estimate.normals), ("specular", estimate.specular))
                   if value is not None)
    click.echo(f"wrote {out_dir}/brdf.json, albedo.exr, {maps}scene.xml")


@main.command()
@renamed("--model", "--brdf", "models", multiple=True, type=click.Choice(BRDF_MODELS))
@click.argument("capture", required=False, type=click.Path(exists=True))
@click.option("--out", "out_dir", default="out/measure", show_default=True, type=click.Path(file_okay=False),
              help="Output folder (capture/, shapes/, brdf/<model>/, report.md/json/png).")
@option_flags(MeasureOptions)
def measure(capture: str | None, out_dir: str, options: MeasureOptions) -> None:
    """The main job: from CAPTURE (default: a simulated capture of the built-in face) to fitted BRDFs and a report."""
    check_writable(out_dir)
    report = measure_capture(out_dir, capture, options)
    for model, entry in report["models"].items():
        skin = entry["regions"].get("skin", {})
        truth = (entry.get("ground_truth") or {}).get("regions", {}).get("skin")
        errors = f"  (vs ground truth: {', '.join(f'{k} {100 * v:.1f}%' for k, v in truth.items())})" if truth else ""
        values = ", ".join(f"{k}={format_value(v, list_digits=4)}" for k, v in skin.items())
        click.echo(f"{model:13s} skin: {values}{errors}")
    face = report.get("face_model") or {}
    if "truth_shape_modes" in face:
        errors = report.get("shape_errors") or {}
        click.echo(f"face: fitted on the leading {face['fit_shape_modes']} of {face['model_shape_modes']} identity "
                   f"modes; the simulated truth drew on {face['truth_shape_modes']}, so it lies outside the fitted "
                   "span: the errors above include the shape's" + (
                       f" (fitted faces {errors['mean_world_mm']:.1f} mm from the truth on average, "
                       f"{errors['mean_aligned_mm']:.1f} mm after a rigid alignment)" if errors else ""))
    for key, order in report.get("ranking", {}).items():
        click.echo(f"ranked by {RANKED[key]} (novel pose, relative image RMSE; ≈: within the renders' noise): "
                   + ranking_sentence(report["models"], order, report.get("ties", {}).get(key, []), key))
    click.echo(f"done in {report['seconds']['total']:.0f} s; report: {out_dir}/report.md, report.png and report.html")


@main.command()
@click.argument("brdf_dir", type=click.Path(exists=True, file_okay=False))
@click.argument("capture", type=click.Path(exists=True))
@click.option("--out", "out_stem", required=True, type=click.Path(dir_okay=False),
              help="Output image path without suffix: writes OUT.exr and OUT.png.")
@option_flags(RenderOptions)
def render(brdf_dir: str, capture: str, out_stem: str, options: RenderOptions) -> None:
    """Render the BRDF fitted in BRDF_DIR on a face of CAPTURE, in the capture's camera and units: novel poses,
    point or directional lights, environment maps, a sun and sky, or another person's face (BRDF transfer)."""
    check_writable(Path(out_stem).parent)
    paths = render_fitted(brdf_dir, capture, out_stem, options)
    click.echo(f"wrote {paths['exr']} and {paths['png']}")


@main.command()
@click.argument("result", type=click.Path(exists=True, file_okay=False))
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Output file: .glb or .gltf (glTF 2.0), .obj (with .mtl and textures), .usd, .usda or .usdc.")
@click.option("--measurement", default=None,
              help="Export the shape fitted to this photograph (default: the face model's mean shape).")
@click.option("--shapes", default=None, type=click.Path(exists=True, file_okay=False),
              help="The fit-shape folder of that fit (default: shapes/ of the measure run RESULT belongs to).")
@click.option("--face-model", default=None, help="Face model (default: the one the fitted shapes name, else builtin).")
def export(result: str, out_path: str, measurement: str | None, shapes: str | None, face_model: str | None) -> None:
    """Write the face measured in RESULT (a fit-brdf or measure model folder, e.g. out/measure/brdf/cooktorrance)
    as glTF, OBJ or USD with PBR textures."""
    written = export_face(result, out_path, measurement=measurement, shapes=shapes, face_model=face_model)
    click.echo("wrote " + ", ".join(str(p) for p in written))


@main.command()
@click.argument("images", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="JSON file: {IMAGE: {points: 68 [x, y], box: [x0, y0, x1, y1]}}.")
@click.option("--box", default=None, type=(int, int, int, int),
              help="Face box X0 Y0 X1 Y1 for every image (pixels, X1 Y1 inside), skipping the face detector.")
def landmarks(images: tuple[str, ...], out_path: str, box) -> None:
    """Find the 68 iBUG landmarks of the face in each of IMAGES (pixel centres at integers)."""
    found, failed = {}, []
    for image in images:
        try:
            result = detect_landmarks(image, box=box)
        except NoFaceError as error:
            click.echo(f"error: {error}", err=True)
            failed.append(image)
            continue
        found[image] = {"points": result.points.tolist(), "box": list(result.box)}
    write_json(out_path, found)
    click.echo(f"wrote the landmarks of {len(found)} of {len(images)} images to {out_path}")
    if failed:
        raise SystemExit(1)


main.add_command(import_)
main.add_command(export_calibration_command)


@main.command()
@renamed("--model", "--brdf", "models", multiple=True, type=click.Choice(BRDF_MODELS))
@click.argument("inputs", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False))
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Batch folder: <name>/ per capture (as mifaces measure writes it), batch.json, population.md/json/png.")
@click.option("--workers", type=click.IntRange(1), default=None,
              help="Worker processes of the local Dask cluster (default: one per core, at most one per capture).")
@click.option("--scheduler", default=None,
              help="Address (tcp://host:port) or scheduler file of a running Dask scheduler, instead of a local cluster.")
@click.option("--resume", is_flag=True, help="Skip captures whose results in --out are complete and fitted with "
                                              "these options (the others are measured again).")
@click.option("--import", "importer", default=None,
              help="'yaleb': INPUTS are raw data (Yale subject folders, or folders of them), imported into OUT/captures "
                   "first (mifaces.pipeline.batch.IMPORTERS).")
@option_flags(MeasureOptions)
def batch(inputs: tuple[str, ...], out_dir: str, workers: int | None, scheduler: str | None, resume: bool,
          importer: str | None, options: MeasureOptions) -> None:
    """Measure many captures (INPUTS: capture folders or folders of them) on Dask, and write a population report."""
    from ..pipeline.batch import Cluster, measure_batch  # Dask's import is slow: only for this command

    record = measure_batch(inputs, out_dir, options, cluster=Cluster(workers, scheduler), resume=resume,
                           importer=importer, echo=click.echo)
    counts = {s: sum(e["status"] == s for e in record["captures"].values()) for s in ("done", "skipped", "failed")}
    click.echo(f"{counts['done']} measured, {counts['skipped']} skipped (complete), {counts['failed']} failed in "
               f"{record['seconds']:.0f} s; population report: {out_dir}/population.md")
    if record["failed"]:
        raise click.ClickException(f"{len(record['failed'])} capture(s) failed: {', '.join(record['failed'])} "
                                   f"(errors in {out_dir}/batch.json)")
