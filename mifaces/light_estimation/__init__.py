"""Estimating the lights nobody measured, with the face."""
