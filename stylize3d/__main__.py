"""``python -m stylize3d ...``: runs the ``stylize3d`` command line (``app.entry``, then ``app.cli``)."""

from app.entry import entrypoint  # signal-safe: SIGINT during the imports is one line, exit 130

if __name__ == "__main__":
    entrypoint()
