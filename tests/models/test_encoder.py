import pytest
import torch
import torch.nn.functional as F

from stylize3d_core.errors import InputError
from stylize3d_core.models.encoder import (
    Encoder,
    EncoderConfig,
    mrconv,
    neighbour_max,
)
from stylize3d_core.models.scene_geometry import NeighbourhoodConfig, PointHierarchy, build_hierarchy
from stylize3d_core.models.stylize3d import ModelConfig
from stylize3d_core.points.reference import ball_query_reference


def photo_cloud(n_side: int = 64, seed: int = 0) -> torch.Tensor:
    """(n_side^2, 3) NDC-like cloud: a jittered pixel grid over a bumpy surface with a depth step.

    Spacing 2 / n_side, so with n_side = 64 the stem ball (0.015) holds only the
    point itself; the tests below use a denser patch where balls must be full.
    """
    g = torch.Generator().manual_seed(seed)
    ys, xs = torch.meshgrid(torch.linspace(-1, 1, n_side), torch.linspace(-1, 1, n_side), indexing="ij")
    xy = torch.stack([xs, ys], -1).reshape(-1, 2)
    xy = xy + 0.5 * (torch.rand(xy.shape, generator=g) - 0.5) * (2.0 / n_side)
    z = 0.2 * torch.sin(3 * xy[:, 0]) * torch.cos(2 * xy[:, 1]) + 0.6 * (xy[:, 0] > 0.3)
    return torch.cat([xy, z[:, None]], 1)


def dense_patch(n: int = 4096, seed: int = 0) -> torch.Tensor:
    """(n, 3) points on a 0.25-wide patch: about 20 points per stem ball, like a 1 MP photo."""
    return photo_cloud(int(n**0.5), seed) * torch.tensor([0.125, 0.125, 0.05])


def mrconv_reference(features, neighbour_idx, weight, bias=None, centre_idx=None):
    """The formula as written: W [f_i || max_j (f_j - f_i)] + b, with an (M, k, C) gather."""
    centre = features if centre_idx is None else features[centre_idx]  # (M, C)
    rel = (features[neighbour_idx] - centre[:, None, :]).amax(dim=1)  # (M, C)
    return F.linear(torch.cat([centre, rel], 1), weight, bias)


def encoder_reference(enc: Encoder, features: torch.Tensor, h: PointHierarchy) -> torch.Tensor:
    """Encoder.forward in eval mode, rebuilt from mrconv_reference and the module's parameters."""

    def conv(layer, f, nbr, centre=None):
        return layer.norm(mrconv_reference(f, nbr, layer.linear.weight, layer.linear.bias, centre))

    x = F.relu(conv(enc.stem, features, h.stem_neighbours))
    for s, block in enumerate(enc.blocks):
        y = F.relu(conv(block.conv1, x, h.down_neighbours[s], h.sample_idx[s]))
        y = conv(block.conv2, y, h.same_neighbours[s])
        x = F.relu(y + block.shortcut(x[h.sample_idx[s]]))
    return enc.out(x)


# ----------------------------------------------------------------------------- functions


def test_mrconv_matches_reference_forward_and_backward():
    g = torch.Generator().manual_seed(0)
    feats = torch.randn(60, 5, generator=g, dtype=torch.float64, requires_grad=True)
    nbr = torch.randint(0, 60, (20, 7), generator=g)
    centre = torch.randint(0, 60, (20,), generator=g)
    w = torch.randn(4, 10, generator=g, dtype=torch.float64, requires_grad=True)
    b = torch.randn(4, generator=g, dtype=torch.float64, requires_grad=True)
    out = mrconv(feats, nbr, w, b, centre)
    ref = mrconv_reference(feats, nbr, w, b, centre)
    torch.testing.assert_close(out, ref)
    gout = torch.randn(20, 4, generator=g, dtype=torch.float64)
    for a, r in zip(torch.autograd.grad(out, (feats, w, b), gout), torch.autograd.grad(ref, (feats, w, b), gout)):
        torch.testing.assert_close(a, r)


def test_mrconv_gradcheck_float64():
    g = torch.Generator().manual_seed(1)
    feats = torch.randn(15, 3, generator=g, dtype=torch.float64, requires_grad=True)
    nbr = torch.randint(0, 15, (15, 4), generator=g)
    w = torch.randn(2, 6, generator=g, dtype=torch.float64, requires_grad=True)
    b = torch.randn(2, generator=g, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda f, w_, b_: mrconv(f, nbr, w_, b_), (feats, w, b))


def test_neighbour_max_paths_agree_and_ties_go_to_the_first():
    g = torch.Generator().manual_seed(2)
    feats = torch.randn(100, 6, generator=g)
    nbr = torch.randint(0, 100, (77, 5), generator=g)
    ref = feats[nbr].amax(dim=1)
    assert torch.equal(neighbour_max(feats, nbr), ref)  # no-grad path
    for c in (1, 3, 4):  # the no-grad path of narrow features (the stem's RGB): one channel at a time
        assert torch.equal(neighbour_max(feats[:, :c], nbr), ref[:, :c])
        assert torch.equal(neighbour_max(feats[:, 1 : 1 + c].double(), nbr), ref[:, 1 : 1 + c].double())
    f = feats.clone().requires_grad_(True)
    out = neighbour_max(f, nbr)  # autograd path
    assert torch.equal(out, ref)
    out.sum().backward()
    # each (row, channel) sends its gradient to exactly one source point
    assert float(f.grad.sum()) == 77 * 6
    # ties: the first maximising column wins
    f = torch.tensor([[1.0], [3.0], [3.0]], requires_grad=True)
    neighbour_max(f, torch.tensor([[0, 2, 1]])).sum().backward()
    assert f.grad.flatten().tolist() == [0.0, 0.0, 1.0]


def test_neighbour_max_bad_indices():
    with pytest.raises(InputError):
        neighbour_max(torch.rand(5, 2), torch.tensor([[0, 5]]))
    with pytest.raises(InputError):
        neighbour_max(torch.rand(5, 2), torch.tensor([[0, 1]], dtype=torch.int32))
    with pytest.raises(InputError):
        neighbour_max(torch.rand(5, 2), torch.zeros(3, 0, dtype=torch.long))


# ----------------------------------------------------------------------------- hierarchy


def test_hierarchy_shapes_and_neighbourhoods():
    xyz = dense_patch(4096)
    cfg = NeighbourhoodConfig()
    h = build_hierarchy(xyz, cfg)
    assert h.num_points == (4096, 1024, 256)
    assert h.stem_neighbours.shape == (4096, 16)
    assert [t.shape for t in h.sample_idx] == [(1024,), (256,)]
    assert [t.shape for t in h.down_neighbours] == [(1024, 16), (256, 16)]
    assert [t.shape for t in h.same_neighbours] == [(1024, 16), (256, 16)]
    torch.testing.assert_close(h.xyz[1], h.xyz[0][h.sample_idx[0]])
    torch.testing.assert_close(h.xyz[2], h.xyz[1][h.sample_idx[1]])
    # the neighbourhoods are the reference ball queries, at the configured radii
    some = torch.arange(0, 4096, 8)  # a subset of the stem queries keeps the brute force small
    assert torch.equal(h.stem_neighbours[some], ball_query_reference(h.xyz[0], h.xyz[0][some], 0.015, 16).idx)
    assert torch.equal(h.down_neighbours[0][::4], ball_query_reference(h.xyz[0], h.xyz[1][::4], 0.015, 16).idx)
    assert torch.equal(h.same_neighbours[0], ball_query_reference(h.xyz[1], h.xyz[1], 0.025, 16).idx)
    assert torch.equal(h.down_neighbours[1], ball_query_reference(h.xyz[1], h.xyz[2], 0.025, 16).idx)
    assert torch.equal(h.same_neighbours[1], ball_query_reference(h.xyz[2], h.xyz[2], 0.05, 16).idx)
    # a dense photo-like patch: stem balls are well filled
    counts = (h.stem_neighbours != h.stem_neighbours[:, :1]).sum(1) + 1
    assert float(counts.float().mean()) > 10


def test_hierarchy_is_deterministic_and_input_untouched():
    xyz = dense_patch(1024)
    before = xyz.clone()
    a, b = build_hierarchy(xyz), build_hierarchy(xyz)
    assert torch.equal(xyz, before)
    for ta, tb in zip(
        [a.stem_neighbours, *a.sample_idx, *a.down_neighbours, *a.same_neighbours],
        [b.stem_neighbours, *b.sample_idx, *b.down_neighbours, *b.same_neighbours],
    ):
        assert torch.equal(ta, tb)


# ----------------------------------------------------------------------------- encoder


def test_encoder_shapes_gradients_and_reference():
    torch.manual_seed(0)
    xyz = dense_patch(4096)
    rgb = torch.rand(4096, 3)
    h = build_hierarchy(xyz)
    enc = Encoder(EncoderConfig.paper())
    out = enc(rgb, h)
    assert out.features.shape == (256, 256) and out.xyz.shape == (256, 3)
    assert torch.equal(out.xyz, h.xyz[-1])
    assert bool(torch.isfinite(out.features).all())
    out.features.square().mean().backward()
    missing = [n for n, p in enc.named_parameters() if p.grad is None or not bool(p.grad.abs().sum() > 0)]
    assert missing == []
    # eval mode: equal to the formula composed by hand
    enc.eval()
    with torch.no_grad():
        torch.testing.assert_close(enc(rgb, h).features, encoder_reference(enc, rgb, h))


def test_eval_is_deterministic_and_hierarchy_reusable():
    torch.manual_seed(1)
    xyz = dense_patch(1024)
    h = build_hierarchy(xyz)
    enc = Encoder().eval()
    rgb1, rgb2 = torch.rand(1024, 3), torch.rand(1024, 3)
    with torch.inference_mode():
        a = enc(rgb1, h).features
        b = enc(rgb2, h).features  # another "style": same hierarchy
        c = enc(rgb1, h).features
        d = enc(rgb1, build_hierarchy(xyz)).features
    assert torch.equal(a, c) and torch.equal(a, d)
    assert not torch.equal(a, b)


@pytest.mark.parametrize("n", [1, 2, 5, 15, 17, 63])
def test_tiny_clouds(n):
    torch.manual_seed(n)
    h = build_hierarchy(torch.rand(n, 3))
    m1 = max(1, n // 4)
    assert h.num_points == (n, m1, max(1, m1 // 4))
    enc = Encoder().eval()
    with torch.inference_mode():
        out = enc(torch.rand(n, 3), h)
    assert out.features.shape == (h.num_points[-1], 256)
    assert bool(torch.isfinite(out.features).all())


def test_coincident_points_train_and_eval():
    xyz = torch.full((64, 3), 0.3)
    h = build_hierarchy(xyz)
    enc = Encoder()
    out = enc(torch.full((64, 3), 0.5), h)
    out.features.sum().backward()
    assert bool(torch.isfinite(out.features).all())
    assert all(bool(torch.isfinite(p.grad).all()) for p in enc.parameters() if p.grad is not None)
    enc.eval()
    with torch.inference_mode():
        assert bool(torch.isfinite(enc(torch.rand(64, 3), h).features).all())


def test_lite_config():
    cfg = EncoderConfig.lite()
    assert cfg.out_channels == 128 and ModelConfig.lite().neighbourhood == ModelConfig.paper().neighbourhood
    xyz = dense_patch(1024)
    h = build_hierarchy(xyz, ModelConfig.paper().neighbourhood)  # same neighbourhoods: reusable
    out = Encoder(cfg).eval()(torch.rand(1024, 3), h)
    assert out.features.shape == (64, 128)


def test_bad_inputs():
    xyz = dense_patch(256)
    h = build_hierarchy(xyz)
    enc = Encoder()
    with pytest.raises(InputError):
        enc(torch.rand(255, 3), h)  # wrong number of points
    with pytest.raises(InputError):
        enc(torch.rand(256, 4), h)  # wrong channels
    with pytest.raises(InputError):
        enc(torch.full((256, 3), float("nan")), h)
    with pytest.raises(InputError, match="stages"):
        Encoder(EncoderConfig(stage_channels=(128,)))(torch.rand(256, 3), h)  # hierarchy of 2 stages, encoder 1
    with pytest.raises(InputError, match="stages"):
        enc(torch.rand(256, 3), build_hierarchy(xyz, NeighbourhoodConfig(stage_radii=((0.015, 0.025),),
                                                                          downsample=(4,))))
    with pytest.raises(InputError):
        enc(torch.rand(5, 3), build_hierarchy(torch.rand(5, 3)))  # training needs >= 2 points per level
    with pytest.raises(InputError):
        build_hierarchy(torch.rand(0, 3))
    with pytest.raises(InputError):
        build_hierarchy(torch.rand(10, 2))
    with pytest.raises(InputError):
        build_hierarchy(torch.tensor([[0.0, float("inf"), 0.0]]))


@pytest.mark.parametrize("kwargs", [dict(stem_channels=0), dict(in_channels=0), dict(stage_channels=(128, 0))])
def test_config_validation(kwargs):
    with pytest.raises(InputError):
        EncoderConfig(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(k=0),
        dict(stage_radii=((0.015, 0.025),)),  # one stage of radii, two down-sampling factors
        dict(downsample=(4, 0)),
        dict(stage_radii=((0.01, 0.0), (0.02, 0.03))),
        dict(stage_radii=((0.01,), (0.02, 0.03))),
        dict(stem_radius=-1.0),
        dict(stem_radius=float("nan")),
        dict(fps_start=-1),
        dict(upsample_k=0),
        dict(reference_points_across=0),
        dict(max_points=8),
        dict(k=2.5),
    ],
)
def test_neighbourhood_config_validation(kwargs):
    with pytest.raises(InputError):
        NeighbourhoodConfig(**kwargs)


def test_model_config_needs_as_many_stages_as_the_neighbourhoods():
    one_stage = NeighbourhoodConfig(stage_radii=((0.015, 0.025),), downsample=(4,))
    with pytest.raises(InputError, match="stages"):
        ModelConfig(neighbourhood=one_stage)  # the lite encoder has two stages


def test_compiled_neighbour_max_gives_the_torch_lines_values_nan_and_zeros_too(monkeypatch):
    """The compiled neighbour max (inference, float32) against the running torch.maximum it replaces, on
    several parts of rows, with NaNs (propagated, as torch.maximum does) and zeros of both signs."""
    import stylize3d_core.models.encoder as enc

    if enc._threads.compiled("stylize3d_core.models._kernels") is None:
        pytest.skip("Numba does not import here: only the torch lines run")
    g = torch.Generator().manual_seed(7)
    feats = torch.randn(5000, 32, generator=g)
    feats[::97, 3] = float("nan")
    feats[1::13, 5] = 0.0
    feats[2::13, 5] = -0.0
    nbr = torch.randint(0, 5000, (9001, 16), generator=g)  # several parts on the pool's threads
    with torch.no_grad():
        fast = neighbour_max(feats, nbr)
        monkeypatch.setattr(enc, "_compiled_max", lambda f, i: None)
        torch_lines = neighbour_max(feats, nbr)
    assert fast.dtype == torch.float32 and fast.shape == (9001, 32)
    assert torch.isnan(fast[:, 3]).any() and torch.equal(torch.isnan(fast), torch.isnan(torch_lines))
    same = ~torch.isnan(fast)
    assert torch.equal(fast[same], torch_lines[same])  # (-0.0 == 0.0: torch's own loops differ in a zero's sign)
