"""Training samples (``train/data.py``), their disk cache (``train/cache.py``) and the photos."""

import dataclasses
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
from stylize3d_core.models.scene_geometry import NeighbourhoodConfig, build_hierarchy, radius_scale
from stylize3d_core.models.checkpoint import Checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.scene.ldi import BORDER, INPAINTED, ORIGINAL
from stylize3d_core.scene.photo3d import Photo3D
from stylize3d_core.scene.pointcloud import PointCloud
from stylize3d_core.stylize import Stylized3DPhoto
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
    for name in ("image", "targets", "masks", "seen"):
        assert torch.equal(getattr(a, name), getattr(b, name)), name
    for x, y in zip(a.points, b.points):
        assert (x is None and y is None) or torch.equal(x, y)
    assert torch.equal(a.cameras.cam_to_world, b.cameras.cam_to_world)
    assert torch.equal(a.cameras.fov_y_deg, b.cameras.fov_y_deg)
    assert_geometry_equal(a.geometry, b.geometry)


def assert_geometry_equal(ga, gb):
    """Two SceneGeometry are identical: NDC, subset, every hierarchy tensor and the upsampling weights."""
    assert tuple(ga.ndc) == tuple(gb.ndc)
    for name in ("xyz", "rgb", "encoder_idx"):
        assert torch.equal(getattr(ga, name), getattr(gb, name)), name
    ha, hb = ga.hierarchy, gb.hierarchy
    assert ha.neighbourhood == hb.neighbourhood and ha.scale == hb.scale
    assert torch.equal(ha.stem_neighbours, hb.stem_neighbours)
    for fa, fb in ((ha.xyz, hb.xyz), (ha.sample_idx, hb.sample_idx), (ha.down_neighbours, hb.down_neighbours),
                   (ha.same_neighbours, hb.same_neighbours)):
        assert len(fa) == len(fb) and all(torch.equal(x, y) for x, y in zip(fa, fb))
    assert torch.equal(ga.upsample.idx, gb.upsample.idx)
    assert torch.equal(ga.upsample.weight, gb.upsample.weight)


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
    g = s.geometry
    assert torch.equal(g.xyz, s.points.xyz) and torch.equal(g.rgb, s.points.rgb)
    assert torch.equal(g.encoder_idx, torch.arange(n))  # small: every point is encoded
    assert torch.equal(g.hierarchy.xyz[0], to_ndc(s.points.xyz, g.ndc))
    assert g.upsample.idx.shape == (n, 3) and g.upsample.weight.shape == (n, 3)
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
    assert {"ldi", "targets", "geometry", "total"} <= set(s.timings)


@pytest.mark.parametrize("kind", ["ldi", "procedural"])
def test_hierarchy_is_build_hierarchy_of_the_points(samples, kind):
    s = samples[kind]
    h = s.geometry.hierarchy
    scale = radius_scale(SMALL.image_size, 1, 1)  # 512 / 48 px across
    ref = build_hierarchy(h.xyz[0], SMALL.neighbourhood, scale)
    assert h.neighbourhood == SMALL.neighbourhood == NeighbourhoodConfig()
    assert h.scale == pytest.approx(512 / 48)
    assert h.neighbourhood.radii(h.scale)[0] == pytest.approx(NeighbourhoodConfig().stem_radius * 512 / 48)
    assert h.num_points == ref.num_points
    assert torch.equal(h.stem_neighbours, ref.stem_neighbours)
    for a, b in zip(h.sample_idx + h.down_neighbours + h.same_neighbours,
                    ref.sample_idx + ref.down_neighbours + ref.same_neighbours):
        assert torch.equal(a, b)


def _photo_of(sample):
    """The sample's point cloud as the Photo3D an inference run would hold."""
    cloud = PointCloud(sample.points.xyz.numpy(), sample.points.rgb.numpy(), sample.points.label.numpy(),
                       sample.image_size, sample.fov_y_deg)
    return Photo3D(sample.image.numpy(), None, None, cloud, sample.fov_y_deg, {})


@pytest.mark.parametrize("kind", ["ldi", "procedural"])
def test_training_geometry_is_the_inference_geometry(samples, kind, tmp_path):
    """Inference (Stylized3DPhoto of the same cloud) and training (the sample, fresh and cached) agree exactly."""
    s = samples[kind]
    model = Stylize3DModel(ModelConfig.lite())
    inference = Stylized3DPhoto(_photo_of(s), Checkpoint(model, 1, {})).geometry
    assert_geometry_equal(inference, s.geometry)
    save_sample(tmp_path / "s.pt", s)
    assert_geometry_equal(inference, load_sample(tmp_path / "s.pt").geometry)
    # and the model encodes both to the same features
    with torch.inference_mode():
        assert torch.equal(model.eval().encode(inference), model.encode(s.geometry))


def test_training_geometry_subsets_large_clouds_as_inference_does(samples):
    hood = NeighbourhoodConfig(max_points=500)
    s = make_sample(3, dataclasses.replace(SMALL, neighbourhood=hood), seed=11, kind="ldi")
    assert s.geometry.encoder_idx.numel() == 500 < s.num_points
    assert s.geometry.hierarchy.scale == pytest.approx(radius_scale(SMALL.image_size, 500, s.num_points))
    model = Stylize3DModel(dataclasses.replace(ModelConfig.lite(), neighbourhood=hood))
    assert_geometry_equal(Stylized3DPhoto(_photo_of(s), Checkpoint(model, 1, {})).geometry, s.geometry)
    assert_samples_equal(s._replace(geometry=samples["ldi"].geometry), samples["ldi"])  # only the geometry differs


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
    ds = TrainDataset(dataset_dir, neighbourhood=NeighbourhoodConfig())
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


def _as_version_1(d):
    """A sample dict in the version-1 layout (positional hierarchy key, no upsampling weights)."""
    g = d.pop("geometry")
    hood = g["neighbourhood"]
    r = g["scale"]
    key = (hood["k"], hood["stem_radius"] * r, [[a * r, b * r] for a, b in hood["stage_radii"]],
           hood["downsample"], hood["fps_start"])
    d["ndc"] = g["ndc"]
    d["hierarchy"] = {"stem": g["stem"], "sample_idx": g["sample_idx"], "down": g["down"], "same": g["same"],
                      "key": key}
    d["version"] = 1
    return d


def test_old_format_samples_are_detected_and_regenerated(dataset_dir, tmp_path):
    dataset_dir = shutil.copytree(dataset_dir, tmp_path / "ds")
    path = sample_path(dataset_dir, 2)
    torch.save(_as_version_1(torch.load(path, weights_only=True)), path)
    with pytest.raises(InputError, match=f"{path.name}.*version 1, expected 2"):
        load_sample(path)
    report = build_dataset(dataset_dir, 3, SMALL, seed=4)
    assert (report.generated, report.skipped) == (0, 2)
    assert [(os.path.basename(p), "version 1" in why) for p, why in report.regenerated] == [(path.name, True)]
    assert_samples_equal(load_sample(path), make_sample(2, SMALL, seed=4))


def test_old_format_dataset_folders_are_refused_or_rebuilt(dataset_dir, tmp_path):
    dataset_dir = shutil.copytree(dataset_dir, tmp_path / "ds")
    manifest = json.loads((dataset_dir / "dataset.json").read_text())
    assert manifest["sample_version"] == 2
    assert manifest["neighbourhood"] == NeighbourhoodConfig().to_dict()  # by name
    assert manifest["neighbourhood_key"] == NeighbourhoodConfig().key
    # as an older version wrote it: no sample format, another config key, version-1 samples
    old = {k: v for k, v in manifest.items() if k not in ("sample_version", "neighbourhood", "neighbourhood_key")}
    (dataset_dir / "dataset.json").write_text(json.dumps({**old, "config_key": "0123456789abcdef"}))
    for i in range(3):
        path = sample_path(dataset_dir, i)
        torch.save(_as_version_1(torch.load(path, weights_only=True)), path)
    with pytest.raises(InputError, match="format version 1.*rebuild"):
        TrainDataset(dataset_dir)
    with pytest.raises(InputError, match="another folder"):
        build_dataset(dataset_dir, 3, SMALL, seed=5)  # another dataset: not overwritten
    report = build_dataset(dataset_dir, 3, SMALL, seed=4)
    assert (report.generated, report.skipped, len(report.regenerated)) == (0, 0, 3)
    ds = TrainDataset(dataset_dir, neighbourhood=NeighbourhoodConfig())
    assert_samples_equal(ds[0], make_sample(0, SMALL, seed=4))


def test_dataset_folder_mismatches_are_reported(dataset_dir, tmp_path):
    with pytest.raises(InputError, match="dataset.json.*another folder"):
        build_dataset(dataset_dir, 1, SMALL, seed=5)
    with pytest.raises(InputError, match="no dataset.json"):
        TrainDataset(tmp_path)
    with pytest.raises(InputError, match="neighbourhood.*differing: k 16 vs 8"):
        TrainDataset(dataset_dir, neighbourhood=NeighbourhoodConfig(k=8))
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "dataset.json").write_text((dataset_dir / "dataset.json").read_text())
    with pytest.raises(InputError, match="missing"):
        TrainDataset(copy)
