"""Results kept by the content of their inputs (mifaces.runtime.memo) and the functions that keep them:
the texture-space rasterization and the pixel footprints."""

from __future__ import annotations

import mifaces  # first: it points Dr.Jit at a working libLLVM  # isort: skip

import numpy as np
import pytest

from mifaces.model.texture_space import _rasterize, rasterize
from mifaces.reflectance.footprint import _normal_spread, normal_spread
from mifaces.runtime.memo import ContentCache


def test_a_content_cache_keys_by_content_and_forgets_the_oldest():
    cache, calls = ContentCache(2), []

    def compute(x):
        calls.append(x)
        return np.full(3, x, np.float64)

    a = np.arange(4.0)
    first = cache.get((a, 1), lambda: compute(1))
    assert cache.get((a.copy(), 1), lambda: compute(99)) is first  # equal content, another object
    assert not first.flags.writeable
    assert cache.get((a, 2), lambda: compute(2))[0] == 2  # another scalar: another key
    assert cache.get((a.astype(np.float32), 1), lambda: compute(3))[0] == 3  # another dtype: another key
    assert cache.get((a, 1), lambda: compute(4))[0] == 4  # the oldest was forgotten (size 2)
    assert calls == [1, 2, 3, 4]
    cache.clear()
    assert cache.get((a, 1), lambda: compute(5))[0] == 5  # cleared: computed again
    assert calls == [1, 2, 3, 4, 5]
    with pytest.raises(ValueError, match="at least one"):
        ContentCache(0)


def test_rasterize_gives_the_uncached_raster_read_only():
    rng = np.random.default_rng(3)
    uv = rng.uniform(0.05, 0.95, (30, 2))
    triangles = rng.choice(30, (20, 3))
    triangles = triangles[np.array([len(set(t)) == 3 for t in triangles])]
    kept = rasterize(uv, triangles, (32, 32))
    fresh = _rasterize(uv.astype(np.float64), triangles.astype(np.int64), 32, 32, 4_000_000)
    assert rasterize(uv.copy(), triangles.copy(), (32, 32)) is kept
    for name in ("triangle", "barycentric", "count"):
        assert np.array_equal(getattr(kept, name), getattr(fresh, name))
        assert not getattr(kept, name).flags.writeable
    moved = uv.copy()
    moved[0] += 0.01
    assert rasterize(moved, triangles, (32, 32)) is not kept


def test_normal_spread_is_kept_per_photograph():
    rng = np.random.default_rng(5)
    r = 16
    texel = np.arange(r * r)
    rows, cols = np.divmod(texel, r)
    xy = np.stack([cols * 1.3, rows * 1.3], 1)
    normal = np.stack([0.02 * cols, 0.01 * rows, np.ones(r * r)], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    tangent = np.cross([0.0, 1.0, 0.0], normal)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(normal, tangent)
    spread = normal_spread(xy, normal, tangent, bitangent, texel, r)
    assert np.array_equal(spread, _normal_spread(xy, normal, tangent, bitangent, texel, r, 0.5))
    assert normal_spread(xy + 0.0, normal, tangent, bitangent, texel, r) is spread
    other = normal_spread(xy + rng.uniform(0, 0.5, xy.shape), normal, tangent, bitangent, texel, r)
    assert other is not spread and not np.array_equal(other, spread)
