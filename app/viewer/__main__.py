"""``python -m stylize3d_app.viewer``: same as ``stylize3d-viewer``."""

from . import entrypoint

entrypoint()
