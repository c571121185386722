import numpy as np
import pytest
import torch

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.models.adaattn import AdaAttNConfig
from stylize3d_core.models.decoder import DecoderConfig
from stylize3d_core.models.encoder import EncoderConfig
from stylize3d_core.models.stylize3d import (
    ModelConfig,
    Stylize3DModel,
    count_parameters,
    prepare_geometry,
    radius_scale,
)
from stylize3d_core.scene.photo3d import Photo3D

TINY = ModelConfig(
    name="lite",
    encoder=EncoderConfig(stem_channels=8, stage_channels=(16, 32)),
    stylizer=AdaAttNConfig(content_channels=32, hidden=16, value_channels=16, qk_channels=8),
    raster_channels=8,
    decoder=DecoderConfig(in_channels=8, width=16),
)


@pytest.fixture(scope="module")
def cloud():
    g = np.random.default_rng(0)
    rgb = g.random((40, 48, 3), dtype=np.float32)
    depth = np.ones((40, 48), np.float32)
    depth[10:30, 12:36] = 0.5
    p = Photo3D.build(rgb, DepthMap(depth, np.ones_like(depth, bool), "metric", "test"))
    return p.points.to_tensors(), p.fov_y_deg


def test_radius_scale():
    assert radius_scale((512, 300), 10, 10) == pytest.approx(1.0)
    assert radius_scale((128, 128), 5, 5) == pytest.approx(4.0)
    # a subset of a quarter of the points is half as dense across
    assert radius_scale((1024, 1024), 250, 1000) == pytest.approx(1.0)


def test_shapes_and_gradients_through_the_whole_model(cloud):
    pts, fov = cloud
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY)
    n = pts.xyz.shape[0]
    assert geom.upsample.idx.shape == (n, 3)
    model = Stylize3DModel(TINY)
    content = model.encode(geom)
    assert content.shape == (geom.hierarchy.num_points[-1], 32)
    style = [torch.rand(1, c, 6, 6) for c in TINY.stylizer.style_channels]
    feats = model.stylize(content, style, 0.7)
    dense = model.dense_features(feats, geom)
    assert dense.shape == (n, 8)
    rgb, frags = model.render_view(dense, geom.xyz, Cameras.identity(fov), 24, 32)
    assert rgb.shape == (3, 24, 32) and torch.isfinite(rgb).all()
    assert ((rgb > 0) & (rgb < 1)).all()
    rgb.mean().backward()
    for name, p in model.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name
    assert count_parameters(model) > 0


def test_strength_zero_is_the_content(cloud):
    pts, fov = cloud
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY)
    model = Stylize3DModel(TINY).eval()
    with torch.no_grad():
        c = model.encode(geom)
        style = [torch.rand(1, ch, 4, 4) for ch in TINY.stylizer.style_channels]
        assert torch.equal(model.stylize(c, style, 0.0), c)
        assert not torch.allclose(model.stylize(c, style, 1.0), c)
    with pytest.raises(InputError):
        model.stylize(c, style, 1.5)


def test_encoder_subset_for_large_clouds(cloud):
    pts, fov = cloud
    cfg = ModelConfig(**{**TINY.__dict__, "encoder_max_points": 500})
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), cfg, seed=3)
    assert geom.encoder_idx.numel() == 500 and geom.hierarchy.num_points[0] == 500
    again = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), cfg, seed=3)
    assert torch.equal(geom.encoder_idx, again.encoder_idx)
    # every point still gets features through the 3-NN upsampling
    assert geom.upsample.idx.shape[0] == pts.xyz.shape[0]


def test_config_checks():
    with pytest.raises(InputError):
        ModelConfig(raster_channels=16)  # decoder expects 32
    with pytest.raises(InputError):
        ModelConfig.by_name("huge")
    assert ModelConfig.paper().raster_channels == 256
