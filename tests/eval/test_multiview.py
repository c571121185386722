"""Merged views render a held-out pose of a procedural scene better than any single view does."""

import numpy as np
import pytest

from stylize3d_core.eval.multiview import _held_out_camera, held_out_psnr, observed_mask, procedural_views
from stylize3d_core.render.plain import PlainRenderer
from stylize3d_core.scene.multiview import merge_views


@pytest.mark.parametrize("seed", [3, 5])
def test_merged_cloud_beats_every_single_view(seed):
    # Scored where some input view saw the scene: the rest of the held-out image (below every input frame,
    # 12-19 % here) shows only invented border, which merging cannot inform (see eval/multiview.py).
    data = procedural_views(seed)
    assert observed_mask(data).mean() > 0.75
    scores = held_out_psnr(data, observed_only=True)
    singles = [v for k, v in scores.items() if k != "merged"]
    assert len(singles) == 3
    assert scores["merged"] > max(singles) + 0.2, scores


@pytest.mark.parametrize("seed", [3, 5])
def test_merged_cloud_covers_the_held_out_view(seed):
    # Every view's border is kept where no view saw better: the held-out pose sees past the centre view's
    # border, and the merge once left 957 of its pixels (seed 5) to the hole filling.
    data = procedural_views(seed)
    h, w = data.held_out_rgb.shape[:2]
    merged = merge_views(data.views, 0).photo
    holes = PlainRenderer(merged.points).rasterize(_held_out_camera(data, data.views[0], merged), h, w).hole
    assert float(holes.float().mean()) < 0.005
    assert np.isfinite(held_out_psnr(data)["merged"])
