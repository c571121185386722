"""``python -m app.viewer``: same as ``stylize3d-viewer``."""

from . import entrypoint

entrypoint()
