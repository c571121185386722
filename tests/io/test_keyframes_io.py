"""Keyframe files (stylize3d_core/io/keyframes.py): camera-path JSON with a timing block, round trips."""

from __future__ import annotations

import json

import numpy as np
import pytest

from stylize3d_core.errors import InputError
from stylize3d_core.geometry.keyframes import Keyframe, KeyframePath, interpolate_keyframes
from stylize3d_core.io.camera_path import load_camera_path, save_camera_path
from stylize3d_core.io.keyframes import load_keyframes, save_keyframes


def path3() -> KeyframePath:
    ms = []
    for i, (yaw, t) in enumerate(((0.0, 0.0), (0.2, 0.05), (-0.1, 0.1))):
        m = np.eye(4)
        m[:3, :3] = [[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]]
        m[:3, 3] = [t, 0.01 * i, 0.1 * i]
        ms.append(Keyframe(m, 55.0 + 5 * i))
    return KeyframePath(tuple(ms), (1.0, 2.5, 1.0), loop=True)


def test_keyframes_round_trip_and_read_as_a_camera_path(tmp_path):
    kp = path3()
    f = save_keyframes(tmp_path / "keys.json", kp, fps=24, image_size=(480, 640))
    back, fps = load_keyframes(f)
    assert fps == 24 and back.durations_s == kp.durations_s and back.loop
    for a, b in zip(back.keyframes, kp.keyframes):
        assert np.array_equal(a.cam_to_world, b.cam_to_world) and a.fov_y_deg == b.fov_y_deg
    assert len(load_camera_path(f).cameras) == 3  # any camera-path reader sees the keyframes
    # The interpolated path round-trips through the camera-path format exactly.
    cams = interpolate_keyframes(kp, 24)
    g = save_camera_path(tmp_path / "path.json", cams, fps=24)
    again = load_camera_path(g).cameras
    assert np.array_equal(again.cam_to_world.numpy(), cams.cam_to_world.numpy())
    # A plain camera path reads as keyframes one second apart.
    plain, _ = load_keyframes(g)
    assert len(plain.keyframes) == len(cams) and set(plain.durations_s) == {1.0} and not plain.loop


def test_bad_timing_block_names_the_file(tmp_path):
    f = save_keyframes(tmp_path / "keys.json", path3())
    doc = json.loads(f.read_text())
    doc["keyframes"]["durations_s"] = [1.0]
    bad = tmp_path / "bad_keys.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="bad_keys.json"):
        load_keyframes(bad)
    doc["keyframes"] = {"durations_s": [1, 1, 1], "loop": "yes"}
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="bad_keys.json.*loop"):
        load_keyframes(bad)
