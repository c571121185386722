"""Layered depth image (LDI): the photo's surface torn at depth edges, plus hidden background.

Stage 3 of the pipeline (docs/architecture.md, "Pipeline stages"), after 3DPhoto (Shih et al. 2020):

1. **Scene units.** The depth is multiplied by ``depth_scale`` so that its 1st
   percentile equals :data:`~stylize3d_core.geometry.camera.NEAR_DEPTH` (1/3).
   Edges are then found on the *normalised disparity* ``nd = NEAR_DEPTH / depth``,
   i.e. the disparity divided by its robust maximum (its 99th percentile): the
   near surface has ``nd`` = 1, as 3DPhoto's disparity normalised by its maximum.
2. **Pre-filter.** A 5-point ("+"-shaped) median on ``nd`` removes single-pixel
   speckle but keeps corners and 2-pixel-wide structures (a 3x3 median would
   round off every corner).
3. **Discontinuities.** Two 4-neighbours whose ``nd`` differs by more than
   ``disparity_jump`` are torn apart: the nearer one is a *foreground-edge*
   pixel, the farther one a *background-edge* pixel. Tiny regions enclosed by
   tears (fewer pixels than the island threshold) are flattened: their depth
   becomes the farthest depth found just outside them, so nothing floats. Edge
   components with fewer foreground-edge pixels than the minimum length are
   then ignored (no tear, no hidden layer).
4. **Coverage.** How much hidden background each edge can show is measured,
   not assumed: for every foreground-edge pixel (front depth, and the farthest
   depth within 3 px behind it) the parallax ``|uv'(front) - uv'(back)|`` is
   computed for the extreme cameras of ``camera_range`` (the viewer's range)
   and of the default trajectories (``geometry/camera_range.py``); for a
   sideways move ``b`` it is ``b f |1/z_near - 1/z_far|``. The edge's hidden
   layer is that wide plus a margin, capped at ``max_band``, and absent where
   the parallax is under a pixel. The border is as wide as those cameras see
   beyond the frame (at the depths found along each side), capped at
   ``max_border``. Where the caps bind, the range is scaled down until it fits
   and the LDI reports the covered fraction (``range_scale``, ``camera_range``).
5. **Hidden layer.** Foreground pixels within their nearest edge's width of it
   that are in front of their local background (``nd`` minus its min-filter
   over that radius > ``disparity_jump``) and not clearly behind that edge get a
   second, hidden sample. Its depth and colour come from *background sources
   only*: pixels near the edge, outside the band, farther than their nearest
   foreground edge by more than the jump, and more than ``edge_exclusion_px``
   from any tear (the pixels at a tear mix foreground and background colours).
   Depth and colour (``hidden_depth="surface"``):
   the local linear fit of ``nd`` (affine on a plane) and of the colour at a
   source, anchored at the source's own value where the fit explains its
   neighbourhood, continued to the pixel (steps capped at one jump and at
   ``max_colour_step``, the colour gradient damped on noise-like texture): from
   the nearest source, or, where the sources on opposite sides of the pixel
   along its row or column continue to the same surface and that surface is not
   the nearest source's, the inverse-squared-distance blend of the sources on
   it (the ground behind a card that hides the ground / wall crease). Those
   pixels, and the others between the same two sources, take their colour
   where the texture's isophotes through them meet the gap's two sides (the
   sides' profiles matched for the shift an isophote makes across the gap), not
   straight along the row or column. The depth
   is then smoothed by a small normalised convolution and
   clamped to lie behind the foreground by at least ``disparity_jump``; the
   colour, background-only, never takes a foreground pixel's, so no foreground
   colour can bleed in. **Layer 0 keeps the photo's colour and depth** (the photo
   seen from its own camera stays the photo) **but on the silhouettes' background
   side** (``unmix_silhouettes``): a pixel just outside a foreground edge the
   hidden layer covers holds the anti-aliased mix of the foreground's colour and
   the background's, which, left at the background's depth, stays behind as a
   ghost outline when the foreground moves. It loses the foreground's share (its
   colour's projection on foreground minus background, the background continued
   from the sources like the hidden layer's, the foreground the pixel two steps
   across the tear), where it is such a mix; a pixel that is mostly foreground
   across a colour edge (the depth's edge inside the colour's) joins the
   foreground instead, with its colour, and the hidden layer gets the background
   behind it. Only padded boxes around clusters of
   edges are processed, and the fits are solved only at the sources some band
   pixel continues (its nearest, and its nearest along its row and column: a
   thin rim of the sources), where few, by summing their Gaussian windows
   directly rather than blurring the box. With no edge the step is skipped
   (``LDI.inpainted`` is False).
6. **Border.** The canvas is extended by ``pad`` pixels on every side (step 4).
   Colour: push-pull continuation of the photo (blur grows with the distance
   from the photo, no mirrored seams). Depth: the push-pull continuation of
   ``nd``, never closer than the replicated photo-border pixel. Where a
   foreground edge comes within ``pad`` of the frame, border pixels whose layer 0 continues a foreground cut by the
   frame's edge get a hidden sample: the photo's background alone continued
   the same way.

Coordinates: canvas pixel ``(i, j)`` is photo pixel ``(i - pad, j - pad)``.

The package: :mod:`.layers` (the labels, :class:`LDISettings`, :class:`LDI`), :mod:`.build`
(:func:`build_ldi`, the coverage of each edge), :mod:`.tear` (the depth edges), :mod:`.hidden` (the
hidden layer's depth and colour), :mod:`.silhouettes` (mixed pixels at the foreground's outline) and
:mod:`.border` (the photo extended beyond its frame), :mod:`.isophotes` (colour matched across a gap).
"""

from .build import build_ldi
from .layers import BORDER, INPAINTED, LDI, MIN_PHOTO_SIDE, ORIGINAL, LDISettings
from .silhouettes import subpixel_edges, unmix_silhouette

__all__ = ["BORDER", "INPAINTED", "LDI", "LDISettings", "MIN_PHOTO_SIDE", "ORIGINAL", "build_ldi", "subpixel_edges",
           "unmix_silhouette"]
