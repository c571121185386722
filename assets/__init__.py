"""``stylize3d_assets``: the data stylize3d ships, as an importable package.

This folder is the repository's ``assets/``; ``pyproject.toml`` maps it to the
package name ``stylize3d_assets`` (``[tool.setuptools.package-dir]``), so a built
wheel carries it as ``site-packages/stylize3d_assets/``:

* ``model/`` -- the trained lite checkpoint ``stylize3d_lite.safetensors`` and
  its provenance (``model/README.md``; the training logs stay in the repository);
* ``samples/`` -- sample photos (scikit-image's public-domain / CC0 images);
* ``styles/`` -- style images (``styles/README.md`` says how each was made).

Code finds these files through :mod:`stylize3d_core.resources`
(``importlib.resources``), never through paths relative to the source tree.
"""
