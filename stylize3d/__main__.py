"""``python -m stylize3d ...``: runs the ``stylize3d`` command line (``stylize3d_app.entry``, then ``stylize3d_app.cli``)."""

from stylize3d_app.entry import entrypoint  # signal-safe: SIGINT during the imports is one line, exit 130

if __name__ == "__main__":
    entrypoint()
