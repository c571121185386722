"""The export default picked by ``bench speed``: RenderJob.points_per_pixel reaches the stylized frames."""

import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.pipeline import EXPORT_POINTS_PER_PIXEL, RenderJob, _check_style_inputs
from stylize3d_core.resources import style_image


def test_export_points_per_pixel_reaches_the_stylize_settings():
    assert RenderJob().points_per_pixel == EXPORT_POINTS_PER_PIXEL == 7.0
    settings, _, _ = _check_style_inputs(RenderJob(style=str(style_image())))
    assert settings.final_points_per_pixel == EXPORT_POINTS_PER_PIXEL
    settings, _, _ = _check_style_inputs(RenderJob(style=str(style_image()), points_per_pixel=2.5, supersample=2))
    assert (settings.final_points_per_pixel, settings.supersample) == (2.5, 2)
    with pytest.raises(InputError):
        RenderJob(points_per_pixel=0.1)
