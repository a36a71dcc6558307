"""Morphable face models (paper sections 4.1 and 4.4).

:func:`load_model` returns a :class:`MorphableModel` for ``'builtin'`` (the
ICT Face Model Light, shipped with mifaces) or for a file: the Surrey Face Model (npz or
eos ``.bin``), the Basel Face Models 2009 (``.mat``) and 2017/2019 (``.h5``),
or a model saved by :meth:`MorphableModel.save`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .basel import load_basel2009, load_basel2017
from .builtin import load_builtin
from .loaders import ModelFormatError
from .morphable import MorphableModel
from .regions import REGIONS
from .sfm import is_sfm_npz, load_eos, load_sfm_npz

__all__ = ["MorphableModel", "ModelFormatError", "REGIONS", "load_model"]


def load_model(source: str | os.PathLike | MorphableModel = "builtin", **kwargs) -> MorphableModel:
    """Load a morphable model.

    Parameters
    ----------
    source : str, path or MorphableModel
        A model is returned as it is. ``'builtin'`` for the default model that ships with mifaces
        (the ICT Face Model Light, :mod:`mifaces.model.builtin`), or a model file, recognised by its suffix and content:
        ``.npz`` (a mifaces model, or the Surrey Face Model's npz layout),
        ``.bin`` (eos, needs ``eos-py``), ``.mat`` (Basel 2009), ``.h5``
        (Basel 2017/2019).
    **kwargs
        Passed to the format's reader (e.g. ``landmarks=`` for the Basel models).

    Returns
    -------
    MorphableModel

    Examples
    --------
    >>> model = load_model("builtin")
    >>> vertices = model.shape(model.random_coefficients(1)["shape"])
    """
    if isinstance(source, MorphableModel):
        return source
    if str(source) == "builtin":
        return load_builtin(**kwargs)
    path = Path(source)
    if not path.is_file():
        raise FileNotFoundError(f"model file not found: {path} (or pass 'builtin')")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            keys = set(data.files)
        if "mifaces_model_format" in keys:
            return MorphableModel.load(path)
        if is_sfm_npz(keys):
            return load_sfm_npz(path, **kwargs)
        raise ModelFormatError(f"{path}: an npz that is neither a mifaces model (key 'mifaces_model_format') "
                               f"nor a Surrey Face Model (keys 'shape_mean', 'shape_basis', "
                               f"'shape_eigenvalues', ...); its keys: {sorted(keys)}")
    if suffix == ".bin":
        return load_eos(path, **kwargs)
    if suffix == ".mat":
        return load_basel2009(path, **kwargs)
    if suffix in (".h5", ".hdf5"):
        return load_basel2017(path, **kwargs)
    raise ValueError(f"unknown model format {suffix!r} for {path}; "
                     "expected .npz, .bin (eos), .mat (Basel 2009) or .h5 (Basel 2017/2019)")
