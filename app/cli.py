"""The ``stylize3d`` command line: thin subcommands over the library's job dataclasses.

    stylize3d render PHOTO [--depth SPEC] [--trajectory circle] [--frames 90]
                           [--fps 30] [--size 512] [-o out.mp4] [--save-ply FILE]

Exit status: 0 on success, 2 for bad input (the message names the file or the
setting), 1 when an output could not be written, 130 when interrupted.
"""

from __future__ import annotations

import argparse
import sys
from typing import List, Optional, get_args

from stylize3d_core.errors import ExportError, InputError, Stylize3DError
from stylize3d_core.geometry.trajectories import TrajectoryName
from stylize3d_core.io.video import ExportCancelled, console_progress
from stylize3d_core.pipeline import RenderJob, run_render

PROG = "stylize3d"


def _add_render(sub: "argparse._SubParsersAction") -> None:
    d = RenderJob(photo="")
    p = sub.add_parser(
        "render",
        help="render a 3D photo along a camera path into a video",
        description="Turn PHOTO into a 3D photo and render it along a camera path "
        "(currently the plain, unstylized 3D photo).",
    )
    p.add_argument("photo", help="the photo: JPEG, PNG, WebP or TIFF")
    p.add_argument("-o", "--output", default=d.output,
                   help=f"video to write: .mp4, .gif, or a folder (ending in /) for PNG frames (default {d.output})")
    p.add_argument("--depth", default=d.depth, metavar="SPEC",
                   help="depth source: auto (default: phone depth, else the built-in prior), prior, "
                        "a depth file (PNG16/NPY/PFM/TIFF/EXR; append :disparity for disparity), "
                        "onnx:MODEL.onnx, stereo:RIGHT_IMAGE, stereo:sbs")
    p.add_argument("--trajectory", default=d.trajectory, choices=get_args(TrajectoryName),
                   help=f"camera path shape (default {d.trajectory})")
    p.add_argument("--frames", type=int, default=d.frames, help=f"number of frames (default {d.frames})")
    p.add_argument("--fps", type=float, default=d.fps, help=f"frames per second (default {d.fps:g})")
    p.add_argument("--size", type=int, default=d.size,
                   help=f"long side of the output frames in pixels (default {d.size})")
    p.add_argument("--max-size", type=int, default=d.max_size,
                   help=f"shrink the photo so its long side is at most this (default {d.max_size})")
    p.add_argument("--fov", type=float, default=None,
                   help="vertical field of view of the photo in degrees (default: from EXIF, else 60)")
    p.add_argument("--supersample", type=int, choices=(1, 2), default=d.supersample,
                   help=f"1 = sharp and fast, 2 = smoother when the camera moves away (default {d.supersample})")
    p.add_argument("--camera-path", default=None, metavar="JSON",
                   help="follow the cameras of this camera-path JSON instead of --trajectory/--frames")
    p.add_argument("--save-camera-path", default=None, metavar="JSON", help="also write the cameras used")
    p.add_argument("--save-ply", default=None, metavar="FILE", help="also write the coloured point cloud (PLY)")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description="Stylized 3D photos from one photo.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_render(sub)
    return parser


def _render(args: argparse.Namespace) -> int:
    job = RenderJob(
        photo=args.photo, output=args.output, depth=args.depth, trajectory=args.trajectory,
        frames=args.frames, fps=args.fps, size=args.size, max_size=args.max_size, fov=args.fov,
        supersample=args.supersample, camera_path=args.camera_path,
        save_camera_path=args.save_camera_path, save_ply=args.save_ply,
    )
    log = (lambda _msg: None) if args.quiet else (lambda msg: print(f"{PROG}: {msg}", file=sys.stderr))
    progress = None if args.quiet else console_progress("render")
    result = run_render(job, progress=progress, log=log)
    if not args.quiet:
        t = result.timings
        stages = ", ".join(f"{k} {v:.2f}s" for k, v in t.items())
        print(f"{PROG}: done ({stages})", file=sys.stderr)
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit status."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "render":
            return _render(args)
    except InputError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    except ExportCancelled:
        print(f"{PROG}: cancelled; nothing was written", file=sys.stderr)
        return 130
    except ExportError as e:
        print(f"{PROG}: could not write output: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; nothing was written", file=sys.stderr)
        return 130
    except Stylize3DError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 1
    raise AssertionError(f"unhandled command {args.command!r}")  # argparse guarantees a known command


def entrypoint() -> None:
    """Console-script entry point (see pyproject.toml)."""
    sys.exit(main())


if __name__ == "__main__":
    entrypoint()
