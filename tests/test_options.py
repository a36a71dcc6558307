"""mifaces.options: an options value validated on construction (the error names the field),
recorded whole and read back equal, built the same from measure's keywords and from the value,
and its command-line flags made from its fields (one declaration per flag)."""

from __future__ import annotations

import json

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import pytest
from click.testing import CliRunner

import mifaces.cli.commands as cli
from mifaces.options.measure import MeasureOptions
from mifaces.reflectance import FitOptions
from mifaces.reflectance.fit.region_fit import SubsetSchedule
from mifaces.refine import ShapeRefineSchedule

#: Options other than the defaults in every field a record holds (nested ones too).
CHANGED = MeasureOptions(models=("lafortune",), geometry="ground-truth", face_model="face.npz", shape_iterations=0.25,
                         fit=FitOptions(resolution=64, lobes=2, model_options={"fresnel": "schlick"},
                                        fixed={"eta": 1.38}, schedule=SubsetSchedule(first=500), seed=3, normals=True,
                                        normal_options={"rounds": 2}, specular_maps=True, uncertainty=None,
                                        albedo_rounds=1, texel_albedo=False, balance_lights=True,
                                        interreflection=True),
                         refine=True, refine_shape=ShapeRefineSchedule(judged=1, early_stop=True), spp=2)


@pytest.mark.parametrize("options", [MeasureOptions(), CHANGED], ids=["defaults", "changed"])
def test_a_record_reads_back_equal(options):
    record = json.loads(json.dumps(options.to_record()))
    assert MeasureOptions.from_record(record) == options
    assert FitOptions.from_record(record["fit"]) == options.fit


@pytest.mark.parametrize("fields, message", [
    ({"models": ("blinn",)}, r"MeasureOptions\.models must be one or more of 'phong'.*got \('blinn',\)"),
    ({"models": ()}, r"MeasureOptions\.models must be one or more of"),
    ({"geometry": "guess"}, r"MeasureOptions\.geometry must be one of 'fitted', 'ground-truth', got 'guess'"),
    ({"spp": 0}, r"MeasureOptions\.spp must be an integer in \[1, inf\], got 0"),
    ({"shape_iterations": 0.0}, r"MeasureOptions\.shape_iterations must be a number in \[0\.01, inf\]"),
    ({"fit": FitOptions(lobes=2)}, r"MeasureOptions\.fit\.lobes is 2, but phong, cooktorrance, ward have one lobe"),
    ({"refine_shape": "yes"}, r"MeasureOptions\.refine_shape must be a ShapeRefineSchedule")])
def test_bad_options_name_their_field(fields, message):
    with pytest.raises(ValueError, match=message):
        MeasureOptions(**fields)


@pytest.mark.parametrize("fields, message", [
    ({"resolution": 4}, r"FitOptions\.resolution must be an integer in \[8, 8192\], got 4"),
    ({"resolution": 64.0}, r"FitOptions\.resolution must be an integer"),
    ({"lobes": 9}, r"FitOptions\.lobes must be an integer in \[1, 8\]"),
    ({"uncertainty": "guess"}, r"FitOptions\.uncertainty must be one of 'jackknife', .*None, got 'guess'"),
    ({"albedo_rounds": -1}, r"FitOptions\.albedo_rounds must be an integer in \[0, inf\]")])
def test_bad_fit_options_name_their_field(fields, message):
    with pytest.raises(ValueError, match=message):
        FitOptions(**fields)


def test_bad_schedule_names_its_field():
    with pytest.raises(ValueError, match=r"ShapeRefineSchedule\.judged must be an integer in \[0, inf\], got -1"):
        ShapeRefineSchedule(judged=-1)


def test_a_record_of_other_options_is_refused():
    record = MeasureOptions().to_record()
    with pytest.raises(ValueError, match=r"MeasureOptions has no option\(s\) \['colour'\]"):
        MeasureOptions.from_record({**record, "colour": 1})
    with pytest.raises(ValueError, match=r"FitOptions has no option\(s\) \['lobe'\]"):
        MeasureOptions.from_record({**record, "fit": {"lobe": 2}})


def test_old_and_new_spellings_give_the_same_options(recwarn):
    """measure's keywords, as it took them before the options value, build the same value."""
    new = MeasureOptions(models=("phong",), geometry="ground-truth", spp=2, refine=True,
                         refine_shape=ShapeRefineSchedule(), fit=FitOptions(resolution=32))
    old = MeasureOptions.of(FitOptions(resolution=32), {"models": ("phong",), "geometry": "ground-truth", "spp": 2,
                                                        "refine": True, "refine_shape": True})
    assert old == new and MeasureOptions.of(new) is new
    assert not [w for w in recwarn if issubclass(w.category, DeprecationWarning)]
    with pytest.warns(DeprecationWarning, match=r"measure\(resolution=\.\.\.\) is deprecated"):
        assert MeasureOptions.of(None, {"models": ["phong"], "geometry": "ground-truth", "spp": 2, "refine": True,
                                        "refine_shape": True, "resolution": 32}) == new
    with pytest.raises(TypeError, match=r"measure\(\) got unexpected keyword argument\(s\) \['resolutoin'\]"):
        MeasureOptions.of(None, {"resolutoin": 32})


def test_resolved_is_the_fits_plan():
    # per-texel normals, the default: their glossy fit takes the albedo offsets out, once at least
    assert FitOptions().resolved() == FitOptions(albedo_rounds=1, texel_albedo=False)
    assert FitOptions(albedo_rounds=3).resolved() == FitOptions(albedo_rounds=3, texel_albedo=False)
    assert FitOptions(normals=False).resolved() == FitOptions(normals=False)
    assert FitOptions(normals=False, albedo_rounds=2).resolved() == FitOptions(normals=False, albedo_rounds=2,
                                                                               texel_albedo=False)
    assert MeasureOptions(fit=FitOptions(normals=True)).resolved().fit == FitOptions(normals=True).resolved()


@pytest.fixture
def called(monkeypatch):
    """Run a command line with its API call stubbed: the arguments it was called with."""
    import mifaces.pipeline.batch

    calls = []

    def stub(*args, **kwargs):
        calls.append((args, kwargs))
        raise ValueError("stubbed")

    for module, name in ((cli, "fit_brdf_model"), (cli, "measure_capture"), (mifaces.pipeline.batch, "measure_batch")):
        monkeypatch.setattr(module, name, stub)

    def invoke(*args):
        calls.clear()
        result = CliRunner().invoke(cli.main, [str(a) for a in args])
        return result, (calls[-1] if calls else None)

    return invoke


FIT_FLAGS = ["--resolution", "64", "--lobes", "2", "--normals", "--specular-maps", "--uncertainty", "none",
             "--no-texel-albedo", "--balance-lights", "--interreflection"]
FIT = FitOptions(resolution=64, lobes=2, normals=True, specular_maps=True, uncertainty=None, texel_albedo=False,
                 balance_lights=True, interreflection=True)


@pytest.mark.parametrize("command", ["fit-brdf", "measure", "batch"])
def test_every_fitting_command_takes_the_fit_options(called, tmp_path, command):
    """The same fit flags on each command, one range for --resolution, and the value built from them."""
    (tmp_path / "capture").mkdir(exist_ok=True)
    head = [command, tmp_path / "capture", "--out", tmp_path / "out", "--brdf", "lafortune"]
    result, (args, kwargs) = called(*head, *FIT_FLAGS)
    assert "stubbed" in result.output
    assert (kwargs["options"] if command == "fit-brdf" else args[2].fit) == FIT
    result, call = called(*head, "--resolution", "4")
    assert result.exit_code == 2 and "4 is not in the range 8<=x<=8192" in result.output and call is None


@pytest.mark.parametrize("command", ["measure", "batch"])
def test_measure_and_batch_pass_the_options_whole(called, tmp_path, command):
    (tmp_path / "capture").mkdir(exist_ok=True)
    result, (args, _) = called(command, tmp_path / "capture", "--out", tmp_path / "out", "--brdf", "phong", "--brdf",
                               "ward", "--geometry", "ground-truth", "--face-model", "face.npz",
                               "--shape-iterations", "0.5", "--resolution", "32", "--refine", "--refine-shape",
                               "--refine-shape-judged", "1", "--spp", "2")
    assert args[2] == MeasureOptions(models=("phong", "ward"), geometry="ground-truth", face_model="face.npz",
                                     shape_iterations=0.5, fit=FitOptions(resolution=32), refine=True,
                                     refine_shape=ShapeRefineSchedule(judged=1), spp=2)
    result, (args, _) = called(command, tmp_path / "capture", "--out", tmp_path / "out")
    assert args[2] == MeasureOptions()  # every default the API's
    result, call = called(command, tmp_path / "capture", "--out", tmp_path / "out", "--lobes", "2")
    assert result.exit_code == 1 and "MeasureOptions.fit.lobes is 2" in result.output and call is None


def test_no_flag_is_declared_twice(monkeypatch):
    """validation/design_metrics.py's count of flags copied between commands (one API option declared
    twice) is 0."""
    import importlib
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    monkeypatch.syspath_prepend(str(root / "validation"))
    metrics = importlib.import_module("design_metrics")
    assert metrics.copied_flags(metrics.duplicate_flags(root)) == {}
