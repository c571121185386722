"""``python -m stylize3d``: the ``stylize3d`` command line as a module (same as the console script).

The library is :mod:`stylize3d_core`; this package only holds the module entry
point, so ``python -m stylize3d render ...`` works wherever the distribution is
installed, without relying on the console script being on ``PATH``.
"""

from stylize3d_core import __version__

__all__ = ["__version__"]
