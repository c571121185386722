import json
from dataclasses import replace

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.checkpoint import config_to_json, load_checkpoint, save_checkpoint
from stylize3d_core.models.encoder import EncoderConfig
from stylize3d_core.models.scene_geometry import NeighbourhoodConfig
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel


def _model():
    torch.manual_seed(0)
    return Stylize3DModel(ModelConfig.lite())


def test_round_trip(tmp_path):
    m = _model()
    path = save_checkpoint(tmp_path / "m.safetensors", m, 1, {"iterations": 7, "note": "test"})
    ck = load_checkpoint(path)
    assert ck.stage == 1 and ck.info == {"iterations": 7, "note": "test"}
    assert ck.model.config == m.config
    for (k, a), (_, b) in zip(m.state_dict().items(), ck.model.state_dict().items()):
        assert torch.equal(a, b), k
    assert not ck.model.training


def test_paper_config_round_trips_its_architecture(tmp_path):
    m = Stylize3DModel(ModelConfig.paper())
    ck = load_checkpoint(save_checkpoint(tmp_path / "p.safetensors", m, 2, {}))
    assert ck.model.config == ModelConfig.paper() and ck.stage == 2


def test_missing_empty_truncated_and_foreign_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_checkpoint(tmp_path / "nope.safetensors")
    empty = tmp_path / "empty.safetensors"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        load_checkpoint(empty)
    good = save_checkpoint(tmp_path / "m.safetensors", _model(), 1, {})
    data = good.read_bytes()
    cut = tmp_path / "cut.safetensors"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="cut.safetensors"):
        load_checkpoint(cut)
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"hello world, not a model" * 10)
    with pytest.raises(InputError, match="junk.safetensors"):
        load_checkpoint(junk)
    from safetensors.torch import save_file

    other = tmp_path / "other.safetensors"
    save_file({"w": torch.zeros(2)}, str(other), metadata={"format": "something-else"})
    with pytest.raises(InputError, match="not a stylize3d model"):
        load_checkpoint(other)


def test_wrong_architecture(tmp_path):
    from safetensors import safe_open
    from safetensors.torch import load_file, save_file

    good = save_checkpoint(tmp_path / "m.safetensors", _model(), 1, {})
    with safe_open(str(good), framework="pt") as f:
        meta = f.metadata()
    tensors = load_file(str(good))
    assert json.loads(meta["config"])["name"] == "lite"
    # claim the paper architecture for lite weights
    wrong = dict(meta, config=config_to_json(ModelConfig.paper()))
    bad = tmp_path / "bad.safetensors"
    save_file(tensors, str(bad), metadata=wrong)
    with pytest.raises(InputError, match="bad.safetensors"):
        load_checkpoint(bad)
    # a missing weight
    tensors.pop(next(iter(tensors)))
    save_file(tensors, str(bad), metadata=meta)
    with pytest.raises(InputError, match="missing"):
        load_checkpoint(bad)


def test_nan_weights_are_refused(tmp_path):
    m = _model()
    with torch.no_grad():
        next(m.parameters()).fill_(float("nan"))
    path = save_checkpoint(tmp_path / "nan.safetensors", m, 1, {})
    with pytest.raises(InputError, match="NaN"):
        load_checkpoint(path)


def test_a_configuration_asking_for_huge_or_negative_sizes_is_refused_without_allocating(tmp_path):
    """Found by the fuzzer: a mutated width reached nn.Linear (negative: RuntimeError; huge: gigabytes)."""
    import dataclasses

    good = save_checkpoint(tmp_path / "m.safetensors", _model(), 1, {})
    lite = ModelConfig.lite()
    huge = dataclasses.replace(lite, stylizer=dataclasses.replace(lite.stylizer, hidden=2**20))
    bad = tmp_path / "huge.safetensors"
    _with_metadata(good, bad, config=config_to_json(huge))  # a 2**20 x 2**20 layer: 4 TiB of floats
    with pytest.raises(InputError, match="huge.safetensors.*shape"):
        load_checkpoint(bad)
    cfg = json.loads(config_to_json(lite))
    cfg["stylizer"]["style_channels"][3] = -59
    _with_metadata(good, bad, config=json.dumps(cfg))
    with pytest.raises(InputError, match="style_channels"):
        load_checkpoint(bad)


def _with_metadata(src, dst, **changes):
    from safetensors import safe_open
    from safetensors.torch import load_file, save_file

    with safe_open(str(src), framework="pt") as f:
        meta = f.metadata()
    save_file(load_file(str(src)), str(dst), metadata={**meta, **changes})
    return meta


def test_version_1_layout_is_mapped_to_the_neighbourhood_config(tmp_path):
    """Version 1 kept k, radii, down-sampling and FPS start in "encoder" and the subset size at the top."""
    m = _model()
    good = save_checkpoint(tmp_path / "m.safetensors", m, 1, {})
    d = json.loads(config_to_json(m.config))
    assert d["neighbourhood"] == NeighbourhoodConfig().to_dict()
    v1 = {k: v for k, v in d.items() if k != "neighbourhood"}
    v1["encoder"] = {**d["encoder"], "k": 8, "stem_radius": 0.02, "stage_radii": [[0.02, 0.03], [0.03, 0.06]],
                     "downsample": [4, 2], "fps_start": 1}
    v1["encoder_max_points"] = 1234
    old = tmp_path / "v1.safetensors"
    _with_metadata(good, old, version="1", config=json.dumps(v1, sort_keys=True))
    ck = load_checkpoint(old)
    assert ck.model.config.encoder == EncoderConfig.lite()
    assert ck.model.config.neighbourhood == NeighbourhoodConfig(
        k=8, stem_radius=0.02, stage_radii=((0.02, 0.03), (0.03, 0.06)), downsample=(4, 2), fps_start=1,
        reference_points_across=512, upsample_k=3, max_points=1234)
    for (k, a), (_, b) in zip(m.state_dict().items(), ck.model.state_dict().items()):
        assert torch.equal(a, b), k
    # the new layout under the old version number is not silently read
    bad = tmp_path / "mixed.safetensors"
    _with_metadata(good, bad, version="1")
    with pytest.raises(InputError, match="mixed.safetensors.*configuration is unreadable"):
        load_checkpoint(bad)
    _with_metadata(good, bad, version="7")
    with pytest.raises(InputError, match="version .7. is not supported"):
        load_checkpoint(bad)


def test_style_prior_round_trips_and_older_files_have_none(tmp_path):
    from stylize3d_core.models.stylize3d import add_style_prior

    m = add_style_prior(_model())
    assert m.config.style_prior and not m.config.detail_transfer
    path = save_checkpoint(tmp_path / "p.safetensors", m, 2, {})
    assert load_checkpoint(path).model.config == m.config
    d = json.loads(config_to_json(m.config))
    del d["style_prior"]
    d["detail_transfer"] = True
    old = tmp_path / "v5.safetensors"
    _with_metadata(save_checkpoint(tmp_path / "plain.safetensors", _model(), 2, {}), old, version="5",
                   config=json.dumps(d))
    assert load_checkpoint(old).model.config.style_prior is False
    with pytest.raises(InputError, match="style_prior"):
        ModelConfig(detail_transfer=True, style_prior=True)


def test_shipped_checkpoint_is_the_current_lite_layout():
    from safetensors import safe_open

    from stylize3d_core.pipeline import DEFAULT_MODEL

    with safe_open(str(DEFAULT_MODEL), framework="pt") as f:
        meta = f.metadata()
    assert meta["version"] == "6"
    ck = load_checkpoint(DEFAULT_MODEL)
    # the lite layout with the 2D style prior on its detail path (in place of the colour transfer)
    assert ck.model.config == replace(ModelConfig.lite(), style_prior=True, detail_transfer=False)
    assert ck.model.config.neighbourhood == NeighbourhoodConfig()
    assert ck.info["hours_total"] > 0 and "provenance" in ck.info
