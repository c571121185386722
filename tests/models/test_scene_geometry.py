"""The shared geometry recipe (``models/scene_geometry.py``) and its neighbourhood config."""

import dataclasses

import pytest
import torch

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.ndc import ndc_params, to_ndc
from stylize3d_core.models.scene_geometry import (
    NeighbourhoodConfig,
    build_hierarchy,
    encoder_subset,
    prepare_geometry,
    radius_scale,
)
from stylize3d_core.points import ball_query, farthest_point_sample, idw_neighbours
from stylize3d_core.points.reference import ball_query_reference, knn_reference


def test_config_by_name_round_trips_and_keys_by_field():
    cfg = NeighbourhoodConfig(k=8, stage_radii=((0.02, 0.03), (0.04, 0.05)), upsample_k=4, max_points=1000)
    d = cfg.to_dict()
    assert d["k"] == 8 and d["stage_radii"] == [[0.02, 0.03], [0.04, 0.05]] and d["max_points"] == 1000
    assert NeighbourhoodConfig.from_dict(d) == cfg
    assert NeighbourhoodConfig.from_dict(dict(reversed(list(d.items())))).key == cfg.key  # order-free
    assert NeighbourhoodConfig.from_dict({}) == NeighbourhoodConfig()  # missing fields: the defaults
    keys = {NeighbourhoodConfig().key}
    for f in dataclasses.fields(NeighbourhoodConfig):
        value = getattr(NeighbourhoodConfig(), f.name)
        other = value * 2 if isinstance(value, float) else value + 1 if isinstance(value, int) else None
        changed = {"stage_radii": ((0.015, 0.025), (0.025, 0.06)), "downsample": (4, 2)}.get(f.name, other)
        keys.add(dataclasses.replace(NeighbourhoodConfig(), **{f.name: changed}).key)
    assert len(keys) == 1 + len(dataclasses.fields(NeighbourhoodConfig))  # every field is in the key
    with pytest.raises(InputError, match="unknown neighbourhood settings.*'radius'"):
        NeighbourhoodConfig.from_dict({"radius": 0.1}, "file.json")
    with pytest.raises(InputError, match="file.json"):
        NeighbourhoodConfig.from_dict([1, 2], "file.json")
    with pytest.raises(InputError):
        NeighbourhoodConfig.from_dict({"k": 0})


def test_radii_scale():
    stem, stages = NeighbourhoodConfig().radii(2.0)
    assert stem == pytest.approx(0.03)
    assert [list(p) for p in stages] == [pytest.approx([0.03, 0.05]), pytest.approx([0.05, 0.1])]
    for bad in (0.0, -1.0, float("inf"), float("nan")):
        with pytest.raises(InputError, match="radius scale"):
            NeighbourhoodConfig().radii(bad)


def test_scaled_hierarchy_uses_the_scaled_radii():
    xyz = torch.rand(400, 3, generator=torch.Generator().manual_seed(0)) * 0.2
    cfg = NeighbourhoodConfig()
    h = build_hierarchy(xyz, cfg, 2.0)
    assert h.neighbourhood == cfg and h.scale == 2.0 and h.num_stages == 2
    assert torch.equal(h.stem_neighbours, ball_query_reference(xyz, xyz, 0.03, 16).idx)
    assert torch.equal(h.same_neighbours[1], ball_query_reference(h.xyz[2], h.xyz[2], 0.1, 16).idx)


def test_prepare_geometry_is_ndc_subset_hierarchy_and_idw(cloud, cloud_size):
    (pts, fov), size = cloud, cloud_size
    n = pts.xyz.shape[0]
    cfg = NeighbourhoodConfig(max_points=600, upsample_k=4)
    geom = prepare_geometry(pts.xyz, pts.rgb, fov, size, cfg, seed=5)
    params = ndc_params(pts.xyz[:, 2], fov, size[1] / size[0])
    ndc = to_ndc(pts.xyz, params)
    assert tuple(geom.ndc) == tuple(params)
    idx = encoder_subset(n, 600, 5)
    assert idx.numel() == 600 and bool((idx[1:] > idx[:-1]).all()) and torch.equal(geom.encoder_idx, idx)
    assert torch.equal(idx, torch.randperm(n, generator=torch.Generator().manual_seed(5))[:600].sort().values)
    scale = radius_scale(size, 600, n)
    ref = build_hierarchy(ndc[idx], cfg, scale)
    assert geom.hierarchy.scale == scale and geom.hierarchy.num_points == ref.num_points
    for a, b in zip((geom.hierarchy.stem_neighbours, *geom.hierarchy.sample_idx, *geom.hierarchy.down_neighbours),
                    (ref.stem_neighbours, *ref.sample_idx, *ref.down_neighbours)):
        assert torch.equal(a, b)
    assert geom.upsample.idx.shape == (n, 4)
    up = idw_neighbours(ndc, ref.xyz[-1], 4)
    assert torch.equal(geom.upsample.idx, up.idx) and torch.equal(geom.upsample.weight, up.weight)
    chosen = (ndc[:, None] - ref.xyz[-1][geom.upsample.idx]).square().sum(-1)  # (n, 4), ties aside the 4-NN
    torch.testing.assert_close(chosen, knn_reference(ref.xyz[-1], ndc, 4).sq_dist.float(), rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(geom.upsample.weight.sum(1), torch.ones(n))
    # the density scaling follows reference_points_across
    half = prepare_geometry(pts.xyz, pts.rgb, fov, size, dataclasses.replace(cfg, reference_points_across=256), seed=5)
    assert half.hierarchy.scale == pytest.approx(scale / 2)
    # below max_points every point is encoded, whatever the seed
    small = prepare_geometry(pts.xyz, pts.rgb, fov, size, NeighbourhoodConfig(), seed=9)
    assert torch.equal(small.encoder_idx, torch.arange(n))


@pytest.mark.parametrize("stages", [((4, 4), ((0.015, 0.025), (0.025, 0.05))), ((3, 2, 5), ((0.2, 0.1), (0.3, 0.35), (0.4, 0.5))),
                                    ((), ())])
def test_hierarchy_equals_one_search_per_ball(cloud, cloud_size, stages):
    # build_hierarchy reuses each level's k-NN search for the next stage's down balls and runs the FPS in a
    # thread; the textbook recipe makes one search per ball query: the same indices, ties and all (a
    # pixel grid has many equidistant points)
    (pts, fov), size = cloud, cloud_size
    factors, radii = stages
    cfg = NeighbourhoodConfig(k=10, stem_radius=0.1, stage_radii=radii, downsample=factors)
    xyz = to_ndc(pts.xyz, ndc_params(pts.xyz[:, 2], fov, size[1] / size[0]))  # (N, 3) on the pixel grid
    h = build_hierarchy(xyz, cfg, 1.5)
    assert h.num_stages == len(factors)
    assert torch.equal(h.stem_neighbours, ball_query(xyz, xyz, 0.1 * 1.5, 10).idx)
    prev = xyz
    for s, (factor, (r_down, r_same)) in enumerate(zip(factors, radii)):
        idx = farthest_point_sample(prev, max(1, prev.shape[0] // factor))
        cur = prev[idx]
        assert torch.equal(h.sample_idx[s], idx) and torch.equal(h.xyz[s + 1], cur)
        assert torch.equal(h.down_neighbours[s], ball_query(prev, cur, r_down * 1.5, 10).idx)
        assert torch.equal(h.same_neighbours[s], ball_query(cur, cur, r_same * 1.5, 10).idx)
        prev = cur


def test_prepare_geometry_rejects_bad_input(cloud, cloud_size):
    (pts, fov), size = cloud, cloud_size
    with pytest.raises(InputError, match="NeighbourhoodConfig"):
        prepare_geometry(pts.xyz, pts.rgb, fov, size, {"k": 16})
    with pytest.raises(InputError, match="rgb"):
        prepare_geometry(pts.xyz, pts.rgb[:-1], fov, size)
    with pytest.raises(InputError, match="image_size"):
        prepare_geometry(pts.xyz, pts.rgb, fov, (0, 36))
    with pytest.raises(InputError, match="NeighbourhoodConfig"):
        build_hierarchy(pts.xyz, "paper")


def test_build_hierarchy_validates_at_the_top(cloud, cloud_size):
    # each level's search uses its tree's own array as the query (KNNIndex.self_knn, no second check):
    # a NaN or infinity in the input is still refused by name, and a float64 input gives the float32
    # input's hierarchy (one cast up front)
    (pts, fov), size = cloud, cloud_size
    xyz = to_ndc(pts.xyz, ndc_params(pts.xyz[:, 2], fov, size[1] / size[0]))  # (N, 3)
    cfg = NeighbourhoodConfig(k=8, stem_radius=0.1, stage_radii=((0.1, 0.2),), downsample=(4,))
    for bad in (float("nan"), float("inf")):
        broken = xyz.clone()
        broken[len(xyz) // 2, 1] = bad
        with pytest.raises(InputError, match="xyz_ndc.*NaN or infinite"):
            build_hierarchy(broken, cfg)
    with pytest.raises(InputError, match="xyz_ndc.*floating-point"):
        build_hierarchy(xyz.round().long(), cfg)
    a, b = build_hierarchy(xyz, cfg), build_hierarchy(xyz.double(), cfg)
    for x, y in zip((a.stem_neighbours, *a.sample_idx, *a.down_neighbours, *a.same_neighbours, *a.xyz),
                    (b.stem_neighbours, *b.sample_idx, *b.down_neighbours, *b.same_neighbours, *b.xyz)):
        assert torch.equal(x, y)


def test_work_while_waiting_for_fps_runs_once_and_changes_nothing(cloud, cloud_size, monkeypatch):
    """prepare_geometry's ``while_waiting`` runs once, where the thread would wait for the first FPS (made
    slow here so that the wait surely comes), and the geometry is the one made without it."""
    import time

    import stylize3d_core.models.scene_geometry as sg

    (pts, fov), size = cloud, cloud_size
    cfg = NeighbourhoodConfig(max_points=600)
    plain = prepare_geometry(pts.xyz, pts.rgb, fov, size, cfg, seed=2)
    real = sg._fps_level
    monkeypatch.setattr(sg, "_fps_level", lambda *a: (time.sleep(0.3), real(*a))[1])
    calls = []
    waited = prepare_geometry(pts.xyz, pts.rgb, fov, size, cfg, seed=2, while_waiting=lambda: calls.append(1))
    assert calls == [1]  # two FPS levels, one call
    for a, b in zip(plain.hierarchy, waited.hierarchy):
        if isinstance(a, tuple):
            assert all(torch.equal(x, y) for x, y in zip(a, b))
        elif isinstance(a, torch.Tensor):
            assert torch.equal(a, b)
    assert torch.equal(plain.upsample.idx, waited.upsample.idx) and torch.equal(plain.upsample.weight, waited.upsample.weight)
