import json

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.models.checkpoint import config_to_json, load_checkpoint, save_checkpoint
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
