"""A photograph as the shape fit renders it (Blanz and Vetter 1999, sec. 4; paper sec. 4.2): the
photographs of one fit by key, and E_I's illumination model on the Dr.Jit side, as pure functions
that :class:`~mifaces.shape.energy.Energy` composes with each photograph's parameters
(:attr:`~mifaces.shape.layout.Layout.IMAGE_BLOCK`):

    I = gain * (L + c (colour - L)) + offset,   L = LUMINANCE . colour,
    colour = albedo (ambient + light max(n.l, 0) shadow) + light k_s max(r.v, 0)^16 shadow [n.l > 0],

with ``r = 2 (n.l) n - l`` the mirror direction of ``l``, a lamp's light falling off with the
square of its distance (:func:`lamp`), and a greyscale photograph compared with ``gain L + offset``.

Frame: the fit's camera space (OpenCV: x right, y down, z forward), mm; ``n``, ``l`` and ``v`` unit
vectors pointing away from the surface (towards the light, towards the viewer).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Phong exponent of the specular lobe (fixed; its strength is fitted).
PHONG_EXPONENT = 16.0
#: Rec. 601 luminance weights of the colour-contrast operator (Blanz and Vetter 1999).
LUMINANCE = (0.3, 0.59, 0.11)
#: The photographs of one fit, by key: the measurement's photograph under its directed light, the
#: other photographs of its pose under theirs (:func:`lit_key`), and its diffuse-light companion.
POINT, DIFFUSE = "point", "diffuse"


def lit_key(index: int) -> str:
    """The key of the ``index``-th photograph (0: the measurement's own) lit by a directed light."""
    return POINT if index == 0 else f"{POINT}_{index}"


def directed(key: str) -> bool:
    """Whether photograph ``key`` is lit by a directed light (with a cast shadow): all but the
    diffuse-light companion."""
    return key != DIFFUSE


def towards_light(el, az):
    """The unit direction towards a directed light at elevation ``el`` and azimuth ``az`` (Floats,
    radians), camera space: (0, 0) points at the camera, positive elevation up, positive azimuth to
    the image's right (as :func:`mifaces.shape.targets.light_direction` gives it on the host)."""
    return mi.Vector3f(dr.cos(el) * dr.sin(az), -dr.sin(el), -dr.cos(el) * dr.cos(az))


def lamp(direction, colour, distance, centre, points):
    """A lamp at its calibrated ``distance`` (mm) from the face centre ``centre`` (3 Floats, camera
    space) in the fitted ``direction``: per point of ``points`` (Vector3f), the unit direction
    towards it and its colour with the inverse-square falloff, relative to the face centre's."""
    to_light = mi.Vector3f(*centre) + distance * direction - points
    dist2 = dr.squared_norm(to_light)
    return to_light / dr.sqrt(dist2), colour * (dr.square(distance) / dist2)


def phong(albedo, normal, view, light, colour, ambient, specular, shadow):
    """The colour of a surface lit by ambient light and one directed light (Blanz and Vetter 1999,
    sec. 4): the Lambertian term of ``albedo`` under ``ambient`` and ``colour`` (its cast ``shadow``:
    0 or 1), and a Phong lobe of strength ``specular`` and exponent :data:`PHONG_EXPONENT` in the
    light's colour, for unit ``normal``, direction towards the ``view`` and towards the ``light``."""
    ndl = dr.dot(normal, light)
    refl = 2 * ndl * normal - light
    spec = specular * dr.power(dr.maximum(dr.dot(refl, view), 0.0), PHONG_EXPONENT)
    lit = shadow * dr.select(ndl > 0, 1.0, 0.0)
    return albedo * (ambient + colour * dr.maximum(ndl, 0.0) * shadow) + colour * spec * lit


def response(colour, contrast, gain, offset, greyscale: bool = False):
    """The photograph's value of a rendered ``colour`` (Blanz and Vetter 1999, sec. 4): its colour
    contrast ``contrast`` about its luminance (:data:`LUMINANCE`), then ``gain`` and ``offset`` per
    channel. A ``greyscale`` photograph's grey value is the luminance under channel 0's gain and
    offset (the contrast plays no part)."""
    lum = LUMINANCE[0] * colour.x + LUMINANCE[1] * colour.y + LUMINANCE[2] * colour.z
    if greyscale:
        return mi.Color3f(gain.x * lum + offset.x)
    colour = lum + contrast * (colour - lum)
    return gain * colour + offset
