"""Benchmarks and numerical stress cases behind ``stylize3d bench`` (speed, skips, targets, floor, consistency,
scaling, stress, quality).

Modules import the heavy parts (the model, the 2D baseline) inside the functions
that need them. Tables are written as Markdown and JSON, plots as PNG (drawn
with OpenCV, no plotting dependency), all through ``io.atomic``.
"""
