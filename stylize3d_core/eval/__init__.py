"""Evaluation (paper Sec. 4.2): multi-view consistency, the 2D baseline, view synthesis; benchmark timing."""

from .baseline import baseline_frames, stylize_frames_2d
from .consistency import (
    ConsistencyResult,
    ConsistencySettings,
    consistency_metrics,
    long_range_pairs,
    short_range_pairs,
    view_geometry,
    warp_view,
)
from .view_synthesis import (
    KindScores,
    ViewSynthesisResult,
    evaluate_view_synthesis,
    masked_psnr,
    masked_ssim,
    score_views,
    ssim_map,
)

__all__ = [
    "ConsistencyResult", "ConsistencySettings", "KindScores", "ViewSynthesisResult", "baseline_frames",
    "consistency_metrics", "evaluate_view_synthesis", "long_range_pairs", "masked_psnr", "masked_ssim",
    "score_views", "short_range_pairs", "ssim_map", "stylize_frames_2d", "view_geometry", "warp_view",
]
