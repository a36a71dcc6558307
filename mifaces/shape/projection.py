"""The camera geometry of the shape fit's energy on the Dr.Jit side (:mod:`mifaces.shape.energy`):
points moved into another camera's frame, projected through a camera's lens (OpenCV's model, the
distortion :func:`mifaces.capture.camera.distorted`, the numpy camera's own), and a photograph read
bilinearly where they land."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..capture.camera import distorted


def moved(pc, A, b):
    """``A pc + b`` of points ``pc`` (3 Floats): into another camera's frame (``Energy.views``)."""
    return [float(A[i][0]) * pc[0] + float(A[i][1]) * pc[1] + float(A[i][2]) * pc[2] + float(b[i])
            for i in range(3)]


def project(pc, focal, cam):
    """Pixel coordinates of camera-space points ``pc`` (3 Floats) in camera ``cam`` (OpenCV model with
    distortion, :func:`~mifaces.capture.camera.distorted`), its focal lengths times ``focal``."""
    z = dr.maximum(pc[2], 1.0)
    x, y = pc[0] / z, pc[1] / z
    if np.any(cam.distortion):
        x, y = distorted(x, y, cam.distortion_coefficients)
    return focal * cam.fx * x + cam.cx, focal * cam.fy * y + cam.cy


def bilinear(image, u, v, cam):
    """Image (flat RGB Float, ``cam``'s size) at pixel coordinates (u, v), bilinear; returns (rgb, inside)."""
    w, h = cam.width, cam.height
    inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    uc, vc = dr.clip(u, 0, w - 1.001), dr.clip(v, 0, h - 1.001)
    x0, y0 = dr.floor(uc), dr.floor(vc)
    fx, fy = uc - x0, vc - y0
    i0 = mi.UInt32(y0) * w + mi.UInt32(x0)

    def at(i):
        return dr.gather(mi.Vector3f, image, i)

    top = at(i0) * (1 - fx) + at(i0 + 1) * fx
    bottom = at(i0 + w) * (1 - fx) + at(i0 + w + 1) * fx
    return top * (1 - fy) + bottom * fy, inside
