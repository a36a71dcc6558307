"""Readers of public face and reflectance data sets and of other tools' calibrations, converted at the
edge to plain arrays and captures.

- :mod:`mifaces.importers.yaleb`: the Extended Yale Face Database B (cropped).
- :mod:`mifaces.importers.diligent`: DiLiGenT objects (photometric stereo).
- :mod:`mifaces.importers.colmap`: COLMAP sparse models, text and binary: :func:`~.colmap.read_colmap`
  (cameras per image, 3D points, observations, in mifaces' conventions), :func:`~.colmap.write_colmap`;
  the files themselves in :mod:`mifaces.importers.colmap_records`.
- :mod:`mifaces.importers.transforms`: Nerfstudio / instant-ngp ``transforms.json``:
  :func:`~.transforms.read_transforms`, :func:`~.transforms.write_transforms`.
- :mod:`mifaces.importers.calibration_io`: those calibrations as captures
  (:func:`~.calibration_io.import_colmap`, :func:`~.calibration_io.import_transforms`,
  :func:`~.calibration_io.import_calibration`: one camera or several) and a capture's camera for those
  tools (:func:`~.calibration_io.export_calibration`).
- :mod:`mifaces.importers.cli`: their commands, ``mifaces import ...`` and ``mifaces export-calibration``.
"""
