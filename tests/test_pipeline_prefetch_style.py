"""``pipeline.prefetch_style``: the style CNN in a worker thread while the photo loads, then a cache hit."""

import numpy as np
import pytest
import torch

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.style_features import StyleEncoder
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.pipeline import prefetch_style
from stylize3d_core.scene.photo3d import Photo3D
from stylize3d_core.stylize import Stylized3DPhoto, StylizeSettings, style_feature_cache, style_tensor


def test_prefetched_features_are_the_encoders_and_set_style_hits_them(tmp_path):
    g = np.random.default_rng(1)
    style = g.random((40, 56, 3), dtype=np.float32)
    encoder = StyleEncoder()
    fut = prefetch_style(style, encoder)
    rgb = g.random((24, 32, 3), dtype=np.float32)  # meanwhile, the photo
    photo = Photo3D.build(rgb, DepthMap(np.ones((24, 32), np.float32), np.ones((24, 32), bool), "metric", "test"))
    assert fut.result() is encoder
    cache = style_feature_cache(encoder)
    assert (cache.misses, cache.hits, len(cache)) == (1, 0, 1)
    with torch.inference_mode():
        direct = encoder(style_tensor(style))
    for a, b in zip(cache.features(style_tensor(style)).maps, direct.maps):
        assert torch.equal(a, b)  # computed in the worker thread: the same features
    torch.manual_seed(0)
    path = save_checkpoint(tmp_path / "m.safetensors", Stylize3DModel(ModelConfig.lite()), 2, {})
    st = Stylized3DPhoto(photo, path, StylizeSettings(strength=1.0), style_encoder=fut.result())
    st.set_style(style)
    assert cache.misses == 1 and cache.hits == 2  # set_style skipped the CNN
    assert prefetch_style(style).result() is not encoder  # no encoder given: a new one


def test_prefetch_reraises_the_workers_error():
    bad = np.full((8, 8, 3), np.nan, np.float32)
    with pytest.raises(InputError, match="style image"):
        prefetch_style(bad, StyleEncoder()).result()


def test_warm_up_waits_for_the_fps_worker_and_the_kernels():
    """``warm_up(wait=True)`` returns with the FPS worker process answering and the rasterizer's kernels
    loaded; a second call finds everything running and starts nothing new."""
    from stylize3d_core.pipeline import warm_up
    from stylize3d_core.points import sampling
    from stylize3d_core.render import rasterize

    first = warm_up(wait=True)
    assert first >= 0.0
    if sampling._WORKER.enabled:
        assert sampling._WORKER._ready and sampling._WORKER._proc.poll() is None
    assert rasterize._WARM is not None and not rasterize._WARM.is_alive()
    proc, thread = sampling._WORKER._proc, rasterize._WARM
    warm_up(wait=True)
    assert sampling._WORKER._proc is proc and rasterize._WARM is thread  # the same process, no new warm-up
