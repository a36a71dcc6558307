"""The poses of a capture (paper sec. 4.2): measurements that share a ``pose`` label are one
unmoved head under several lights, fitted once (:func:`~mifaces.shape.fit.fit_shape`). Here: how
measurements are grouped into poses, which photographs of a pose are fitted together with its
leader, and the fits the pose's other measurements get from the leader's."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..capture.camera import relative_pose
from .shading import DIFFUSE, POINT
from .result import ShapeFit
from .targets import FRONTAL, light_direction, reference_measurement, start_light_angles

#: Feature points of measurements labelled with one pose that differ from the pose's fitted
#: measurement's by more than this fraction of their spread (RMS) are not one pose: fitted apart.
POSE_AGREEMENT = 0.25
#: The most photographs of one pose fitted jointly (the leader and its companions,
#: :func:`~mifaces.shape.fit.fit_measurement`'s ``companions``): each adds its own light, and its share of E_I's cost.
JOINT_PHOTOGRAPHS = 8


def pose_groups(capture, measurements) -> list[list]:
    """``measurements`` grouped by their ``pose`` label, each group led by the measurement its
    shared fit is made on (:func:`~mifaces.shape.targets.reference_measurement` among those of the
    first camera that took the pose); unlabelled measurements, and labelled ones whose feature
    points disagree with the leader's (:data:`POSE_AGREEMENT`; compared within one camera: a shot's
    other cameras see the face elsewhere), are groups of their own."""
    labelled: dict[str, list] = {}
    groups = []
    for m in measurements:
        if m.pose is None:
            groups.append([m])
        else:
            labelled.setdefault(m.pose, []).append(m)
    for pose, members in labelled.items():
        first = [m for m in members if m.camera == members[0].camera]
        leader = next(m for m in first if m.name == reference_measurement(capture, first))
        group = [leader]
        for m in members:
            if m is leader:
                continue
            if m.camera != leader.camera or points_agree(leader.feature_points, m.feature_points):
                group.append(m)
            else:
                warnings.warn(f"measurement {m.name!r} is labelled pose {pose!r} but its feature points differ "
                              f"from {leader.name!r}'s: fitted on its own", stacklevel=3)
                groups.append([m])
        groups.append(group)
    order = {m.name: i for i, m in enumerate(measurements)}
    return sorted(groups, key=lambda g: min(order[m.name] for m in g))


def points_agree(a: dict, b: dict) -> bool:
    """Feature points ``b`` within :data:`POSE_AGREEMENT` of the spread of ``a`` (RMS over the names
    both have); too few shared names do not agree."""
    names = [n for n in a if n in b]
    if len(names) < 3:
        return False
    pa = np.array([np.asarray(a[n], np.float64) for n in names])
    pb = np.array([np.asarray(b[n], np.float64) for n in names])
    spread = np.sqrt(np.mean(np.sum((pa - pa.mean(0)) ** 2, axis=1)))
    return float(np.sqrt(np.mean(np.sum((pa - pb) ** 2, axis=1)))) <= POSE_AGREEMENT * spread


def companions(capture, others, leader=None) -> list:
    """The photographs of a pose fitted with its ``leader``: every one another camera took (the
    shot's views, which fix the face's depth), then those whose light the capture gives (an unknown
    light is fitted afterwards on the pose's face, :func:`~mifaces.shape.fit.fit_light`),
    :data:`JOINT_PHOTOGRAPHS` at most with the leader, in the capture's order, each with its light
    and its camera (:meth:`~mifaces.capture.Capture.camera_of`): ``(measurement, light, camera)``."""
    camera = None if leader is None else leader.camera
    given = [(m, capture.light(m.light) if m.light else None, capture.camera_of(m)) for m in others]
    views = [photograph for photograph in given if camera is not None and photograph[0].camera != camera]
    seen = {m.name for m, *_ in views}
    lit = [(m, light, view) for m, light, view in given
           if m.name not in seen and (light is None or not light.direction_fitted)]
    return (views + lit)[:JOINT_PHOTOGRAPHS - 1]


def seen_by(fit: ShapeFit, source, target) -> ShapeFit:
    """``fit``, made in camera ``source``'s frame, in camera ``target``'s: its camera-space
    vertices, pose and light directions (the world-frame vertices are the same)."""
    A, b = relative_pose(source, target)
    rotation = A @ fit.rotation
    light = {key: dict(values, direction=A @ np.asarray(values["direction"], np.float64)) if "direction" in values
             else values for key, values in (fit.light or {}).items()}
    turn = Rotation.from_matrix(FRONTAL.T @ rotation).as_euler("YXZ", degrees=True)  # R_y R_x R_z
    return replace(fit, vertices_camera=(fit.vertices_camera @ A.T + b).astype(np.float32), rotation=rotation,
                   translation=A @ fit.translation + b, yaw_pitch_roll=turn, light=light,
                   focal_length=np.array([target.fx, target.fy], np.float64))


def own_lights(fit: ShapeFit) -> ShapeFit:
    """``fit`` with only its own photographs' lights (a joint fit also holds its companions')."""
    own = {key: light for key, light in (fit.light or {}).items() if key in (POINT, DIFFUSE)}
    return replace(fit, light=own)


def shared_fit(fit: ShapeFit, measurement, capture, key: str | None = None) -> ShapeFit:
    """The fit of ``measurement`` that shares ``fit``'s geometry, pose and texture (same pose),
    0 iterations, 0 seconds. Its light is the one fitted for it where ``measurement`` was the
    joint fit's photograph ``key`` (:func:`~mifaces.shape.shading.lit_key`); otherwise only the
    capture's light direction, in camera space, where known."""
    light = {}
    fitted = (fit.light or {}).get(key) if key else None
    if fitted is not None:
        light[POINT] = fitted
    else:
        source = capture.light(measurement.light) if measurement.light else None
        head = fit.vertices_world.mean(axis=0)
        angles = start_light_angles(source, capture.camera_of(fit.measurement), head) if np.all(np.isfinite(head)) else None
        if angles is not None:
            light[POINT] = {"direction": light_direction(*angles)}
    joint = f"fitted jointly with {fit.measurement!r}" if fitted is not None else f"geometry of {fit.measurement!r}"
    return replace(fit, measurement=measurement.name, light=light, iterations=0, seconds=0.0, history=[],
                   shared_with=fit.measurement,
                   message=f"{joint} (same pose)" + (f"; {fit.message}" if fit.message else ""))


def one_face(fits: list[ShapeFit]) -> np.ndarray | None:
    """The identity of the face all ``fits`` show: the mean of the converged fits' shape
    coefficients (each photograph's fit is an estimate of the same face), None without two
    converged fits."""
    done = [f.coefficients for f in fits if f.converged]
    return np.mean(done, axis=0) if len(done) >= 2 else None
