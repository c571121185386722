"""Training samples (``train/data.py``), their disk cache (``train/cache.py``) and the photos."""

import json
import math
import os
import shutil

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.ndc import to_ndc
from stylize3d_core.models.encoder import EncoderConfig, build_hierarchy
from stylize3d_core.models.stylize3d import radius_scale
from stylize3d_core.scene.ldi import BORDER, INPAINTED, ORIGINAL
from stylize3d_core.train.cache import (
    TrainDataset,
    build_dataset,
    collate_samples,
    load_sample,
    sample_path,
    save_sample,
)
from stylize3d_core.train.data import (
    DataConfig,
    ViewSampling,
    held_out_config,
    make_sample,
    sample_target_cameras,
)
from stylize3d_core.train.photos import EVAL_PHOTOS, PHOTO_LICENCES, TRAIN_PHOTOS, PhotoAugment, augmented_photo

SMALL = DataConfig(image_size=(40, 48), scene_textures=3, texture_size=32)
STILL = ViewSampling(x=(0.0, 0.0), y=(0.0, 0.0), z=(0.0, 0.0), fov_scale=(1.0, 1.0))


@pytest.fixture(scope="module")
def samples():
    """One sample of each kind at a small size (module-wide: generation is the slow part)."""
    return {k: make_sample(3, SMALL, seed=11, kind=k) for k in ("ldi", "procedural")}


def assert_samples_equal(a, b):
    assert (a.kind, a.source, a.seed, a.index, a.fov_y_deg) == (b.kind, b.source, b.seed, b.index, b.fov_y_deg)
    assert tuple(a.ndc) == tuple(b.ndc)
    for name in ("image", "xyz_ndc", "targets", "masks", "seen"):
        assert torch.equal(getattr(a, name), getattr(b, name)), name
    for x, y in zip(a.points, b.points):
        assert torch.equal(x, y)
    assert torch.equal(a.cameras.cam_to_world, b.cameras.cam_to_world)
    assert torch.equal(a.cameras.fov_y_deg, b.cameras.fov_y_deg)
    ha, hb = a.hierarchy, b.hierarchy
    assert ha.key == hb.key
    assert torch.equal(ha.stem_neighbours, hb.stem_neighbours)
    for fa, fb in ((ha.xyz, hb.xyz), (ha.sample_idx, hb.sample_idx), (ha.down_neighbours, hb.down_neighbours),
                   (ha.same_neighbours, hb.same_neighbours)):
        assert len(fa) == len(fb) and all(torch.equal(x, y) for x, y in zip(fa, fb))


# ----------------------------------------------------------------------------- cameras


def test_view_sampling_defaults_are_the_public_ranges():
    v = ViewSampling()
    assert (v.num_views, v.x, v.y, v.z, v.fov_scale) == (2, (-0.05, 0.05), (-0.05, 0.05), (-0.05, 0.15), (0.95, 1.05))


def test_target_cameras_respect_the_ranges():
    cams = sample_target_cameras(np.random.default_rng(0), 60.0, ViewSampling(num_views=1000))
    t = cams.centres().numpy()
    assert len(cams) == 1000
    for axis, (lo, hi) in enumerate([(-0.05, 0.05), (-0.05, 0.05), (-0.05, 0.15)]):
        assert t[:, axis].min() >= lo and t[:, axis].max() <= hi
        assert t[:, axis].min() < lo + 0.01 and t[:, axis].max() > hi - 0.01  # the whole range is used
    fov = cams.fov_y_deg.numpy()
    assert fov.min() >= 57.0 and fov.max() <= 63.0 and fov.min() < 57.3 and fov.max() > 62.7
    np.testing.assert_array_equal(cams.cam_to_world[:, :3, :3].numpy(), np.tile(np.eye(3), (1000, 1, 1)))
    again = sample_target_cameras(np.random.default_rng(0), 60.0, ViewSampling(num_views=1000))
    assert torch.equal(again.cam_to_world, cams.cam_to_world)


@pytest.mark.parametrize("kwargs", [{"num_views": 0}, {"x": (0.1, -0.1)}, {"z": (0.0,)}, {"fov_scale": (0.0, 1.0)}])
def test_view_sampling_rejects_bad_settings(kwargs):
    with pytest.raises(InputError):
        ViewSampling(**kwargs)


# ----------------------------------------------------------------------------- samples


@pytest.mark.parametrize("kind", ["ldi", "procedural"])
def test_sample_shapes_and_dtypes(samples, kind):
    s = samples[kind]
    h, w = SMALL.image_size
    n, v = s.num_points, SMALL.views.num_views
    assert s.kind == kind and s.image_size == (h, w)
    assert s.image.shape == (h, w, 3) and s.image.dtype == torch.float32
    assert s.points.xyz.shape == (n, 3) and s.points.xyz.dtype == torch.float32
    assert s.points.rgb.shape == (n, 3) and s.points.rgb.dtype == torch.float32
    assert s.points.label.shape == (n,) and s.points.label.dtype == torch.uint8
    assert set(s.points.label.unique().tolist()) <= {ORIGINAL, INPAINTED, BORDER}
    assert int((s.points.label == ORIGINAL).sum()) == h * w  # one point per photo pixel
    assert s.xyz_ndc.shape == (n, 3)
    assert torch.equal(s.xyz_ndc, to_ndc(s.points.xyz, s.ndc))
    assert len(s.cameras) == v
    assert s.targets.shape == (v, 3, h, w) and s.targets.dtype == torch.float32
    assert s.masks.shape == (v, h, w) and s.masks.dtype == torch.bool
    assert s.seen.shape == (v, h, w) and s.seen.dtype == torch.bool
    assert not (s.seen & ~s.masks).any()
    for t in (s.image, s.targets, s.points.rgb):
        assert torch.isfinite(t).all() and t.min() >= 0 and t.max() <= 1
        assert torch.equal(t * 255, torch.round(t * 255))  # quantised to 1/255
    assert torch.isfinite(s.points.xyz).all() and (s.points.xyz[:, 2] > 0).all()
    assert s.masks.float().mean() > 0.8
    assert {"ldi", "targets", "hierarchy", "total"} <= set(s.timings)


@pytest.mark.parametrize("kind", ["ldi", "procedural"])
def test_hierarchy_is_build_hierarchy_of_the_points(samples, kind):
    s = samples[kind]
    scaled = SMALL.encoder.scaled(radius_scale(SMALL.image_size, 1, 1))  # 512 / 48 px across
    ref = build_hierarchy(s.xyz_ndc, scaled)
    assert s.hierarchy.key == scaled.neighbourhood_key()
    assert s.hierarchy.key[1] == pytest.approx(EncoderConfig().stem_radius * 512 / 48)
    assert s.hierarchy.num_points == ref.num_points
    assert torch.equal(s.hierarchy.stem_neighbours, ref.stem_neighbours)
    for a, b in zip(s.hierarchy.sample_idx + s.hierarchy.down_neighbours + s.hierarchy.same_neighbours,
                    ref.sample_idx + ref.down_neighbours + ref.same_neighbours):
        assert torch.equal(a, b)


def test_same_seed_same_sample_other_index_other_sample(samples):
    assert_samples_equal(make_sample(3, SMALL, seed=11, kind="ldi"), samples["ldi"])
    other = make_sample(4, SMALL, seed=11, kind="ldi")
    assert not torch.equal(other.image, samples["ldi"].image)


def test_kind_is_drawn_with_the_configured_fraction():
    kinds = [np.random.default_rng([5, i]).random() < 0.25 for i in range(400)]
    assert 0.18 < np.mean(kinds) < 0.32  # make_sample's first draw decides the kind
    cfg = DataConfig(image_size=(32, 32), procedural_fraction=1.0, scene_textures=2, texture_size=16)
    assert make_sample(0, cfg, seed=5).kind == "procedural"


@pytest.mark.parametrize("kind", ["ldi", "procedural"])
def test_still_camera_target_reproduces_the_source(kind):
    """A target camera equal to the source camera sees the source image (known value)."""
    cfg = DataConfig(image_size=(40, 48), views=STILL, scene_textures=3, texture_size=32)
    s = make_sample(1, cfg, seed=2, kind=kind)
    src = s.image.permute(2, 0, 1)
    if kind == "procedural":  # the same ray cast, scaled scene and all
        torch.testing.assert_close(s.targets[0], src, atol=1.5 / 255, rtol=0)
        assert s.seen.all()
    else:  # the LDI's own points rasterized at their pixel centres
        mse = float(((s.targets[0] - src) ** 2)[:, s.masks[0]].mean())
        assert 10 * math.log10(1 / max(mse, 1e-12)) > 35.0
        assert s.seen.float().mean() > 0.95


def test_procedural_targets_show_what_the_source_did_not_see():
    cfg = DataConfig(image_size=(48, 64), procedural_fraction=1.0, scene_textures=3, texture_size=32,
                     views=ViewSampling(x=(0.05, 0.05), y=(0.0, 0.0), z=(0.0, 0.0)))
    unseen = [1.0 - float(make_sample(i, cfg, seed=0).seen.float().mean()) for i in range(3)]
    assert max(unseen) > 0.005  # a sideways move of 0.05 disoccludes some background
    assert max(unseen) < 0.5


def test_make_sample_rejects_bad_input():
    with pytest.raises(InputError, match="index"):
        make_sample(-1, SMALL)
    with pytest.raises(InputError, match="kind"):
        make_sample(0, SMALL, kind="photo")
    with pytest.raises(InputError, match="config"):
        make_sample(0, {"image_size": (32, 32)})
    with pytest.raises(InputError, match="image_size"):
        DataConfig(image_size=(8, 8))
    with pytest.raises(InputError, match="photos"):
        DataConfig(photos=())


def test_photos_and_splits():
    assert not set(TRAIN_PHOTOS) & set(EVAL_PHOTOS)
    assert set(TRAIN_PHOTOS) | set(EVAL_PHOTOS) <= set(PHOTO_LICENCES)
    assert held_out_config(DataConfig()).photos == EVAL_PHOTOS
    with pytest.raises(InputError, match="held-out"):
        held_out_config(DataConfig(photos=("astronaut", "chelsea")))
    img, where = augmented_photo("retina", np.random.default_rng(0), (32, 40), PhotoAugment())
    assert img.shape == (32, 40, 3) and img.dtype == np.float32 and 0 <= img.min() and img.max() <= 1
    assert img.std() >= PhotoAugment().min_std and where.startswith("retina crop")
    with pytest.raises(InputError, match="not a known training photo"):
        augmented_photo("no_such_photo", np.random.default_rng(0), (32, 32))


# ----------------------------------------------------------------------------- cache


def test_save_load_round_trip(samples, tmp_path):
    for kind, s in samples.items():
        path = tmp_path / f"{kind}.pt"
        save_sample(path, s, "key")
        assert_samples_equal(load_sample(path), s)
        raw = torch.load(path, weights_only=True)  # plain tensors and dicts only
        assert raw["format"] == "stylize3d-train-sample" and raw["config_key"] == "key"


def test_load_sample_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_sample(tmp_path / "missing.pt")
    bad = tmp_path / "garbage.pt"
    bad.write_bytes(b"not a torch file at all")
    with pytest.raises(InputError, match="garbage.pt.*corrupt"):
        load_sample(bad)
    other = tmp_path / "other.pt"
    torch.save({"format": "something else"}, other)
    with pytest.raises(InputError, match="not a stylize3d training sample"):
        load_sample(other)


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    report = build_dataset(root, 3, SMALL, seed=4)
    assert (report.generated, report.skipped, report.regenerated) == (3, 0, ())
    return root


def test_build_dataset_writes_what_make_sample_makes(dataset_dir):
    ds = TrainDataset(dataset_dir, encoder=EncoderConfig())
    assert len(ds) == 3 and ds.seed == 4
    assert_samples_equal(ds[1], make_sample(1, SMALL, seed=4))
    loader = DataLoader(ds, batch_size=2, collate_fn=collate_samples)
    batch = next(iter(loader))
    assert isinstance(batch, list) and len(batch) == 2 and batch[0].index == 0
    with pytest.raises(IndexError):
        ds[3]


def test_build_dataset_resumes_and_regenerates_corrupt_files(dataset_dir, tmp_path):
    dataset_dir = shutil.copytree(dataset_dir, tmp_path / "ds")
    path = sample_path(dataset_dir, 1)
    with open(path, "r+b") as f:
        f.truncate(os.path.getsize(path) // 2)
    with pytest.raises(InputError, match=f"{path.name}.*corrupt"):
        TrainDataset(dataset_dir)[1]
    report = build_dataset(dataset_dir, 4, SMALL, seed=4)
    assert (report.generated, report.skipped) == (1, 2)
    assert [os.path.basename(p) for p, _ in report.regenerated] == [path.name]
    assert "corrupt" in report.regenerated[0][1]
    assert_samples_equal(load_sample(path), make_sample(1, SMALL, seed=4))  # regenerated identically
    assert json.loads((dataset_dir / "dataset.json").read_text())["n_samples"] == 4
    assert len(TrainDataset(dataset_dir)) == 4


def test_dataset_folder_mismatches_are_reported(dataset_dir, tmp_path):
    with pytest.raises(InputError, match="dataset.json.*another folder"):
        build_dataset(dataset_dir, 1, SMALL, seed=5)
    with pytest.raises(InputError, match="no dataset.json"):
        TrainDataset(tmp_path)
    with pytest.raises(InputError, match="encoder"):
        TrainDataset(dataset_dir, encoder=EncoderConfig(k=8))[0]
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "dataset.json").write_text((dataset_dir / "dataset.json").read_text())
    with pytest.raises(InputError, match="missing"):
        TrainDataset(copy)
