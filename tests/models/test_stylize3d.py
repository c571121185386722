import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import Cameras
from stylize3d_core.models.adaattn import AdaAttNConfig
from stylize3d_core.models.decoder import DecoderConfig
from stylize3d_core.models.encoder import EncoderConfig
from stylize3d_core.models.scene_geometry import NeighbourhoodConfig, prepare_geometry, radius_scale
from stylize3d_core.models.stylize3d import (
    ModelConfig,
    Stylize3DModel,
    add_colour_transform,
    add_detail_path,
    add_texture_residual,
    count_parameters,
)

TINY = ModelConfig(
    name="lite",
    encoder=EncoderConfig(stem_channels=8, stage_channels=(16, 32)),
    stylizer=AdaAttNConfig(content_channels=32, hidden=16, value_channels=16, qk_channels=8),
    raster_channels=8,
    decoder=DecoderConfig(in_channels=8, width=16),
    detail_channels=0,
    detail_transfer=False,
)
TINY_DETAIL = ModelConfig(
    name="lite", encoder=TINY.encoder, stylizer=TINY.stylizer, raster_channels=8,
    decoder=DecoderConfig(in_channels=8 + 3, width=16), detail_channels=3, detail_transfer=False,
)


def test_radius_scale():
    assert radius_scale((512, 300), 10, 10) == pytest.approx(1.0)
    assert radius_scale((128, 128), 5, 5) == pytest.approx(4.0)
    # a subset of a quarter of the points is half as dense across
    assert radius_scale((1024, 1024), 250, 1000) == pytest.approx(1.0)
    assert radius_scale((128, 128), 5, 5, reference_points_across=256) == pytest.approx(2.0)


@pytest.mark.parametrize("config", [TINY, TINY_DETAIL], ids=["no-detail", "detail"])
def test_shapes_and_gradients_through_the_whole_model(cloud, config):
    pts, fov = cloud
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY.neighbourhood)
    n = pts.xyz.shape[0]
    assert geom.upsample.idx.shape == (n, 3)
    model = Stylize3DModel(config)
    content = model.encode(geom)
    assert content.shape == (geom.hierarchy.num_points[-1], 32)
    style = [torch.rand(1, c, 6, 6) for c in config.stylizer.style_channels]
    feats = model.stylize(content, style, 0.7)
    dense = model.dense_features(feats, geom)
    assert dense.shape == (n, 8 + config.detail_channels)
    if config.detail_channels:  # the detail path carries every point's own colour
        assert torch.equal(dense[:, 8:], geom.rgb)
    rgb, frags = model.render_view(dense, geom.xyz, Cameras.identity(fov), 24, 32)
    assert rgb.shape == (3, 24, 32) and torch.isfinite(rgb).all()
    assert ((rgb > 0) & (rgb < 1)).all()
    rgb.mean().backward()
    for name, p in model.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name
    assert count_parameters(model) > 0


def test_strength_zero_is_the_content(cloud):
    pts, fov = cloud
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY.neighbourhood)
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
    hood = NeighbourhoodConfig(max_points=500)
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), hood, seed=3)
    assert geom.encoder_idx.numel() == 500 and geom.hierarchy.num_points[0] == 500
    again = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), hood, seed=3)
    assert torch.equal(geom.encoder_idx, again.encoder_idx)
    # the radii are scaled to the subset's density
    assert geom.hierarchy.scale == pytest.approx(radius_scale((40, 48), 500, pts.xyz.shape[0]))
    # every point still gets features through the 3-NN upsampling
    assert geom.upsample.idx.shape[0] == pts.xyz.shape[0]


def test_encode_refuses_geometry_of_other_neighbourhoods(cloud):
    pts, fov = cloud
    model = Stylize3DModel(TINY).eval()
    other = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), NeighbourhoodConfig(k=8))
    with pytest.raises(InputError, match="neighbourhood"):
        model.encode(other)


def test_add_detail_path_keeps_the_output_and_learns_the_new_input(cloud):
    pts, fov = cloud
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY.neighbourhood)
    torch.manual_seed(0)
    narrow = Stylize3DModel(TINY).eval()
    wide = add_detail_path(narrow)
    assert wide.config == TINY_DETAIL and not wide.training
    cam = Cameras.identity(fov)
    with torch.no_grad():
        c = narrow.encode(geom)
        before = narrow.render_view(narrow.dense_features(c, geom), geom.xyz, cam, 24, 32)[0]
        after = wide.render_view(wide.dense_features(wide.encode(geom), geom), geom.xyz, cam, 24, 32)[0]
    torch.testing.assert_close(after, before, rtol=0, atol=1e-6)
    # the new (zero) input weights get gradients, so training can use the colours
    wide.train()
    rgb, _ = wide.render_view(wide.dense_features(wide.encode(geom), geom), geom.xyz, cam, 24, 32)
    rgb.mean().backward()
    g = wide.decoder.downs[0].conv1.weight.grad  # (out, 8 + 3 + 1, 3, 3)
    assert g[:, 8:11].abs().sum() > 0
    with pytest.raises(InputError, match="already"):
        add_detail_path(wide)


def test_add_colour_transform_keeps_the_output_and_learns_to_recolour(cloud):
    pts, fov = cloud
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY.neighbourhood)
    torch.manual_seed(0)
    plain = add_detail_path(Stylize3DModel(TINY)).eval()
    with pytest.raises(InputError, match="detail path"):
        add_colour_transform(Stylize3DModel(TINY))
    head = add_colour_transform(plain)
    assert head.config.decoder.transform_channels == 3 and not head.training
    cam = Cameras.identity(fov)
    with torch.no_grad():
        before, frags = plain.render_view(plain.dense_features(plain.encode(geom), geom), geom.xyz, cam, 24, 32)
        after = head.render_view(head.dense_features(head.encode(geom), geom), geom.xyz, cam, 24, 32)[0]
    torch.testing.assert_close(after, before, rtol=0, atol=1e-6)
    # the identity transform renders the rasterized point colours wherever points land
    with torch.no_grad():
        head.decoder.transform.bias.copy_(torch.tensor([1., 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]))
        rgb = head.render_view(head.dense_features(head.encode(geom), geom), geom.xyz, cam, 24, 32)[0]
    covered = ~frags.hole
    colours = frags.image[-3:]
    torch.testing.assert_close(rgb[:, covered], colours[:, covered].clamp(0, 1), rtol=0, atol=1e-5)
    torch.testing.assert_close(rgb[:, ~covered], before[:, ~covered], rtol=0, atol=1e-6)  # holes: the U-Net's
    # the zero head gets gradients
    fresh = add_colour_transform(plain).train()
    out, _ = fresh.render_view(fresh.dense_features(fresh.encode(geom), geom), geom.xyz, cam, 24, 32)
    out.mean().backward()
    assert fresh.decoder.transform.weight.grad.abs().sum() > 0
    with pytest.raises(InputError, match="already"):
        add_colour_transform(head)


def test_config_checks():
    with pytest.raises(InputError):
        ModelConfig(raster_channels=16)  # decoder expects 32 + 3
    with pytest.raises(InputError, match="detail_channels"):
        ModelConfig(detail_channels=1)
    assert ModelConfig().decoder.in_channels == 35 and ModelConfig.lite().detail_channels == 3
    assert ModelConfig.lite().decoder.transform_channels == 3 == ModelConfig.paper().decoder.transform_channels
    with pytest.raises(InputError, match="colour transform"):
        ModelConfig(detail_channels=0, decoder=DecoderConfig.lite(in_channels=32 + 3, transform_channels=3),
                    raster_channels=35, detail_transfer=False)
    with pytest.raises(InputError, match="detail_transfer"):
        ModelConfig(detail_channels=0, decoder=DecoderConfig.lite(in_channels=32), raster_channels=32)
    with pytest.raises(InputError):
        ModelConfig.by_name("huge")
    assert ModelConfig.paper().raster_channels == 256


def test_add_texture_residual_keeps_the_output(cloud):
    pts, fov = cloud
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY.neighbourhood)
    torch.manual_seed(0)
    head = add_colour_transform(add_detail_path(Stylize3DModel(TINY)), identity=True).eval()
    with pytest.raises(InputError, match="colour transform"):
        add_texture_residual(add_detail_path(Stylize3DModel(TINY)))
    with torch.no_grad():  # a colour transform away from the identity, so rgb and colours both count
        head.decoder.transform.bias.mul_(0.6)
    tex = add_texture_residual(head)
    assert tex.config.decoder.texture_channels == 3 and not tex.training
    with pytest.raises(InputError, match="already"):
        add_texture_residual(tex)
    cam = Cameras.identity(fov)
    with torch.no_grad():
        before = head.render_view(head.dense_features(head.encode(geom), geom), geom.xyz, cam, 24, 32)[0]
        after = tex.render_view(tex.dense_features(tex.encode(geom), geom), geom.xyz, cam, 24, 32)[0]
    torch.testing.assert_close(after, before, rtol=0, atol=1e-6)


def test_dense_features_for_inference_equal_the_differentiable_ones(cloud):
    """Without gradients the detail colours are written into the interpolated result (no copy of the
    whole (N, Cr + 3) array): bit for bit the concatenation that training differentiates through."""
    pts, fov = cloud
    model = Stylize3DModel(TINY_DETAIL).eval()
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, (40, 48), TINY_DETAIL.neighbourhood)
    content = model.encode(geom).detach()
    colours = torch.rand(geom.xyz.shape[0], 3)
    for given in (None, colours):
        with torch.no_grad():
            fast = model.dense_features(content, geom, given)
        slow = model.dense_features(content.clone().requires_grad_(True), geom, given)
        assert slow.requires_grad and fast.shape == slow.shape
        assert torch.equal(fast, slow.detach())
        assert torch.equal(fast[:, -3:], geom.rgb if given is None else colours)
