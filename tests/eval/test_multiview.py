"""Merged views render a held-out pose of a procedural scene better than any single view does."""

import pytest

from stylize3d_core.eval.multiview import held_out_psnr, procedural_views


@pytest.mark.parametrize("seed", [3, 5])
def test_merged_cloud_beats_every_single_view(seed):
    scores = held_out_psnr(procedural_views(seed))
    singles = [v for k, v in scores.items() if k != "merged"]
    assert len(singles) == 3
    assert scores["merged"] > max(singles) + 0.2, scores
