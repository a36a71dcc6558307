"""The DiLiGenT photometric stereo benchmark: one object under 96 calibrated directional lights.

Shi, Mo, Wu, Tai, Ikeuchi, Matsushita, "A benchmark dataset and evaluation
for non-Lambertian and uncalibrated photometric stereo", CVPR 2016 / TPAMI
41(2), 2019. An object's folder holds ``001.png`` ... ``096.png`` (16-bit
RGB, linear), ``filenames.txt`` (the image of each light, in order),
``light_directions.txt`` (K x 3 unit vectors towards the lights),
``light_intensities.txt`` (K x 3 RGB intensities), ``mask.png`` (the
object's pixels) and ``normal_gt.npy`` (the ground-truth normals).

Frame of the directions and normals: x right, y up, z towards the camera
(orthographic, looking along -z), as the benchmark gives them; the viewer is
(0, 0, 1) at every pixel. Row 0 of an image is its top (largest y).

:func:`read_object` never reads the ground truth: :func:`read_normals` does,
for the scores only. :func:`light_split` is the fixed split of the lights
into a training and a held-out half; :func:`import_object`
(``mifaces import diligent``) writes the converted object as ``diligent.npz``
with ``split.json``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.image_files import read_codes
from ..io.atomic import atomic_write, write_json

#: The viewer's direction, at every pixel (orthographic camera).
VIEW = (0.0, 0.0, 1.0)
#: File an import writes: the converted images, lights and mask.
ARCHIVE = "diligent.npz"
#: File an import writes: the training and held-out lights.
SPLIT = "split.json"
#: How :func:`light_split` splits the lights, in words (written to ``split.json``).
SPLIT_RULE = "train: even 0-based indices (001.png, 003.png, ...); heldout: odd indices (002.png, 004.png, ...)"


@dataclass(frozen=True, eq=False)
class DiligentObject:
    """One DiLiGenT object, its images per unit light intensity.

    Attributes
    ----------
    name : str
        The folder's name.
    images : ndarray (K, H, W, 3) float32
        Linear values (16-bit code / 65535) divided by each light's RGB intensity.
    saturated : ndarray (K, H, W) bool
        Pixels where a channel is at the largest code.
    directions : ndarray (K, 3) float64
        Unit directions towards the lights (x right, y up, z towards the camera).
    intensities : ndarray (K, 3) float64
        The lights' RGB intensities the images were divided by.
    mask : ndarray (H, W) bool
        The object's pixels.
    filenames : list of str
        The image of each light.
    """

    name: str
    images: np.ndarray
    saturated: np.ndarray
    directions: np.ndarray
    intensities: np.ndarray
    mask: np.ndarray
    filenames: list

    def select(self, lights) -> DiligentObject:
        """The object under the lights of index ``lights`` only."""
        lights = np.asarray(lights, int)
        return DiligentObject(self.name, self.images[lights], self.saturated[lights], self.directions[lights],
                              self.intensities[lights], self.mask, [self.filenames[i] for i in lights])


def _codes(path: Path) -> np.ndarray:
    codes = read_codes(path)
    if codes.dtype != np.uint16:
        raise ValueError(f"{path.name}: expected a 16-bit image, got {codes.dtype}")
    return codes


def read_object(object_dir: str | os.PathLike) -> DiligentObject:
    """Read a DiLiGenT object folder (not its ground-truth normals).

    Raises
    ------
    FileNotFoundError
        For a folder without ``filenames.txt`` and the light files.
    ValueError
        Where the files disagree (counts, shapes, non-unit directions).
    """
    folder = Path(object_dir)
    missing = [n for n in ("filenames.txt", "light_directions.txt", "light_intensities.txt", "mask.png")
               if not (folder / n).is_file()]
    if missing:
        raise FileNotFoundError(f"{folder} is not a DiLiGenT object folder: no {', '.join(missing)}")
    filenames = (folder / "filenames.txt").read_text().split()
    directions = np.loadtxt(folder / "light_directions.txt", ndmin=2)
    intensities = np.loadtxt(folder / "light_intensities.txt", ndmin=2)
    k = len(filenames)
    for name, a in (("light_directions.txt", directions), ("light_intensities.txt", intensities)):
        if a.shape != (k, 3):
            raise ValueError(f"{name} must have {k} rows of 3 (one per image of filenames.txt), got {a.shape}")
    if np.abs(np.linalg.norm(directions, axis=1) - 1.0).max() > 1e-3 or np.any(intensities <= 0):
        raise ValueError("light_directions.txt must hold unit vectors and light_intensities.txt positive values")
    codes = np.stack([_codes(folder / n) for n in filenames])
    if codes.ndim != 4 or codes.shape[3] != 3:
        raise ValueError(f"the images must be RGB, got shape {codes.shape[1:]}")
    mask_codes = read_codes(folder / "mask.png")
    mask = (mask_codes if mask_codes.ndim == 2 else mask_codes[..., 0]) > np.iinfo(mask_codes.dtype).max // 2
    if mask.shape != codes.shape[1:3]:
        raise ValueError(f"mask.png is {mask.shape}, the images {codes.shape[1:3]}")
    top = np.iinfo(np.uint16).max
    images = codes.astype(np.float32) / np.float32(top) / intensities[:, None, None, :].astype(np.float32)
    return DiligentObject(name=folder.name, images=images, saturated=np.any(codes >= top, axis=3),
                          directions=directions, intensities=intensities, mask=mask, filenames=filenames)


def read_normals(object_dir: str | os.PathLike) -> np.ndarray:
    """The ground-truth normals (H, W, 3) float32, for scoring only (same frame as the lights)."""
    return np.load(Path(object_dir) / "normal_gt.npy").astype(np.float32)


def light_split(count: int) -> tuple[np.ndarray, np.ndarray]:
    """The fixed split of ``count`` lights: training = even indices, held out = odd (:data:`SPLIT_RULE`).

    DiLiGenT's lights lie on a grid ordered row by row, so alternate indices
    spread both halves over all the directions.
    """
    index = np.arange(count)
    return index[0::2], index[1::2]


def import_object(object_dir: str | os.PathLike, out: str | os.PathLike, force: bool = False) -> Path:
    """Write a DiLiGenT object, converted, as ``out/diligent.npz`` and ``out/split.json``.

    ``diligent.npz`` holds ``images`` (K, H, W, 3) float32 per unit light
    intensity, ``saturated`` (K, H, W), ``directions`` and ``intensities``
    (K, 3), ``mask`` (H, W), ``filenames`` and ``view`` (:data:`VIEW`), all in
    the frame of the module docstring; :func:`load_imported` reads it back.
    ``split.json``: ``{"rule", "train": [filenames], "heldout": [filenames],
    "train_index", "heldout_index"}`` (0-based), from :func:`light_split`.
    The ground-truth normals are not copied.

    Raises
    ------
    FileExistsError
        Where ``out`` holds an import already and ``force`` is False.
    """
    out = Path(out)
    if (out / ARCHIVE).exists() and not force:
        raise FileExistsError(f"{out} holds an import already ({ARCHIVE}); use force=True (--force) to replace it")
    obj = read_object(object_dir)
    train, heldout = light_split(len(obj.filenames))
    with atomic_write(out / ARCHIVE) as f:
        np.savez_compressed(f, images=obj.images, saturated=obj.saturated, directions=obj.directions,
                            intensities=obj.intensities, mask=obj.mask, filenames=np.array(obj.filenames),
                            view=np.array(VIEW), name=np.array(obj.name))
    write_json(out / SPLIT, {"rule": SPLIT_RULE, "train": [obj.filenames[i] for i in train],
                             "heldout": [obj.filenames[i] for i in heldout],
                             "train_index": train.tolist(), "heldout_index": heldout.tolist()})
    return out


def load_imported(out: str | os.PathLike) -> DiligentObject:
    """The object :func:`import_object` wrote to ``out``."""
    with np.load(Path(out) / ARCHIVE) as data:
        return DiligentObject(name=str(data["name"]), images=data["images"], saturated=data["saturated"],
                              directions=data["directions"], intensities=data["intensities"], mask=data["mask"],
                              filenames=[str(n) for n in data["filenames"]])
