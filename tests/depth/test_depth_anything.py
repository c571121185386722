"""Depth Anything through Transformers, on a tiny randomly initialised model of the same architecture saved to a
temporary folder (no network): loading, the resize to the patch multiple, orientation and aspect, grey and RGBA
photos, corrupt weights, the cache lookup, the offline errors and the command line end to end."""

from __future__ import annotations

import numpy as np
import pytest

transformers = pytest.importorskip("transformers")

from stylize3d_app.cli import main  # noqa: E402
from stylize3d_core.depth import depth_anything as da  # noqa: E402
from stylize3d_core.depth.sources import AutoDepth, DepthAnythingDepth, parse_depth_spec  # noqa: E402
from stylize3d_core.errors import InputError  # noqa: E402
from stylize3d_core.io.images import load_image, load_image_array, save_image  # noqa: E402


def _tiny(folder):
    import torch
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config, DPTImageProcessor

    torch.manual_seed(0)
    backbone = Dinov2Config(hidden_size=32, num_hidden_layers=4, num_attention_heads=2, intermediate_size=64,
                            patch_size=14, image_size=56, out_indices=[1, 2, 3, 4], reshape_hidden_states=False)
    config = DepthAnythingConfig(backbone_config=backbone, neck_hidden_sizes=[8, 8, 16, 16], fusion_hidden_size=16,
                                 head_hidden_size=8, reassemble_hidden_size=32)
    DepthAnythingForDepthEstimation(config).eval().save_pretrained(folder)
    DPTImageProcessor(do_resize=True, size={"height": 56, "width": 56}, keep_aspect_ratio=True, ensure_multiple_of=14,
                      image_mean=[0.485, 0.456, 0.406], image_std=[0.229, 0.224, 0.225]).save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return _tiny(tmp_path_factory.mktemp("tiny_depth_anything"))


@pytest.fixture(scope="module")
def model(tiny):
    return da.DepthAnythingModel(tiny)


def test_the_network_runs_at_the_patch_multiple_and_returns_the_photo_size(model):
    rgb = np.random.default_rng(0).random((333, 517, 3)).astype(np.float32)
    inputs = model.processor(images=(rgb * 255).astype(np.uint8), return_tensors="pt")["pixel_values"]
    assert inputs.shape[-2] % 14 == 0 and inputs.shape[-1] % 14 == 0
    assert inputs.shape[-1] > inputs.shape[-2]  # the aspect is kept, not squashed to a square
    d = model.estimate(rgb)
    assert d.depth.shape == (333, 517) and d.kind == "relative"
    assert np.isfinite(d.depth).all() and d.depth.min() >= 1.0 - 1e-6 and d.depth.max() <= da.FAR_RATIO + 1e-4


@pytest.mark.parametrize("shape", [(60, 200), (200, 60)])
def test_orientation_follows_the_network_output(model, monkeypatch, shape):
    """What the network says is near stays where it is in the photo: a near left half (landscape and portrait)."""
    import torch

    h, w = shape

    def left_near(**inputs):
        ph, pw = inputs["pixel_values"].shape[-2:]
        inv = torch.zeros(1, ph, pw)
        inv[:, :, : pw // 2] = 1.0  # inverse depth: large = near
        return type("Out", (), {"predicted_depth": inv})()

    monkeypatch.setattr(model, "model", left_near)
    d = model.estimate(np.full((h, w, 3), 0.5, np.float32))
    assert d.depth.shape == (h, w)
    assert d.depth[:, : w // 4].mean() < d.depth[:, -w // 4:].mean()  # left nearer


def test_grey_and_rgba_photos(tmp_path, tiny):
    source = parse_depth_spec(f"depth-anything:{tiny}")
    grey = tmp_path / "grey.png"
    save_image(grey, np.tile(np.linspace(0, 1, 48, dtype=np.float32), (32, 1)))
    rgba = tmp_path / "rgba.png"
    import imageio.v3 as iio

    iio.imwrite(rgba, (np.random.default_rng(1).random((32, 48, 4)) * 255).astype(np.uint8))
    for path in (grey, rgba):
        out = source.estimate(load_image(path))
        assert out.depth_map.depth.shape == (32, 48) and np.isfinite(out.depth_map.depth).all()
    assert "Depth Anything" in source.describe()


def test_corrupt_or_truncated_weights_name_the_folder(tmp_path):
    folder = _tiny(tmp_path / "bad")
    weights = folder / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[: 1000])  # truncated
    with pytest.raises(InputError, match="cannot load the depth model") as e:
        da.DepthAnythingModel(folder)
    assert str(folder) in str(e.value)
    with pytest.raises(InputError, match="no config.json"):
        da.DepthAnythingModel(tmp_path)
    with pytest.raises(InputError, match="not found"):
        parse_depth_spec(f"depth-anything:{tmp_path / 'missing'}")


def test_without_cached_weights_the_source_names_the_download_command(monkeypatch, tmp_path):
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    assert da.cached_folder() is None
    with pytest.raises(InputError, match="stylize3d models download depth-anything"):
        parse_depth_spec("depth-anything")
    auto = AutoDepth()  # falls back to the prior, and says so
    assert not isinstance(auto.fallback, DepthAnythingDepth) and "prior" in auto.describe()


def test_the_cache_lookup_finds_the_pinned_revision(monkeypatch, tmp_path, tiny):
    """A cache laid out as huggingface_hub lays it out (refs, snapshots/<revision>): found, and auto uses it."""
    import shutil

    repo = tmp_path / "cache" / ("models--" + da.MODEL_ID.replace("/", "--"))
    snap = repo / "snapshots" / da.REVISION
    shutil.copytree(tiny, snap)
    (repo / "refs").mkdir()
    (repo / "refs" / "main").write_text(da.REVISION)
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "cache"))
    assert da.cached_folder() == snap
    auto = AutoDepth()
    assert isinstance(auto.fallback, DepthAnythingDepth) and "Depth Anything" in auto.describe()
    out = auto.estimate(load_image_array(np.full((36, 40, 3), 0.3, np.float32)))
    assert out.depth_map.depth.shape == (36, 40)


def test_command_line_end_to_end_and_offline_errors(tmp_path, tiny, capsys, monkeypatch):
    photo = tmp_path / "photo.png"
    y, x = np.mgrid[0:48, 0:64]
    save_image(photo, np.stack([x / 64, y / 48, 0.5 + 0 * x], -1).astype(np.float32))
    out = tmp_path / "out.mp4"
    assert main(["render", str(photo), "--depth", f"depth-anything:{tiny}", "--frames", "2", "--size", "32",
                 "-o", str(out), "-q"]) == 0
    assert out.stat().st_size > 0
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    capsys.readouterr()
    assert main(["render", str(photo), "--depth", "depth-anything", "-o", str(tmp_path / "x.mp4"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "stylize3d models download depth-anything" in err and "--depth prior" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert main(["models", "download", "depth-anything"]) == 2
    err = capsys.readouterr().err
    assert "HF_HUB_OFFLINE" in err and len(err.strip().splitlines()) == 1


def test_download_uses_the_pinned_revision(monkeypatch, tmp_path, tiny, capsys):
    """``models download`` asks huggingface_hub for the pinned revision (a local stand-in for the hub)."""
    import huggingface_hub

    asked = {}

    def stand_in(repo_id, revision=None, local_files_only=False, **kw):
        if local_files_only:
            raise huggingface_hub.errors.LocalEntryNotFoundError("not cached")
        asked.update(repo_id=repo_id, revision=revision)
        return str(tiny)

    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.setattr(huggingface_hub, "snapshot_download", stand_in)
    monkeypatch.setattr(da, "_check_reachable", lambda endpoint: None)
    assert main(["models", "download", "depth-anything"]) == 0
    assert asked == {"repo_id": da.MODEL_ID, "revision": da.REVISION}
    assert len(da.REVISION) == 40 and da.REVISION != "main"
    assert "saved in" in capsys.readouterr().err


def test_info_reports_the_weights(monkeypatch, tmp_path):
    from stylize3d_core.info import collect

    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    report = collect()["depth_anything"]
    assert report["weights_cached"] is False and "models download" in report["detail"]
    assert report["revision"] == da.REVISION


def test_download_reports_the_bytes_it_receives(monkeypatch, tmp_path):
    """``progress`` hears the fraction of the bytes of huggingface_hub's byte bar (a stand-in for the hub that
    drives the tqdm class it is given the way snapshot_download does), and 1.0 at the end."""
    import huggingface_hub

    def stand_in(repo_id, revision=None, tqdm_class=None, **kw):
        files = tqdm_class(total=3, unit="it", disable=True)  # the per-file counter: not reported
        files.update(1)
        bar = tqdm_class(total=0, unit="B", disable=True)  # the byte bar learns its total as files start
        bar.total = 1000
        for _ in range(4):
            bar.update(250)
        return str(tmp_path)

    heard = []
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.setattr(huggingface_hub, "snapshot_download", stand_in)
    monkeypatch.setattr(da, "_check_reachable", lambda endpoint: None)
    assert da.download(progress=heard.append) == tmp_path
    assert heard == [0.25, 0.5, 0.75, 1.0, 1.0]


def test_an_unreachable_hub_fails_at_once_with_one_line(monkeypatch):
    """A hub out of reach is refused before huggingface_hub's retries start."""
    import socket

    import huggingface_hub

    with socket.socket() as s:  # a port nothing listens on: refused at once
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.setenv("HF_ENDPOINT", f"http://127.0.0.1:{port}")
    monkeypatch.setattr(huggingface_hub, "snapshot_download", lambda *a, **k: pytest.fail("the hub was asked"))
    with pytest.raises(InputError, match=r"cannot reach 127\.0\.0\.1 .*--depth prior"):
        da.download()


def _cache_with(tiny, root):
    import shutil

    snap = root / ("models--" + da.MODEL_ID.replace("/", "--")) / "snapshots" / da.REVISION
    shutil.copytree(tiny, snap)
    return snap


def test_onnx_export_runs_as_the_onnx_source_and_matches_the_network(monkeypatch, tmp_path, tiny, capsys):
    """``models export-onnx`` writes a fixed-size graph that the ``onnx:`` source reads its size from; on a
    photo of the graph's aspect (both paths feed the network the same size) the depth equals the Transformers
    path's but for the resize's interpolation."""
    from stylize3d_core.depth.onnx_model import OnnxDepthModel, OnnxSettings, PRESETS

    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "cache"))
    _cache_with(tiny, tmp_path / "cache")
    dest = tmp_path / "da.onnx"
    assert main(["models", "export-onnx", "depth-anything", str(dest), "--size", "56x84"]) == 0
    assert f"onnx:{dest}:depth_anything" in capsys.readouterr().err
    yy, xx = np.mgrid[0:112, 0:168].astype(np.float32)
    rgb = np.stack([xx / 168, yy / 112, 0.5 + 0.4 * np.sin(xx / 9.0) * np.cos(yy / 7.0)], -1).astype(np.float32)
    onnx_depth = OnnxDepthModel(dest, OnnxSettings(preset=PRESETS["depth_anything"])).estimate(rgb).depth
    torch_depth = da.DepthAnythingModel().estimate(rgb).depth
    assert onnx_depth.shape == torch_depth.shape == (112, 168)
    assert np.corrcoef(onnx_depth.ravel(), torch_depth.ravel())[0, 1] > 0.99
    assert main(["render", str(tmp_path / "none.png"), "--depth", f"onnx:{dest}:depth_anything"]) == 2  # no photo


@pytest.mark.parametrize("size", ["500x500", "518", "axb", "0x14"])
def test_onnx_export_refuses_a_size_off_the_patch_grid(monkeypatch, tmp_path, tiny, capsys, size):
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "cache"))
    _cache_with(tiny, tmp_path / "cache")
    dest = tmp_path / "da.onnx"
    assert main(["models", "export-onnx", "depth-anything", str(dest), "--size", size]) == 2
    assert "size" in capsys.readouterr().err
    assert not dest.exists() and list(tmp_path.glob("*.onnx*")) == []


def test_onnx_export_without_weights_names_the_download(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))
    assert main(["models", "export-onnx", "depth-anything", str(tmp_path / "da.onnx")]) == 2
    assert "models download depth-anything" in capsys.readouterr().err
