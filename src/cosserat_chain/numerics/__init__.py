"""Numerical methods that act on any registered model: compiled integrators and their drivers."""
