

def test_balance_intensities_gives_one_albedo(tmp_path):
    """Samples of one face under three estimated lights whose intensities are off by known factors
    (with highlights and grazing samples as outliers): the factors are found and undone."""
    from mifaces.lighting import balance_intensities
    from mifaces.reflectance.samples import ReflectanceSamples

    capture = estimate_lights(_capture(tmp_path, [{"name": "top", "unknown": True},
                                                  {"name": "side", "unknown": True}]),
                              [fitted("m0", (0, 0, -1)), fitted("m1", (0.5, 0, -0.8)), fitted("m2", (0.5, 0, -0.8))])
    capture = replace(capture, lights=capture.lights[:2] + (replace(capture.lights[2], unknown=True, direction=None),))
    capture = estimate_lights(capture, [fitted("m0", (0, 0, -1)), fitted("m1", (0.5, 0, -0.8)),
                                        fitted("m2", (0.5, 0, -0.8))]) if False else capture
    rng = np.random.default_rng(0)
    texels = np.repeat(np.arange(400), 3)
    photo = np.tile([0, 1, 2], 400)  # m0 (top), m1 and m2 (side)
    albedo = rng.uniform(0.2, 0.8, 400)
    wrong = {"top": 1.6, "side": 0.8}  # the estimated intensity is this many times the true one
    light_of = {0: "top", 1: "side", 2: "side"}
    r = albedo[texels] / np.array([wrong[light_of[k]] for k in photo]) * rng.lognormal(0, 0.05, len(photo))
    r[::17] *= 5.0  # highlights
    cosines = np.full(len(photo), 0.8)
    cosines[::23] = 0.1  # grazing: left out
    unit = np.stack([np.zeros_like(cosines), np.sqrt(1 - cosines ** 2), cosines], axis=1).astype(np.float32)
    samples = ReflectanceSamples(unit, unit, np.repeat(r[:, None], 3, axis=1).astype(np.float32),
                                 np.ones(len(photo), np.float32), texels.astype(np.int32), photo.astype(np.int16), 32,
                                 ("m0", "m1", "m2"))
    before = {l.name: l.intensity.mean() for l in capture.lights}
    balanced = balance_intensities(capture, samples)
    after = {l.name: l.intensity.mean() for l in balanced.lights}
    ratio = (after["top"] / after["side"]) / (before["top"] / before["side"])
    assert ratio == pytest.approx(wrong["side"] / wrong["top"], rel=0.03)
    assert np.mean([after["top"], after["side"]]) == pytest.approx(RELATIVE_IRRADIANCE)
    assert balanced.lights[2] is capture.lights[2]  # the given light stays
    assert balanced.metadata["estimated_lights"]["top"]["photographs"] == ["m0"]
