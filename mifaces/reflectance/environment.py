"""Environment lights in the texture-space stages: the light a map sends to each texel, and
a map estimated from the photographs (issue 26, ``docs/unknown_lights.md``).

A map is a latitude-longitude RGB image in the camera-placed frame of
:func:`mifaces.lights.environment.environment_emitter`, read as Mitsuba's ``envmap``
reads it: texel (row j, column i) of an H x W map lies in the direction of
u = (i + 1/2) / W, v = j / (H - 1) (Mitsuba interpolates bilinearly, the first
and last rows at the poles), with u = atan2(x, -z) / 2π, v = acos(y) / π in
the map's frame (:func:`texel_directions`).

**Transport.** For a surface point p with normal n, the map's texel j sends the
irradiance T_j L_j, T_j = V(p, ω_j) max(0, n · ω_j) Ω_j, with V the visibility of
the direction ω_j from p (ray-cast by Mitsuba on the face) and Ω_j the texel's
solid angle. A given map is first reduced to :data:`TRANSPORT_SIZE` texels
(:func:`reduced_map`): each reduced texel carries its block's mean radiance and
its block's radiance-weighted mean direction, so a sun keeps its direction.

**Samples.** The reflectance stage reads a texel lit by the map as lit by one
directional light (:func:`equivalent_lights`): the irradiance E = Σ_j T_j L_j,
from the direction of the irradiance vector Σ_j T_j lum(L_j) ω_j. That is exact
for the diffuse term and approximate for the specular one; the refinement
(:mod:`mifaces.refine.reflectance`) renders the full map and corrects it.

**Estimation** (:func:`estimate_map`). Under a map L, a texel i of albedo ρ_i in
photograph k reads R_ki = ρ_i / π Σ_j T_kij L_j (Lambertian). With several
photographs of one face (head turns, shared albedo) this is bilinear in ρ and L;
it is solved by alternating least squares, L non-negative with a smoothness
prior λ ‖∇L‖² over the map's neighbours (:data:`SMOOTHNESS`, relative to the
data term's scale), the photographs' brightest texels (highlights) down-weighted
by a robust (Huber) weight. The scale of L against ρ cannot be measured: L is
scaled so that the largest unoccluded irradiance over all normals is
:data:`~mifaces.capture.types.RELATIVE_IRRADIANCE` (as an estimated directional
light's).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..capture.types import RELATIVE_IRRADIANCE
from ..lights.environment import LUMINANCE, peak_irradiance, texel_directions, to_world
from ..report.population import MAD_SCALE

#: (width, height) of the map a given one is reduced to for the texture-space stages.
TRANSPORT_SIZE = (32, 16)
#: Weight of the estimated map's smoothness prior, relative to the data term's mean diagonal.
SMOOTHNESS = 0.02
#: Rounds of the alternating least squares of :func:`estimate_map`.
ROUNDS = 25
#: Residuals beyond this many robust standard deviations get a Huber weight.
HUBER = 2.0


def reduced_map(envmap: np.ndarray, size=TRANSPORT_SIZE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``envmap`` (H, 2H, 3) reduced to ``size`` (width, height) blocks: per block its direction
    (map frame, the radiance-weighted mean of its texels', the solid-angle mean where dark), its
    mean radiance (3,) and its solid angle, each (J, ...) row by row."""
    envmap = np.asarray(envmap, np.float64)
    height, width = envmap.shape[:2]
    w, h = size
    d, solid = texel_directions(width, height)
    block = (((np.arange(height) * h) // height)[:, None] * w + ((np.arange(width) * w) // width)[None, :]).ravel()
    radiance = envmap.reshape(-1, 3)
    count = w * h
    omega = np.bincount(block, solid, count)
    power = radiance * solid[:, None]
    mean = np.stack([np.bincount(block, power[:, c], count) for c in range(3)], axis=1) / np.maximum(omega, 1e-30)[:, None]
    weight = power @ LUMINANCE
    bright = np.stack([np.bincount(block, weight * d[:, c], count) for c in range(3)], axis=1)
    plain = np.stack([np.bincount(block, solid * d[:, c], count) for c in range(3)], axis=1)
    lit = np.bincount(block, weight, count) > 1e-12 * max(float(weight.sum()), 1e-30)
    direction = np.where(lit[:, None], bright, plain)
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-30)
    return direction, mean, omega


def _pairs(n: int, j: int):
    index = dr.arange(mi.UInt32, n * j)
    return index // j, index % j


def _rays(scene, position, normal, directions, offset: float, maxt: float):
    """Dr.Jit arrays of every (texel, direction) pair: the texel index, the direction index, the
    cosine and whether the ray from the texel (pushed ``offset`` along its normal) escapes."""
    n, j = len(position), len(directions)
    ti, di = _pairs(n, j)
    p = dr.gather(mi.Point3f, mi.Point3f(np.asarray(position, np.float32).T), ti)
    nn = dr.gather(mi.Vector3f, mi.Vector3f(np.asarray(normal, np.float32).T), ti)
    w = dr.gather(mi.Vector3f, mi.Vector3f(np.asarray(directions, np.float32).T), di)
    cos = dr.dot(nn, w)
    # opaque: each face has its own offset and ray length, and the kernel is compiled once
    ray = mi.Ray3f(p + dr.opaque(mi.Float, offset) * nn, w)
    ray.maxt = dr.opaque(mi.Float, maxt)
    escapes = (cos > 0) & ~scene.ray_test(ray, cos > 0)
    return ti, di, dr.select(escapes, cos, 0.0)


def shadowed_irradiance(scene, position, normal, directions, radiance, solid, offset: float, maxt: float,
                        chunk: int = 1 << 22) -> tuple[np.ndarray, np.ndarray]:
    """The irradiance (N, 3) the map's texels (world ``directions`` (J, 3), ``radiance`` (J, 3),
    ``solid`` angles (J,)) send to each surface point (``position``, ``normal``: (N, 3), world,
    mm) in ``scene``, with cast shadows, and the direction (N, 3) of each point's irradiance
    vector (luminance-weighted; zero where no light arrives). One kernel per chunk of
    ``chunk`` (point, direction) pairs: the rays are traced once and scattered into all six sums."""
    n, j = len(position), len(directions)
    weights = np.asarray(radiance, np.float64) * np.asarray(solid, np.float64)[:, None]
    lum = weights @ LUMINANCE
    out = np.zeros((n, 6))
    step = max(1, chunk // max(j, 1))
    table = mi.Float(np.concatenate([weights, lum[:, None] * np.asarray(directions, np.float64)], axis=1)
                     .astype(np.float32).ravel())
    for start in range(0, n, step):
        stop = min(n, start + step)
        ti, di, t = _rays(scene, position[start:stop], normal[start:stop], directions, offset, maxt)
        sums = [dr.zeros(mi.Float, stop - start) for _ in range(6)]
        for k, acc in enumerate(sums):
            dr.scatter_reduce(dr.ReduceOp.Add, acc, t * dr.gather(mi.Float, table, di * 6 + k), ti)
        dr.eval(sums)
        out[start:stop] = np.stack([np.array(acc, np.float64) for acc in sums], axis=1)
    return out[:, :3], out[:, 3:]


def transport(scene, position, normal, directions, solid, offset: float, maxt: float) -> np.ndarray:
    """The transport matrix T (N, J): T_ij = V(p_i, ω_j) max(0, n_i · ω_j) Ω_j (module docstring)."""
    n, j = len(position), len(directions)
    if n == 0:
        return np.zeros((0, j), np.float32)
    _, _, t = _rays(scene, position, normal, directions, offset, maxt)
    return (np.array(t, np.float32).reshape(n, j) * np.asarray(solid, np.float32)[None, :])


def equivalent_lights(scene, position, normal, envmap: np.ndarray, camera, offset: float,
                      maxt: float) -> tuple[np.ndarray, np.ndarray]:
    """Per surface point, the directional light that stands for ``envmap`` there (module
    docstring): world directions (N, 3) towards it (zero where nothing lights the point) and
    irradiance E (N, 3) it gives the point (E = irradiance at normal incidence x cos)."""
    direction, radiance, solid = reduced_map(envmap)
    e, vector = shadowed_irradiance(scene, position, normal, to_world(direction, camera), radiance, solid, offset,
                                    maxt)
    length = np.linalg.norm(vector, axis=1, keepdims=True)
    return np.where(length > 0, vector / np.maximum(length, 1e-30), 0.0), e


def neighbour_pairs(width: int, height: int) -> np.ndarray:
    """Index pairs (P, 2) of a ``width`` x ``height`` map's texels (row by row) that the smoothness
    priors compare: each texel and its right neighbour (wrapping round in azimuth), and each texel
    and the one below."""
    index = np.arange(width * height).reshape(height, width)
    return np.concatenate([np.stack([index.ravel(), np.roll(index, -1, axis=1).ravel()], 1),
                           np.stack([index[:-1].ravel(), index[1:].ravel()], 1)])


def _neighbours(width: int, height: int) -> np.ndarray:
    """The smoothness prior's difference operator G (P, J) over :func:`neighbour_pairs`."""
    pairs = neighbour_pairs(width, height)
    g = np.zeros((len(pairs), width * height))
    g[np.arange(len(pairs)), pairs[:, 0]] = 1.0
    g[np.arange(len(pairs)), pairs[:, 1]] = -1.0
    return g


def _nonnegative_solve(lhs: np.ndarray, rhs: np.ndarray, start: np.ndarray, sweeps: int = 30) -> np.ndarray:
    """argmin_x≥0 of x^T lhs x / 2 - rhs^T x (``lhs`` symmetric positive definite): the unconstrained
    solution where it is non-negative, else projected coordinate descent from ``start`` clipped."""
    x = np.linalg.solve(lhs, rhs)
    if x.min() >= 0:
        return x
    x = np.clip(start, 0, None).astype(np.float64)
    diag = np.diag(lhs)
    grad = lhs @ x - rhs
    for _ in range(sweeps):
        for i in range(len(x)):
            new = max(0.0, x[i] - grad[i] / diag[i])
            if new != x[i]:
                grad += lhs[:, i] * (new - x[i])
                x[i] = new
    return x


def estimate_map(radiance: list[np.ndarray], transports: list[np.ndarray], texels: list[np.ndarray],
                 size: tuple[int, int], smoothness: float = SMOOTHNESS,
                 rounds: int = ROUNDS) -> tuple[np.ndarray, dict]:
    """An environment map (H, W, 3) that, with one albedo per texel, explains the photographs
    (module docstring).

    Parameters
    ----------
    radiance : list of (N_k, 3)
        Per photograph, the radiance at its usable texels.
    transports : list of (N_k, J)
        Their transport matrices over the ``size`` map's texels (:func:`transport`).
    texels : list of (N_k,) int
        Their texel indices (shared albedo where equal).
    size : (width, height)

    Returns
    -------
    envmap : (H, W, 3) float32, scaled so that its
        :func:`~mifaces.lights.environment.peak_irradiance` has luminance :data:`RELATIVE_IRRADIANCE`
    info : dict
        ``rounds``, ``residual`` (relative RMS of the last round), ``samples``.
    """
    width, height = size
    j = width * height
    r = np.concatenate(radiance).astype(np.float64)
    t = np.concatenate(transports).astype(np.float64)
    ids, texel = np.unique(np.concatenate(texels), return_inverse=True)
    if len(r) < j // 4 or len(ids) < 16:
        raise ValueError(f"too few usable texels ({len(r)} samples over {len(ids)} texels) to estimate a "
                         f"{width}x{height} environment map")
    g = _neighbours(width, height)
    gg = g.T @ g
    light = np.ones((j, 3))  # a uniform map to start
    weight = np.ones(len(r))
    residual = np.nan
    for _ in range(rounds):
        e = t @ light  # (M, 3) irradiance
        # albedo per texel given the light: weighted least squares over its samples
        num = np.stack([np.bincount(texel, weight * r[:, c] * e[:, c], len(ids)) for c in range(3)], 1)
        den = np.stack([np.bincount(texel, weight * e[:, c] ** 2, len(ids)) for c in range(3)], 1)
        albedo = np.where(den > 0, num / np.maximum(den, 1e-30), 0.0)  # rho / pi
        # light given the albedo: non-negative, smooth least squares per channel
        for c in range(3):
            a = t * (albedo[texel, c] * np.sqrt(weight))[:, None]
            ata = a.T @ a
            lam = smoothness * max(float(np.trace(ata)) / j, 1e-30)
            lhs = ata + lam * gg + 1e-9 * lam * np.eye(j)
            rhs = a.T @ (r[:, c] * np.sqrt(weight))
            light[:, c] = _nonnegative_solve(lhs, rhs, light[:, c])
        model = albedo[texel] * (t @ light)
        res = (r - model) @ LUMINANCE
        scale = MAD_SCALE * np.median(np.abs(res)) + 1e-12
        weight = np.minimum(1.0, HUBER * scale / np.maximum(np.abs(res), 1e-30))
        residual = float(np.sqrt(np.mean(res ** 2)) / max(float(np.sqrt(np.mean((r @ LUMINANCE) ** 2))), 1e-30))
    envmap = light.reshape(height, width, 3)
    peak = peak_irradiance(envmap) @ LUMINANCE
    envmap = envmap * (RELATIVE_IRRADIANCE / max(float(peak), 1e-30))
    return envmap.astype(np.float32), {"rounds": rounds, "residual": residual, "samples": int(len(r)),
                                       "texels": int(len(ids))}


