"""Fixtures shared by the viewer's tests."""

from pathlib import Path

import pytest
import torch

from stylize3d_core.models.decoder import identity_transform
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel


@pytest.fixture(scope="module")
def untrained(tmp_path_factory) -> Path:
    """An untrained lite checkpoint (a model whose outputs tests can compare, not judge)."""
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("model") / "untrained.safetensors"
    model = Stylize3DModel(ModelConfig.lite())
    # a zero colour transform: the untrained U-Net's own colours, visibly not the plain render (a new model
    # starts at the identity transform, which shows the points' colours)
    identity_transform(model.decoder.transform, False)
    save_checkpoint(path, model, 1, {"note": "untrained, for tests"})
    return path


@pytest.fixture(autouse=True)
def settings_dir(tmp_path_factory, monkeypatch) -> Path:
    """Every test's viewer keeps its settings file (recent files) in a fresh folder, never the user's."""
    folder = tmp_path_factory.mktemp("config")
    monkeypatch.setenv("STYLIZE3D_CONFIG_DIR", str(folder))
    return folder
