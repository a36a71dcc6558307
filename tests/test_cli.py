"""Tests of mifaces.cli.commands's option names: ``--face-model`` is the face model and
``--brdf`` the BRDF model in every command; ``--model``, which named either,
still works for one release with a deprecation message on stderr.

The API calls the commands make are replaced by a stub that reports its
arguments (as a ValueError, which a command ends with), so that these tests
parse the command lines without simulating or fitting anything."""

import pytest
from click.testing import CliRunner

import mifaces.pipeline.batch
import mifaces.cli.commands as cli
from mifaces.options.measure import MeasureOptions
from mifaces.studio.options import SimulationOptions

#: Command -> (the API function it calls, as an attribute of mifaces.cli.commands or mifaces.pipeline.batch).
CALLS = {"simulate": (cli, "simulate_capture"), "fit-shape": (cli, "fit_shapes"), "fit-brdf": (cli, "fit_brdf_model"),
         "measure": (cli, "measure_capture"), "batch": (mifaces.pipeline.batch, "measure_batch")}


class Called(ValueError):
    """The stub's report of the arguments it was called with."""


@pytest.fixture
def run(monkeypatch, tmp_path):
    """Invoke a command line with the API stubbed; the result and the arguments of the API call."""
    calls = []

    def stub(*args, **kwargs):
        calls.append((args, kwargs))
        raise Called("stubbed")

    for module, name in CALLS.values():
        monkeypatch.setattr(module, name, stub)

    def invoke(*args):
        result = CliRunner().invoke(cli.main, [str(a) for a in args])
        return result, (calls[-1] if calls else None)

    return invoke


def _arguments(command: str, tmp_path):
    """The command's arguments before its options."""
    capture = tmp_path / "capture"
    capture.mkdir(exist_ok=True)
    return {"simulate": [tmp_path / "sim"], "fit-shape": [capture, "--out", tmp_path / "shapes"],
            "fit-brdf": [capture, "--out", tmp_path / "brdf", "--no-refine"],
            "measure": [capture, "--out", tmp_path / "measure"],
            "batch": [capture, "--out", tmp_path / "batch"]}[command]


def _face_model(call):
    """The face model of the call: simulate's options', fit-shape's second argument."""
    args, kwargs = call
    options = [a for a in args if isinstance(a, SimulationOptions)]
    return options[0].face_model if options else args[1]


def _brdf(call):
    """The BRDF model(s) of the call: fit-brdf's second argument, the models of measure's and batch's options."""
    args, kwargs = call
    options = [a for a in args if isinstance(a, MeasureOptions)]
    return options[0].models if options else args[1]


@pytest.mark.parametrize("command", ["simulate", "fit-shape"])
def test_face_model_option_and_its_deprecated_spelling(run, tmp_path, command):
    """``--face-model`` sets the face model quietly; ``--model`` still does, with a warning naming --face-model."""
    result, call = run(command, *_arguments(command, tmp_path), "--face-model", "face.npz")
    assert "stubbed" in result.output and _face_model(call) == "face.npz"
    assert "deprecated" not in result.stderr
    result, call = run(command, *_arguments(command, tmp_path), "--model", "old.npz")
    assert "stubbed" in result.output and _face_model(call) == "old.npz"
    assert "--model is deprecated" in result.stderr and "use --face-model" in result.stderr
    assert "deprecated" not in result.stdout


@pytest.mark.parametrize("command", ["fit-brdf", "measure", "batch"])
def test_brdf_option_and_its_deprecated_spelling(run, tmp_path, command):
    """``--brdf`` sets the BRDF model(s) quietly; ``--model`` still does, with a warning naming --brdf."""
    several = command != "fit-brdf"
    result, call = run(command, *_arguments(command, tmp_path), "--brdf", "ward")
    assert "stubbed" in result.output and _brdf(call) == (("ward",) if several else "ward")
    assert "deprecated" not in result.stderr
    result, call = run(command, *_arguments(command, tmp_path), "--model", "phong")
    assert "stubbed" in result.output and _brdf(call) == (("phong",) if several else "phong")
    assert "--model is deprecated" in result.stderr and "use --brdf" in result.stderr
    if several:
        result, call = run(command, *_arguments(command, tmp_path), "--model", "phong", "--model", "ward")
        assert _brdf(call) == ("phong", "ward")


def test_the_deprecated_spelling_is_checked_and_not_given_twice(run, tmp_path):
    """``--model`` takes the values of the option it stands for, and with that option it is a usage error."""
    result, _ = run("fit-brdf", *_arguments("fit-brdf", tmp_path), "--model", "blinn")
    assert result.exit_code == 2 and "'blinn' is not one of" in result.output
    result, call = run("measure", *_arguments("measure", tmp_path), "--brdf", "ward", "--model", "phong")
    assert result.exit_code == 2 and "not both --brdf and --model" in result.output and call is None


@pytest.mark.parametrize("command", ["simulate", "fit-shape", "fit-brdf", "measure", "batch"])
def test_help_names_the_new_options_only(command):
    """Each command's help lists --face-model or --brdf, and no longer --model."""
    result = CliRunner().invoke(cli.main, [command, "--help"])
    assert result.exit_code == 0
    assert "--model" not in result.output
    assert ("--face-model" if command in ("simulate", "fit-shape") else "--brdf") in result.output


@pytest.mark.parametrize("flags, judged, early_stop", [
    (["--refine-shape"], 0, False),
    (["--refine-shape", "--refine-shape-judged", "1", "--refine-shape-early-stop"], 1, True)])
def test_measure_passes_the_shape_refinement_schedule(run, tmp_path, flags, judged, early_stop):
    result, (args, _) = run("measure", *_arguments("measure", tmp_path), *flags)
    schedule = args[2].refine_shape
    assert (schedule.judged, schedule.early_stop) == (judged, early_stop)
    result, (args, _) = run("measure", *_arguments("measure", tmp_path))
    assert args[2].refine_shape is None  # off unless asked
