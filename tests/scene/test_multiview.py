"""Merging views: the frame of the centre view, thinning of duplicates, the pose check."""

import numpy as np
import pytest

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.eval.multiview import look_pose, procedural_views
from stylize3d_core.geometry.camera import NEAR_DEPTH
from stylize3d_core.scene.ldi import ORIGINAL
from stylize3d_core.scene.multiview import View, merge_views, pose_in_view
from stylize3d_core.scene.photo3d import Photo3D, Photo3DSettings


@pytest.fixture(scope="module")
def data():
    return procedural_views(3)


def test_merged_cloud_is_in_the_centre_views_frame(data):
    merged = merge_views(data.views, 1)
    photo = merged.photo
    assert photo.size == data.views[1].rgb.shape[:2] and photo.rgb is not None
    own = merged.view_of_point == 1
    assert np.array_equal(photo.points.rgb[own & (photo.points.label == ORIGINAL)],
                          photo.ldi.rgb[photo.ldi.photo_region].reshape(-1, 3))  # the centre's points, as they are
    z = photo.points.xyz[own & (photo.points.label == ORIGINAL), 2]
    assert np.percentile(z, 1) == pytest.approx(NEAR_DEPTH, rel=0.05)
    assert all(k > 0 for k in merged.kept) and min(merged.agreement) > 0.9
    assert np.isfinite(photo.points.xyz).all() and photo.points.xyz[:, 2].min() > 0


def test_overlap_is_thinned(data):
    two = [data.views[0], View(data.views[0].rgb, data.views[0].depth, data.views[0].cam_to_world, 55.0, "copy.png")]
    merged = merge_views(two, 0)
    assert merged.kept[1] < 0.02 * merged.kept[0]  # the same view again adds (almost) nothing


def test_a_wrong_pose_is_refused(data):
    views = list(data.views)
    views[1] = View(views[1].rgb, views[1].depth, data.views[2].cam_to_world, 55.0, "view1.png")
    with pytest.raises(InputError, match="view1.png: its pose does not match the images"):
        merge_views(views, 0)


def test_bad_views():
    rgb = np.zeros((20, 30, 3), np.float32)
    depth = DepthMap(np.ones((20, 30), np.float32), np.ones((20, 30), bool), "metric", "d")
    skew = np.eye(4)
    skew[0, 1] = 0.5
    with pytest.raises(InputError, match="not a rigid transform"):
        View(rgb, depth, skew, 50.0, "a.png")
    small = DepthMap(np.ones((10, 30), np.float32), np.ones((10, 30), bool), "metric", "d")
    with pytest.raises(InputError, match="depth is"):
        View(rgb, small, np.eye(4), 50.0, "a.png")
    with pytest.raises(InputError, match="no views"):
        merge_views([], 0)
    with pytest.raises(InputError, match="centre"):
        merge_views([View(rgb, depth, np.eye(4), 50.0, "a.png")], 3)


def test_pose_in_view_scales_translations():
    v = View(np.zeros((20, 30, 3), np.float32),
             DepthMap(np.ones((20, 30), np.float32), np.ones((20, 30), bool), "metric", "d"),
             look_pose(1.0), 50.0, "a.png")
    T = pose_in_view(look_pose(1.5), v, 2.0)
    assert np.allclose(T[:3, 3], [1.0, 0, 0]) and np.allclose(T[:3, :3], np.eye(3))


def test_no_invented_point_hides_what_another_view_saw(data):
    merged = merge_views(data.views, 0)
    pts = merged.photo.points
    invented = pts.label != ORIGINAL
    assert invented.any()
    centre = data.views[0]
    for j, v in enumerate(data.views):
        single = Photo3D.build(v.rgb, v.depth, Photo3DSettings(fov_y_deg=v.fov_y_deg))
        mine = invented & (merged.view_of_point != j)
        T = np.linalg.inv(v.cam_to_world) @ centre.cam_to_world  # centre camera -> view j
        local = ((pts.xyz[mine] / merged.photo.ldi.depth_scale) @ T[:3, :3].T + T[:3, 3]) * single.ldi.depth_scale
        h, w = single.size
        f = (h / 2) / np.tan(np.radians(v.fov_y_deg) / 2)
        u = local[:, 0] / local[:, 2] * f + w / 2
        r = local[:, 1] / local[:, 2] * f + h / 2
        inside = (local[:, 2] > 0) & (u >= 0) & (u < w) & (r >= 0) & (r < h)
        surface = single.ldi.depth[single.ldi.photo_region][r[inside].astype(int), u[inside].astype(int)]
        # in view j's photo, an invented point of another view lies behind what view j saw (it may hide there)
        assert (local[inside, 2] > surface * 1.05).all(), (j, int((local[inside, 2] <= surface * 1.05).sum()))
