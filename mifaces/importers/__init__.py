"""Readers for public face and reflectance data sets, converted at the edge to plain arrays.

- :mod:`mifaces.importers.yaleb`: the Extended Yale Face Database B (cropped).
"""
