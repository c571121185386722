"""``python -m stylize3d ...``: runs the ``stylize3d`` command line (``app.cli``)."""

from app.cli import entrypoint

if __name__ == "__main__":
    entrypoint()
