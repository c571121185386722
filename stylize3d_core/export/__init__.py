"""What a 3D photo becomes besides a plain video: files for other tools and ways of rendering it.

=======================  ==============================================================
module                   what
=======================  ==============================================================
``settings.py``          :class:`ExportSettings`: the ``--export``, ``--eye-distance``,
                         ``--loop`` ... options of a render job
``splat.py``             3D Gaussian splat ``.ply`` (positions, isotropic scales from each
                         point's footprint, opacity, degree-0 SH colour); read back
``bake.py``              colours of rendered (stylized) views baked onto the points
``stereo.py``            two eyes per camera: side-by-side (full, half) and red-cyan anaglyph
``loop.py``              boomerang loops (forward, then back)
``frames.py``            write frames by suffix: MP4 / GIF / PNG (``io.video``) and animated WebP
``camera_paths.py``      camera paths by format: stylize3d JSON or Open3D PinholeCameraTrajectory
``layered.py``           layered stylization: a foreground mask keeps its colours
=======================  ==============================================================

This package imports nothing at import time; import the modules.
"""
