"""Write the seed corpus of every fuzz target into tests/fuzz/corpus/ (small, valid inputs).

    python tests/fuzz/make_corpus.py

The corpus is committed; rerun this only to change the seeds.
"""

from __future__ import annotations

import base64
import io
import json
from pathlib import Path

import cv2
import numpy as np
import torch
from PIL import Image

HERE = Path(__file__).resolve().parent

from stylize3d_core.geometry.camera import Cameras  # noqa: E402
from stylize3d_core.io.camera_path import save_camera_path, save_open3d_trajectory  # noqa: E402
from stylize3d_core.io.depth_files import write_pfm  # noqa: E402
from stylize3d_core.models.checkpoint import FORMAT, VERSION, config_to_json  # noqa: E402
from stylize3d_core.models.stylize3d import ModelConfig  # noqa: E402


def seeds(tmp: Path) -> dict:
    out = {}
    angle = 0.3
    pose = torch.eye(4, dtype=torch.float64).repeat(2, 1, 1)
    pose[1, :3, :3] = torch.tensor([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    pose[1, :3, 3] = torch.tensor([0.1, -0.2, 0.05])
    cams = Cameras(pose, torch.tensor([60.0, 45.5], dtype=torch.float64))
    save_camera_path(tmp / "c.json", cams, fps=24, image_size=(48, 64))
    save_open3d_trajectory(tmp / "o.json", cams, 48, 64)
    out["camera_path"] = {"stylize3d": b"\0" + (tmp / "c.json").read_bytes(),
                          "open3d": b"\3" + (tmp / "o.json").read_bytes()}

    depth = (1.0 + np.add.outer(np.arange(6), np.arange(8)) / 4.0).astype(np.float32)  # (6, 8)
    png = cv2.imencode(".png", (depth * 1000).astype(np.uint16))[1].tobytes()
    npy = io.BytesIO()
    np.save(npy, depth)
    write_pfm(tmp / "d.pfm", depth)
    tif = io.BytesIO()
    Image.fromarray((depth * 1000).astype(np.uint16)).save(tif, format="TIFF")
    out["depth_file"] = {"png16": b"\0" + png, "npy": b"\1" + npy.getvalue(),
                         "pfm": b"\2" + (tmp / "d.pfm").read_bytes(), "tiff": b"\3" + tif.getvalue()}

    photo = io.BytesIO()
    Image.fromarray(np.full((16, 16, 3), 128, np.uint8)).save(photo, format="JPEG", quality=50)
    dn = cv2.imencode(".png", np.tile(np.arange(0, 256, 32, dtype=np.uint8), (8, 1)))[1].tobytes()
    ns = ('xmlns:GDepth="http://ns.google.com/photos/1.0/depthmap/" '
          'xmlns:xmpNote="http://ns.adobe.com/xmp/note/"')
    std = ('<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
           f'<rdf:Description rdf:about="" {ns} GDepth:Format="RangeInverse" GDepth:Near="0.5" GDepth:Far="10" '
           f'GDepth:Mime="image/png" GDepth:Units="m" GDepth:Data="{base64.b64encode(dn).decode()}"/>'
           "</rdf:RDF></x:xmpmeta>").encode()
    app1 = b"http://ns.adobe.com/xap/1.0/\x00" + std
    jpeg = photo.getvalue()
    out["phone_jpeg"] = {"gdepth": jpeg[:2] + b"\xff\xe1" + (len(app1) + 2).to_bytes(2, "big") + app1 + jpeg[2:],
                         "plain": jpeg}

    config = config_to_json(ModelConfig.lite())
    header = {"__metadata__": {"format": FORMAT, "version": VERSION, "config": config, "stage": "1", "info": "{}"},
              "w": {"dtype": "F32", "shape": [2], "data_offsets": [0, 8]}}
    text = json.dumps(header).encode()
    text += b" " * (-len(text) % 8)
    st = len(text).to_bytes(8, "little") + text + np.zeros(2, np.float32).tobytes()
    out["checkpoint"] = {"file": b"\0" + st, "config": b"\1" + config.encode()}
    return out


def main() -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        for target, files in seeds(Path(tmp)).items():
            folder = HERE / "corpus" / target
            folder.mkdir(parents=True, exist_ok=True)
            for name, data in files.items():
                (folder / name).write_bytes(data)
                print(f"{folder / name}: {len(data)} bytes")


if __name__ == "__main__":
    main()
