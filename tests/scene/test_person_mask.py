"""The automatic person mask (scene.masks.person_mask: MediaPipe's selfie segmentation as ONNX) and its
uses: ``--mask person`` end to end, the layer settings, the viewer's work function."""

import cv2
import imageio.v3 as iio
import numpy as np
import onnx
import pytest
import torch
from PIL import Image

from stylize3d_core.errors import InputError
from stylize3d_core.export.layered import PERSON, LayerSettings
from stylize3d_core.io.images import save_image
from stylize3d_core.models.checkpoint import save_checkpoint
from stylize3d_core.models.stylize3d import ModelConfig, Stylize3DModel
from stylize3d_core.resources import sample_photo
from stylize3d_core.scene import masks
from stylize3d_core.scene.masks import person_mask, person_probability


def _photo(name):
    return np.asarray(Image.open(sample_photo(name)).convert("RGB"))


@pytest.fixture(scope="module")
def astronaut():
    return _photo("astronaut.jpg")


def test_the_shipped_model_is_the_converted_selfie_network():
    session = masks._person_session()
    model = onnx.load(session._model_path)
    onnx.checker.check_model(model)
    props = {p.key: p.value for p in model.metadata_props}
    assert props["source_sha256"].startswith("9ee168ec")  # the .tflite in the mediapipe 0.10.21 wheel
    assert "Apache-2.0" in props["source"]
    (inp,), (out,) = session.get_inputs(), session.get_outputs()
    assert inp.shape == [1, 256, 256, 3] and out.shape == [1, 256, 256, 1]
    assert "ConvTranspose" in {n.op_type for n in model.graph.node}  # MediaPipe's custom op, rebuilt


def test_astronaut_mask_covers_the_person_not_the_corners(astronaut):
    h, w = astronaut.shape[:2]
    mask = person_mask(astronaut)
    assert mask.shape == (h, w) and mask.dtype == bool
    face_torso = mask[int(0.05 * h):int(0.9 * h), int(0.35 * w):int(0.6 * w)]  # her hair to the suit's chest
    assert face_torso.mean() > 0.9, face_torso.mean()
    for corner in (mask[: h // 5, : w // 5], mask[: h // 5, -w // 5:]):  # the flag and the shuttle model
        assert corner.mean() < 0.05, corner.mean()
    assert 0.35 < mask.mean() < 0.75


def test_photos_without_people_give_little_or_nothing():
    rocket = person_mask(_photo("rocket.jpg"))
    assert rocket.mean() < 0.01
    blank = np.full((120, 160, 3), 0.5, np.float32)  # a plain grey image
    assert person_mask(blank).mean() < 0.01


def test_a_person_moved_in_the_frame_moves_the_mask(astronaut):
    """A synthetic case: the astronaut pasted small into a grey canvas, right of centre."""
    canvas = np.full((400, 600, 3), 128, np.uint8)
    small = np.asarray(Image.fromarray(astronaut).resize((256, 256), Image.BILINEAR))
    canvas[144:400, 300:556] = small
    mask = person_mask(canvas)
    inside = mask[144:400, 300:556]
    assert inside[20:220, 90:150].mean() > 0.8  # her face and torso
    outside = mask.copy()
    outside[144:400, 300:556] = False
    assert outside.mean() < 0.02


def test_input_forms_and_bad_inputs(astronaut):
    as_float = person_mask(astronaut / 255.0)
    as_uint8 = person_mask(astronaut)
    assert (as_float != as_uint8).mean() < 0.001  # [0, 1] floats and uint8 are the same photo
    grey = person_mask(np.asarray(Image.fromarray(astronaut).convert("L")))
    assert grey.shape == astronaut.shape[:2] and grey.dtype == bool  # (H, W) grey works
    prob = person_probability(astronaut)
    assert prob.dtype == np.float32 and np.isfinite(prob).all() and 0 <= prob.min() and prob.max() <= 1
    with pytest.raises(InputError, match="too small to find a person"):
        person_mask(np.zeros((8, 40, 3), np.uint8))
    with pytest.raises(InputError, match=r"\(H, W, 3\)"):
        person_mask(np.zeros((40, 40, 4), np.uint8))
    bad = np.zeros((40, 40, 3), np.float32)
    bad[3, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        person_mask(bad)


def test_layer_settings_take_person_as_a_mask_source():
    s = LayerSettings(mask=PERSON)
    assert s.active and s.mask_file is None
    assert LayerSettings(mask="m.png").mask_file == "m.png"
    with pytest.raises(InputError, match="not both"):
        LayerSettings(mask=PERSON, mask_rect="1,2,3,4")


@pytest.fixture(scope="module")
def untrained(tmp_path_factory):
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("model") / "untrained.safetensors"
    save_checkpoint(path, Stylize3DModel(ModelConfig.lite()), 1, {"note": "untrained, for tests"})
    return path


def test_mask_person_end_to_end(astronaut, untrained, tmp_path):
    from stylize3d_app.cli import main

    photo = tmp_path / "astronaut.png"
    Image.fromarray(astronaut).resize((96, 96), Image.BILINEAR).save(photo)
    style = tmp_path / "style.png"
    save_image(style, np.random.default_rng(0).random((48, 48, 3)))
    out = tmp_path / "frames"
    assert main(["render", str(photo), "--style", str(style), "--model", str(untrained), "--mask", "person",
                 "--trajectory", "static", "--frames", "1", "--size", "96", "-o", str(out) + "/", "-q"]) == 0
    frame = iio.imread(out / "frame_0000.png").astype(float)
    src = iio.imread(photo).astype(float)
    assert frame.shape == src.shape
    person = person_mask(src.astype(np.uint8))  # what the render used: the photo is loaded at its size
    core = cv2.erode(person.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert core.mean() > 0.2
    assert np.abs(frame[core] - src[core]).mean() < 3  # the person keeps her colours
    far = ~cv2.dilate(person.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    assert far.mean() > 0.1 and np.abs(frame[far] - src[far]).mean() > 10  # the background is stylized


def test_mask_person_with_no_person_is_a_clear_error(untrained, tmp_path, capsys):
    from stylize3d_app.cli import main

    photo = tmp_path / "rocket.png"
    Image.open(sample_photo("rocket.jpg")).resize((96, 64)).save(photo)
    style = tmp_path / "style.png"
    save_image(style, np.random.default_rng(0).random((48, 48, 3)))
    code = main(["render", str(photo), "--style", str(style), "--model", str(untrained), "--mask", "person",
                 "--frames", "1", "--size", "64", "-o", str(tmp_path / "o.mp4")])
    assert code == 2 and "--mask person found no person in the photo" in capsys.readouterr().err
    assert not (tmp_path / "o.mp4").exists()


def test_viewer_person_item_makes_the_layers(untrained):
    import stylize3d_app.viewer.applications as A
    from stylize3d_app.viewer.session import ViewerSession
    from stylize3d_core.pipeline import PhotoSpec

    from stylize3d_app.viewer.panel import MENU_RECENT_PHOTO, MENU_RECENT_STYLE
    from stylize3d_app.viewer.settings import MAX_RECENT

    ids = {A.MENU_PERSON, A.MENU_GRABCUT, A.MENU_VIEWS, A.MENU_PATH_LOAD}
    recent = set(range(MENU_RECENT_PHOTO, MENU_RECENT_PHOTO + MAX_RECENT)) | \
        set(range(MENU_RECENT_STYLE, MENU_RECENT_STYLE + MAX_RECENT))
    assert len(ids) == 4 and not ids & recent  # the window binds every id: no item may share one
    s = ViewerSession(str(untrained))
    with pytest.raises(InputError, match="open a photo first"):
        A.layers_by_person(s, 0.0)
    s.load_photo(PhotoSpec(str(sample_photo("astronaut.jpg")), "prior", max_size=128))
    layers = A.layers_by_person(s, 0.25)
    assert s.layers is layers and layers.source == "person segmentation"
    assert layers.mask.shape == tuple(s.photo.size) and 0.35 < layers.fraction < 0.75
    assert layers.foreground_strength == pytest.approx(0.25)
    s.load_photo(PhotoSpec(str(sample_photo("rocket.jpg")), "prior", max_size=128))
    with pytest.raises(InputError, match="found no person"):
        A.layers_by_person(s, 0.0)


def test_viewer_controller_person_item(untrained):
    """The Applications menu's "Foreground: person (automatic)" through the controller, with the
    stand-in window of tests/support/viewer_app_helpers.py (its worker runs each task at once)."""
    import stylize3d_app.viewer.applications as A
    from stylize3d_app.viewer.session import ViewerSession
    from stylize3d_core.pipeline import PhotoSpec
    from viewer_app_helpers import StandInWindow  # tests/support

    s = ViewerSession(str(untrained))
    s.load_photo(PhotoSpec(str(sample_photo("astronaut.jpg")), "prior", max_size=128))
    window = StandInWindow(s)
    c = window.applications
    assert A.MENU_PERSON in c.menu_callbacks()
    c.person()
    assert not window.errors, window.errors
    assert s.layers.source == "person segmentation" and c.mask_source == "person segmentation"
    assert "Foreground from person segmentation: 5" in window.status  # 54 % of the astronaut
