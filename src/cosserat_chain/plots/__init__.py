"""Figures (matplotlib only): functions take results, and optionally an Axes, and return figures.

Plots never solve anything; one module per subject.
"""
