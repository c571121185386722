"""Rendering: the z-buffered point rasterizer and hole filling."""

from .holes import fill_holes
from .rasterize import Fragments, RasterSettings, rasterize_points
from .rasterizer import PointRasterizer

__all__ = ["Fragments", "PointRasterizer", "RasterSettings", "fill_holes", "rasterize_points"]
