"""Runs exports of every output format under one injected fault and prints what happened as JSON.

    python tests/app/fault_driver.py MODE WORK PHOTO

MODE is ``tmpfs`` (a small tmpfs mounted on WORK/disk, nearly filled: run it
inside ``unshare -rm``), ``fsize`` (RLIMIT_FSIZE far below the new outputs'
sizes) or ``unwritable`` (WORK/disk made read-only for this user: run it
without CAP_DAC_OVERRIDE when root). For each format it first writes a good
output with no fault, then applies the fault and exports again over it through
``stylize3d_app.cli.main``; it reports the exit status, whether the old output is still
byte-identical, what else is in the folder, and stderr. Used by test_faults.py.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

from stylize3d_app.cli import main

FORMATS = {  # name -> (destination relative to the faulty folder, extra argv given that path)
    "mp4": ("v.mp4", lambda d, out: ["-o", str(d / "v.mp4")]),
    "gif": ("v.gif", lambda d, out: ["-o", str(d / "v.gif")]),
    "png": ("frames", lambda d, out: ["-o", str(d / "frames") + "/"]),
    "ply": ("c.ply", lambda d, out: ["--save-ply", str(d / "c.ply"), "-o", str(out / "v.mp4")]),
    "json": ("c.json", lambda d, out: ["--save-camera-path", str(d / "c.json"), "-o", str(out / "v.mp4")]),
}
FSIZE_LIMIT = 2 * 1024


def snapshot(path: Path) -> dict:
    """name -> bytes of a file, or of every file in a folder."""
    if path.is_dir():
        return {p.name: p.read_bytes().hex() for p in sorted(path.iterdir())}
    return {path.name: path.read_bytes().hex()}


def run(argv) -> tuple:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, err.getvalue()


def fill(disk: Path, leave: int = 8 * 1024) -> None:
    """Fill the file system of ``disk`` until about ``leave`` bytes are free."""
    chunk = b"\0" * 4096
    with open(disk / "filler", "wb", buffering=0) as fh:
        try:
            while True:
                fh.write(chunk)
        except OSError:
            pass
    size = (disk / "filler").stat().st_size
    os.truncate(disk / "filler", max(0, size - leave))


def main_driver(mode: str, work: Path, photo: Path) -> dict:
    disk, outside = work / "disk", work / "outside"
    disk.mkdir(exist_ok=True)
    outside.mkdir(exist_ok=True)
    if mode == "tmpfs":
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(disk)], check=True)
    small = ["render", str(photo), "--frames", "2", "--size", "32", "-q"]
    big = ["render", str(photo), "--frames", "10", "--size", "128", "-q"]
    for argv in (["-o", str(disk / "v.mp4"), "--save-ply", str(disk / "c.ply"), "--save-camera-path",
                  str(disk / "c.json")], ["-o", str(disk / "v.gif")], ["-o", str(disk / "frames") + "/"]):
        rc, err = run(small + argv)  # the good outputs, written with no fault
        assert rc == 0, (argv, err)
    old = {name: snapshot(disk / rel) for name, (rel, _) in FORMATS.items()}
    before = sorted(os.listdir(disk))
    if mode == "tmpfs":
        fill(disk)
    elif mode == "fsize":
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG (ffmpeg too)
        resource.setrlimit(resource.RLIMIT_FSIZE, (FSIZE_LIMIT, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    elif mode == "unwritable":
        os.chmod(disk, 0o555)
        for rel, _ in FORMATS.values():
            if (disk / rel).is_dir():
                os.chmod(disk / rel, 0o555)
    report = {}
    for name, (rel, args) in FORMATS.items():
        rc, err = run(big + args(disk, outside))
        left = sorted(set(os.listdir(disk)) - {"filler"})
        report[name] = {"rc": rc, "intact": snapshot(disk / rel) == old[name], "left": left,
                        "expected_left": before, "stderr": err}
    return report


if __name__ == "__main__":
    result = main_driver(sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]))
    sys.stdout.write("FAULTS " + json.dumps(result) + "\n")
