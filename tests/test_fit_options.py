"""FitOptions: the one value of the BRDF fit's options, and the keywords it replaced (deprecated,
still accepted with a warning; a keyword it has no field for is an error naming it)."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import pytest

from mifaces.reflectance import FitOptions, fit_brdf
from mifaces.reflectance.options import fit_options


def test_old_keywords_warn_and_become_options():
    with pytest.warns(DeprecationWarning, match=r"options=FitOptions\(resolution=\.\.\., normals=\.\.\.\)"):
        options = fit_options(None, {"resolution": 64, "normals": True}, "fit_brdf")
    assert options == FitOptions(resolution=64, normals=True)
    with pytest.warns(DeprecationWarning):  # fit_brdf's old `options`: the model's options
        assert fit_options({"lobes": 2}, {}, "fit_brdf").model_options == {"lobes": 2}
    base = FitOptions(resolution=32)
    with pytest.warns(DeprecationWarning):
        assert fit_options(base, {"specular_maps": True}, "measure") == FitOptions(resolution=32, specular_maps=True)


def test_no_warning_without_old_keywords(recwarn):
    assert fit_options(None, {}, "fit_brdf") == FitOptions()
    assert not [w for w in recwarn if issubclass(w.category, DeprecationWarning)]


@pytest.mark.parametrize("flags, message", [({"refine": True}, "no longer refines: call mifaces.refine"),
                                            ({"resolutoin": 64}, r"unexpected keyword argument\(s\) \['resolutoin'\]")])
def test_unknown_keywords_are_named(flags, message):
    with pytest.raises(TypeError, match=message):
        fit_options(None, flags, "fit_brdf")
    with pytest.raises(TypeError, match=message):  # before anything is loaded or fitted
        fit_brdf("no-such-capture", **flags)


def test_bad_options_are_named():
    with pytest.raises(ValueError, match="uncertainty must be one of"):
        FitOptions(uncertainty="guess")
    with pytest.raises(ValueError, match=r"resolution must be an integer in \[8, "):
        FitOptions(resolution=0)


def test_the_light_a_fit_was_fitted_under_is_the_refined_map():
    """An estimated map that the refinement refined is the light its scene.xml and render_fitted show
    (the brdf.json record as load_estimate returns it); a given light is itself."""
    import numpy as np

    from mifaces.capture import Light
    from mifaces.reflectance.result import fitted_light

    start, refined = np.ones((4, 8, 3), np.float32), np.full((4, 8, 3), 2.0, np.float32)
    estimated = Light("room", None, np.ones(3), kind="environment", estimated=True, envmap=start)
    record = {"environment_maps": {"room": refined.tolist()}}
    np.testing.assert_array_equal(fitted_light(estimated, record).envmap, refined)
    assert fitted_light(estimated, None) is estimated and fitted_light(estimated, {"environment_maps": {}}) is estimated
    given = Light("lamp", np.zeros(3), np.ones(3))
    assert fitted_light(given, record) is given
