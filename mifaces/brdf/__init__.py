"""Analytic BRDF models as pure Dr.Jit functions."""
