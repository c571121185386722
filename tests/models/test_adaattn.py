"""AdaAttN: attention statistics against a naive reference, gradients, chunking, equivariance, safety."""

from __future__ import annotations

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.adaattn import (
    AdaAttNConfig,
    AdaAttNStylizer,
    adaattn,
    attention_statistics,
    blend,
    mean_variance_norm,
    style_tokens,
)

STYLE_CH = (16, 24, 40, 112, 320)


def _gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _style_maps(b: int = 1, base: int = 64, seed: int = 0, constant: float = None):
    g = _gen(seed)
    maps = []
    for c, s in zip(STYLE_CH, (2, 4, 8, 16, 32)):
        size = max(1, base // s)
        m = torch.full((b, c, size, size), constant) if constant is not None else torch.randn(b, c, size, size, generator=g)
        maps.append(m)
    return maps


def _reference_statistics(q, k, v, eps):
    a = torch.softmax(q @ k.transpose(-1, -2), dim=-1)  # (M, L), formed in full
    mean = a @ v
    var = (a @ (v * v) - mean * mean).clamp_min(0)
    return mean, torch.sqrt(var + eps)


@pytest.fixture(scope="module")
def stylizer():
    torch.manual_seed(0)
    return AdaAttNStylizer(AdaAttNConfig(chunk_size=64))


def test_statistics_match_naive_reference():
    g = _gen(1)
    q, k, v = torch.randn(50, 8, generator=g), torch.randn(30, 8, generator=g), torch.randn(30, 5, generator=g)
    mean, std = attention_statistics(q, k, v, eps=1e-5, chunk_size=7)
    ref_mean, ref_std = _reference_statistics(q, k, v, 1e-5)
    torch.testing.assert_close(mean, ref_mean, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(std, ref_std, rtol=1e-4, atol=1e-5)


def test_known_values_single_key_and_identical_values():
    # One key: every query gets exactly that value, with zero variance.
    v = torch.tensor([[2.0, -3.0]])
    mean, std = attention_statistics(torch.randn(4, 3), torch.randn(1, 3), v, eps=1e-4)
    torch.testing.assert_close(mean, v.expand(4, 2))
    torch.testing.assert_close(std, torch.full((4, 2), 1e-2))
    # Identical style values: AdaAttN output = sqrt(eps) * norm(content) + value.
    # (float64: in float32, E[v^2] - E[v]^2 cancels to ~1e-6, visible next to eps = 1e-4)
    c = torch.randn(6, 2, dtype=torch.float64)
    s = torch.tensor([[1.0, 5.0]], dtype=torch.float64)
    out = adaattn(c, torch.randn(6, 3).double(), s.expand(9, 2), torch.randn(9, 3).double(), eps=1e-4)
    torch.testing.assert_close(out, 1e-2 * mean_variance_norm(c, 1e-4) + s)


def test_mean_variance_norm():
    x = torch.randn(2, 100, 3) * 5 + 2
    y = mean_variance_norm(x, eps=0.0)
    torch.testing.assert_close(y.mean(1), torch.zeros(2, 3), atol=1e-5, rtol=0)
    torch.testing.assert_close(y.var(1, unbiased=False), torch.ones(2, 3), atol=1e-4, rtol=0)


def test_gradcheck_attention_statistics():
    g = _gen(2)
    args = [torch.randn(5, 3, generator=g, dtype=torch.float64, requires_grad=True),
            torch.randn(4, 3, generator=g, dtype=torch.float64, requires_grad=True),
            torch.randn(4, 2, generator=g, dtype=torch.float64, requires_grad=True)]
    assert torch.autograd.gradcheck(lambda q, k, v: attention_statistics(q, k, v, chunk_size=2), args)


def test_gradcheck_adaattn_with_projections():
    g = _gen(3)
    lin_q = torch.nn.Linear(3, 4).double()
    lin_k = torch.nn.Linear(2, 4).double()
    args = [torch.randn(5, 3, generator=g, dtype=torch.float64, requires_grad=True),  # content
            torch.randn(5, 3, generator=g, dtype=torch.float64, requires_grad=True),  # content key
            torch.randn(4, 3, generator=g, dtype=torch.float64, requires_grad=True),  # style
            torch.randn(4, 2, generator=g, dtype=torch.float64, requires_grad=True)]  # style key

    def fn(c, ck, s, sk):
        return adaattn(c, ck, s, sk, query_proj=lin_q, key_proj=lin_k, chunk_size=3)

    assert torch.autograd.gradcheck(fn, args)


def test_gradcheck_constant_style():
    g = _gen(4)
    args = [torch.randn(4, 2, generator=g, dtype=torch.float64, requires_grad=True),
            torch.randn(4, 3, generator=g, dtype=torch.float64, requires_grad=True),
            torch.ones(3, 2, dtype=torch.float64, requires_grad=True),
            torch.ones(3, 3, dtype=torch.float64, requires_grad=True)]
    assert torch.autograd.gradcheck(lambda c, ck, s, sk: adaattn(c, ck, s, sk, eps=1e-3), args)


def test_stylizer_shapes(stylizer):
    maps = _style_maps(b=2)
    out = stylizer(torch.randn(2, 100, 256), maps)
    assert out.shape == (2, 100, 256) and torch.isfinite(out).all()
    single = stylizer(torch.randn(100, 256), _style_maps(b=1))
    assert single.shape == (100, 256)


def test_alpha_zero_returns_content_exactly(stylizer):
    content = torch.randn(80, 256)
    out = stylizer(content, _style_maps(), alpha=0.0)
    assert torch.equal(out, content) and out.data_ptr() != content.data_ptr()


def test_alpha_blends_linearly(stylizer):
    content = torch.randn(40, 256)
    maps = _style_maps()
    full = stylizer.stylize(content, maps)
    torch.testing.assert_close(stylizer(content, maps, alpha=1.0), full)
    torch.testing.assert_close(stylizer(content, maps, alpha=0.25), content + 0.25 * (full - content))
    torch.testing.assert_close(blend(content, full, 0.5), 0.5 * (content + full))
    with pytest.raises(InputError, match="alpha"):
        stylizer(content, maps, alpha=1.5)
    with pytest.raises(InputError, match="alpha"):
        blend(content, full, float("nan"))


def test_chunked_equals_unchunked(stylizer):
    content = torch.randn(1, 300, 256, generator=_gen(5))
    maps = _style_maps(seed=5)
    chunked = stylizer.stylize(content, maps)  # chunk_size 64 -> 5 chunks
    whole = AdaAttNStylizer(AdaAttNConfig(chunk_size=10_000))
    whole.load_state_dict(stylizer.state_dict())
    torch.testing.assert_close(chunked, whole.stylize(content, maps), rtol=1e-5, atol=1e-5)


def test_permutation_equivariance_over_points(stylizer):
    content = torch.randn(200, 256, generator=_gen(6))
    maps = _style_maps(seed=6)
    perm = torch.randperm(200, generator=_gen(7))
    torch.testing.assert_close(stylizer.stylize(content[perm], maps), stylizer.stylize(content, maps)[perm], rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("value", [0.0, 3.0])
def test_constant_style_and_constant_content_are_finite(stylizer, value):
    maps = [m.requires_grad_() for m in _style_maps(constant=value)]
    content = torch.full((50, 256), 1.5, requires_grad=True)
    out = stylizer(content, maps)
    assert torch.isfinite(out).all()
    out.square().mean().backward()
    assert torch.isfinite(content.grad).all()
    assert all(torch.isfinite(m.grad).all() for m in maps[:4])  # stage 4 is not used by default
    assert maps[4].grad is None


def test_gradients_reach_every_parameter(stylizer):
    stylizer.zero_grad()
    stylizer(torch.randn(30, 256), _style_maps()).square().mean().backward()
    for name, p in stylizer.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name


def test_style_tokens_resizes_keys_to_value_grid():
    maps = _style_maps(b=2, base=64)
    value, key = style_tokens(maps, 3, (0, 1, 2, 3))
    assert value.shape == (2, 16, 112) and key.shape == (2, 16, 16 + 24 + 40 + 112)
    # area resize: key channel of stage 0 is the 8x8 block mean of that map
    block_mean = maps[0][0, 0, :8, :8].mean()
    torch.testing.assert_close(key[0, 0, 0], block_mean)
    _, deeper = style_tokens(maps, 2, (4,))  # a deeper (smaller) key map is upsampled
    assert deeper.shape == (2, 64, 320)


def test_bad_inputs(stylizer):
    with pytest.raises(InputError, match="content"):
        stylizer(torch.randn(10, 128), _style_maps())
    with pytest.raises(InputError, match="style_maps"):
        stylizer(torch.randn(10, 256), _style_maps()[:3])
    with pytest.raises(InputError, match="style_maps"):
        stylizer(torch.randn(3, 10, 256), _style_maps(b=2))
    with pytest.raises(InputError, match="content_key"):
        adaattn(torch.randn(5, 2), torch.randn(4, 3), torch.randn(3, 2), torch.randn(3, 3))
    with pytest.raises(InputError, match="channels"):
        adaattn(torch.randn(5, 2), torch.randn(5, 3), torch.randn(3, 2), torch.randn(3, 4))
    with pytest.raises(InputError, match="chunk_size"):
        attention_statistics(torch.randn(2, 2), torch.randn(2, 2), torch.randn(2, 2), chunk_size=0)
    with pytest.raises(InputError):
        AdaAttNConfig(value_stage=7)


def test_module_equals_functional_composition(stylizer):
    content = torch.randn(1, 120, 256, generator=_gen(8))
    maps = _style_maps(seed=8)
    style, style_key = style_tokens(maps, 3, (0, 1, 2, 3))
    ref = stylizer.psi(
        adaattn(
            stylizer.phi_value(content), stylizer.phi_query(content), style, style_key,
            query_proj=stylizer.query_proj, key_proj=stylizer.key_proj, value_proj=stylizer.value_proj,
        )
    )
    torch.testing.assert_close(stylizer.stylize(content, maps), ref, rtol=1e-5, atol=1e-5)


def test_prepared_content_is_reusable_across_styles(stylizer):
    content = torch.randn(90, 256, generator=_gen(9))
    prepared = stylizer.prepare(content)
    for seed in (10, 11):
        maps = _style_maps(seed=seed)
        torch.testing.assert_close(stylizer.stylize_prepared(prepared, maps), stylizer.stylize(content, maps))
    with pytest.raises(InputError, match="style_maps"):
        stylizer.stylize_prepared(prepared, _style_maps(b=2))


def test_lite_preset():
    cfg = AdaAttNConfig.lite()
    assert (cfg.hidden, cfg.value_channels, cfg.qk_channels) == (128, 128, 64)
    assert AdaAttNConfig.paper() == AdaAttNConfig()
    out = AdaAttNStylizer(cfg)(torch.randn(2, 50, 256), _style_maps(b=2), alpha=0.5)
    assert out.shape == (2, 50, 256) and torch.isfinite(out).all()
