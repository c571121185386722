"""The ``stylize3d`` command line: thin subcommands over the library's job dataclasses.

    stylize3d render PHOTO [--depth SPEC] [--trajectory circle] [--frames 90]
                           [--fps 30] [--size 512] [-o out.mp4] [--save-ply FILE]
    stylize3d bench speed|consistency|scaling|stress|skips|targets|floor|quality [--quick] [--out bench/]

Exit status: 0 on success, 2 for bad input (the message names the file or the
setting), 1 when an output could not be written, 3 for an unexpected internal
error (one line; the traceback is saved to a file), 130 when interrupted (143 on
SIGTERM). Start it through :mod:`stylize3d_app.entry`, which handles signals from the first line.
"""

from __future__ import annotations

import argparse
import sys
from typing import List, Optional

from stylize3d_core.errors import ExportError, InputError, Stylize3DError
from stylize3d_core.io.video import ExportCancelled, console_progress
from stylize3d_core.pipeline import RenderJob, run_render

from .options import add_options, from_args
from .signals import PROG, install_signal_handlers, interrupted_message, interrupted_status, show_warning


def _add_render(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser(
        "render",
        help="render a 3D photo along a camera path into a video",
        description="Turn PHOTO into a 3D photo and render it along a camera path, "
        "painted in the style of --style (or plain without it).",
    )
    add_options(p, RenderJob, positional={"photo": None})  # every option is a RenderJob / PhotoSpec field
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


def _add_training(sub: "argparse._SubParsersAction") -> None:
    from stylize3d_core.train.trainer import TrainConfig

    d = TrainConfig()
    p = sub.add_parser("prepare-data", help="generate training samples (pseudo views and procedural scenes)")
    p.add_argument("--out", default="runs/data", help="dataset root; train/ and eval/ go inside (default runs/data)")
    p.add_argument("--samples", type=int, default=2500, help="training samples (default 2500)")
    p.add_argument("--eval-samples", type=int, default=100, help="held-out samples (default 100)")
    p.add_argument("--size", type=int, default=128, help="sample image size in pixels (default 128)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--real", default=None, metavar="DIR",
                   help="a folder with photos/ and paintings/: its training photos join the content photos, its "
                        "held-out ones the eval photos (split by stylize3d_core/train/real_images.py)")
    p.add_argument("--threads", type=int, default=1, help="torch threads while building samples (default 1: fastest on a busy machine)")
    p = sub.add_parser("prepare-styles", help="generate the style bank used by stage-2 training")
    p.add_argument("--out", default=d.styles_dir, help=f"folder (default {d.styles_dir})")
    p.add_argument("--count", type=int, default=300, help="number of style images (default 300)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--real", default=None, metavar="DIR",
                   help="a folder with photos/ and paintings/: its training paintings join the bank "
                        "(split by stylize3d_core/train/real_images.py)")
    p = sub.add_parser("prepare-teacher", help="stage 2: bake the 2D network's stylization of every training "
                                               "sample onto its points (consistent stylized targets)")
    p.add_argument("--data", default=d.data_dir, help=f"training samples (default {d.data_dir})")
    p.add_argument("--styles", default=d.styles_dir, help=f"style bank (default {d.styles_dir})")
    p.add_argument("--out", default="runs/teacher", help="folder (default runs/teacher)")
    p.add_argument("--per-sample", type=int, default=1, help="styles per sample (default 1)")
    p.add_argument("--seed", type=int, default=0)
    p = sub.add_parser("train", help="train (or resume) stage 1 or 2 of the model",
                       description="Train the stylization model. Runs resume from the checkpoint in --out. "
                                   "For several GPUs: torchrun --nproc_per_node=N -m stylize3d_app.cli train ...")
    p.add_argument("--stage", type=int, choices=(1, 2), required=True)
    add_options(p, TrainConfig)  # every TrainConfig field with its help and default, but the four below
    p.add_argument("--weight", action="append", default=[], metavar="NAME=VALUE",
                   help="override a loss weight (LossWeights field, e.g. colour=0); repeatable")
    p.add_argument("--style-stages", default=",".join(map(str, d.style_stages)), metavar="S,S,...",
                   help="stage 2: EfficientNet stages (0-4) of the global style loss "
                        f"(default {','.join(map(str, d.style_stages))})")
    p.add_argument("--style-crop", type=float, nargs=2, default=list(d.style_crop), metavar=("LOW", "HIGH"),
                   help="stage 2: side of the random style crops as a fraction of the style's short side, "
                        f"drawn in [LOW, HIGH] (default {d.style_crop[0]} {d.style_crop[1]}; smaller magnifies "
                        "the strokes)")


def _add_info(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("info", help="versions, threads, where the model and samples are, display and GPU "
                                    "(paste it into a bug report)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")


def _add_models(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("models", help="optional models that are not shipped: download them once")
    msub = p.add_subparsers(dest="models_command", required=True)
    d = msub.add_parser("download", help="download an optional model's weights (needs the network, once)",
                        description="Download the weights of an optional model into the Hugging Face cache, "
                                    "from a pinned revision, with a progress bar; later runs are offline.")
    d.add_argument("model", choices=("depth-anything",),
                   help="depth-anything: Depth Anything V2 Small (Apache-2.0, about 99 MB; needs the depth extra: "
                        "pip install 'stylize3d[depth]')")
    e = msub.add_parser("export-onnx", help="export a downloaded model to ONNX (for --depth onnx:FILE)",
                        description="Export the downloaded Depth Anything to an ONNX file with a fixed input size, "
                                    "checked against the network before it is written; run it with "
                                    "--depth onnx:FILE:depth_anything (no Transformers needed then).")
    e.add_argument("model", choices=("depth-anything",), help="the downloaded model to export")
    e.add_argument("output", help="the .onnx file to write")
    e.add_argument("--size", default="518x518", metavar="HxW",
                   help="the graph's input, multiples of 14 (default 518x518; the photo is stretched to it)")


def _models(args: argparse.Namespace) -> int:
    from stylize3d_core.depth import depth_anything

    if args.models_command == "export-onnx":
        try:
            size = tuple(int(v) for v in args.size.lower().split("x"))
        except ValueError:
            size = ()
        if len(size) != 2:
            raise InputError("--size", f"expected HEIGHTxWIDTH such as 518x518, got {args.size!r}")
        gap = depth_anything.export_onnx(args.output, size)
        print(f"{PROG}: wrote {args.output} ({size[0]}x{size[1]} input; matches the network within {gap:.1e} of "
              f"its range); use --depth onnx:{args.output}:depth_anything", file=sys.stderr)
        return 0

    folder = depth_anything.cached_folder()
    if folder is not None:
        print(f"{PROG}: {depth_anything.MODEL_ID} at {depth_anything.REVISION[:12]} is already in {folder}",
              file=sys.stderr)
        return 0
    folder = depth_anything.download()
    print(f"{PROG}: {depth_anything.MODEL_ID} at {depth_anything.REVISION[:12]} saved in {folder}; "
          "use --depth depth-anything (auto uses it from now on)", file=sys.stderr)
    return 0


BENCH_SUITES = ("speed", "consistency", "scaling", "stress", "skips", "targets", "floor", "quality")


def _add_bench(sub: "argparse._SubParsersAction") -> None:
    p = sub.add_parser("bench", help="measure speed against quality, the targets, the floor, consistency, "
                                     "scaling, skipped work; run the numerical stress cases",
                       description="Write Markdown + JSON tables and PNG plots to --out "
                                   "(see stylize3d_core/bench/). Figures on a busy machine are pessimistic.")
    p.add_argument("suite", choices=BENCH_SUITES, help="what to measure")
    p.add_argument("--out", default="bench", help="folder for the tables and plots (default bench)")
    p.add_argument("--quick", action="store_true", help="a small preset (seconds; what CI runs)")
    p.add_argument("--photo", default=None, help="photo (default the shipped sample)")
    p.add_argument("--style", default=None, help="style image (default the shipped style)")
    p.add_argument("--model", default=None, help="quality: the checkpoint measured (default the shipped model)")
    p.add_argument("--eval-data", default=None, help="quality: held-out dataset folder for stage-1 PSNR/SSIM")
    p.add_argument("--real", default=None, metavar="DIR",
                   help="quality: measure held-out real photos x real paintings of DIR (photos/, paintings/; "
                        "stylize3d_core/train/real_images.py) and write blind boards, instead of the built-in set")
    p.add_argument("--pairs", type=int, default=16, help="quality --real: number of pairs (default 16)")
    p.add_argument("--compare", action="append", default=[], metavar="NAME=CHECKPOINT",
                   help="quality --real: another checkpoint measured beside --model (repeatable)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar, print nothing but errors")


def build_parser() -> argparse.ArgumentParser:
    from stylize3d_core import __version__

    parser = argparse.ArgumentParser(prog=PROG, description="Stylized 3D photos from one photo.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_render(sub)
    _add_training(sub)
    _add_info(sub)
    _add_models(sub)
    _add_bench(sub)
    return parser


def _info(args: argparse.Namespace) -> int:
    import json

    from stylize3d_core.info import collect, format_report

    report = collect()
    print(json.dumps(report, indent=2) if args.json else format_report(report))
    return 0


def _prepare_data(args: argparse.Namespace) -> int:
    import dataclasses

    from stylize3d_core.train.cache import build_splits
    from stylize3d_core.train.data import DataConfig
    from stylize3d_core.train.photos import EVAL_PHOTOS

    config, eval_config = DataConfig(image_size=(args.size, args.size)), None
    if args.real is not None:
        from stylize3d_core.train.real_images import split_real_images

        split = split_real_images(args.real)
        eval_config = dataclasses.replace(config, photos=EVAL_PHOTOS + tuple(str(p) for p in split.eval_photos))
        config = dataclasses.replace(config, photos=config.photos + tuple(str(p) for p in split.train_photos))
    train, held = build_splits(args.out, args.samples, args.eval_samples, config, args.seed, threads=args.threads,
                               eval_config=eval_config)
    for r in (train, held):
        print(f"{PROG}: {r.root}: {r.generated} generated, {r.skipped} already there, "
              f"{len(r.regenerated)} regenerated ({r.seconds:.0f} s)", file=sys.stderr)
    return 0


def _prepare_styles(args: argparse.Namespace) -> int:
    from stylize3d_core.train.styles import build_style_bank

    entries = build_style_bank(args.out, args.count, seed=args.seed)
    print(f"{PROG}: wrote {len(entries)} style images to {args.out}", file=sys.stderr)
    if args.real is not None:
        from stylize3d_core.train.real_images import split_real_images
        from stylize3d_core.train.styles import add_real_paintings

        real = add_real_paintings(args.out, split_real_images(args.real).train_paintings)
        print(f"{PROG}: added {len(real)} real paintings to {args.out}", file=sys.stderr)
    return 0


def _prepare_teacher(args: argparse.Namespace) -> int:
    from stylize3d_core.train.teacher import build_teacher

    progress = console_progress("teacher")
    r = build_teacher(args.data, args.styles, args.out, styles_per_sample=args.per_sample, seed=args.seed,
                      progress=progress)
    print(f"{PROG}: {args.out}: {r['made']} made, {r['kept']} already there ({r['seconds']:.0f} s)", file=sys.stderr)
    return 0


def _loss_weights(items):
    import dataclasses

    from stylize3d_core.train.trainer import LossWeights

    names = {f.name for f in dataclasses.fields(LossWeights)}
    values = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in names:
            raise InputError("--weight", f"expected NAME=VALUE with NAME one of {', '.join(sorted(names))}, "
                                         f"got {item!r}")
        try:
            values[name] = float(value)
        except ValueError:
            raise InputError("--weight", f"{name}: {value!r} is not a number") from None
        if not values[name] >= 0.0:
            raise InputError("--weight", f"{name} must be >= 0, got {value}")
    return LossWeights(**values)


def _stages(text: str):
    try:
        return tuple(int(part) for part in text.split(","))
    except ValueError:
        raise InputError("--style-stages", f"expected comma-separated integers such as 1,2,3, got {text!r}") from None


def _train(args: argparse.Namespace) -> int:
    from stylize3d_core.train.trainer import TrainConfig, train

    config = from_args(TrainConfig, args, stage=args.stage, weights=_loss_weights(args.weight),
                       style_stages=_stages(args.style_stages), style_crop=tuple(args.style_crop))
    path = train(config, log=lambda msg: print(f"{PROG}: {msg}", file=sys.stderr, flush=True))
    print(f"{PROG}: checkpoint {path}", file=sys.stderr)
    return 0


def _render(args: argparse.Namespace) -> int:
    job = from_args(RenderJob, args)  # InputError (exit 2) for a bad value, before any work
    log = (lambda _msg: None) if args.quiet else (lambda msg: print(f"{PROG}: {msg}", file=sys.stderr))
    progress = None if args.quiet else console_progress("render")
    result = run_render(job, progress=progress, log=log)
    if not args.quiet:
        t = result.timings
        stages = ", ".join(f"{k} {v:.2f}s" for k, v in t.items())
        print(f"{PROG}: done ({stages})", file=sys.stderr)
    return 0


def _bench(args: argparse.Namespace) -> int:
    from stylize3d_core.bench.suites import run_suite

    log = (lambda _msg: None) if args.quiet else (lambda msg: print(f"{PROG}: {msg}", file=sys.stderr))
    if args.real is not None:
        if args.suite != "quality":
            raise InputError("--real", f"measures the quality suite, not {args.suite!r}")
        from pathlib import Path

        from stylize3d_core.bench.real_quality import run_real_quality

        others = {}
        for item in args.compare:
            name, sep, path = item.partition("=")
            if not sep or not name or not path:
                raise InputError("--compare", f"expected NAME=CHECKPOINT, got {item!r}")
            others[name] = path
        run_real_quality(Path(args.out), args.real, model=args.model, others=others, pairs=args.pairs, log=log)
        if not args.quiet:
            print(f"{PROG}: bench quality: {args.out}/real_quality.md and the boards", file=sys.stderr)
        return 0
    rows = run_suite(args.suite, args.out, quick=args.quick, show_progress=not args.quiet, log=log,
                     photo=args.photo, style=args.style, model=args.model, eval_data=args.eval_data)
    if not args.quiet:
        print(f"{PROG}: bench {args.suite}: {len(rows)} rows in {args.out}/", file=sys.stderr)
    if args.suite == "stress" and not all(r["pass"] for r in rows):
        print(f"{PROG}: bench stress: {sum(not r['pass'] for r in rows)} case(s) failed", file=sys.stderr)
        return 1
    return 0


INTERNAL_ERROR = 3
"""Exit status of an unexpected exception (a bug): the traceback goes to a file, see :func:`_internal_error`."""


def _inputs(args: argparse.Namespace) -> str:
    """The inputs a command was working on, for the last-resort error line."""
    names = ("photo", "style", "camera_path", "depth", "data", "init", "out")
    parts = [f"{n.replace('_', '-')} {getattr(args, n)}" for n in names if isinstance(getattr(args, n, None), str)]
    return ", ".join(parts) or "no input file"


def _internal_error(e: BaseException, args: argparse.Namespace) -> int:
    """Save the traceback to a file and print one line naming the command, its inputs and the file."""
    import os
    import tempfile
    import time
    import traceback

    what = " ".join(f"{type(e).__name__}: {e}".split())[:300]
    folder = os.environ.get("STYLIZE3D_CRASH_DIR") or tempfile.gettempdir()
    try:
        fd, path = tempfile.mkstemp(prefix=f"{PROG}-crash-{time.strftime('%Y%m%d-%H%M%S')}-", suffix=".txt",
                                    dir=folder)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(f"{PROG} {args.command}: {_inputs(args)}\n\n" + traceback.format_exc())
        saved = f"full traceback in {path}"
    except OSError as err:
        saved = f"the traceback could not be saved ({err.strerror or err})"
    print(f"{PROG}: internal error in '{args.command}' working on {_inputs(args)}: {what}; {saved}",
          file=sys.stderr)
    return INTERNAL_ERROR


def main(argv: Optional[List[str]] = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit status.

    0 success, 1 an output could not be written, 2 bad input, 3 an unexpected
    internal error (traceback saved to a file), 128 + signal when interrupted
    (130 Ctrl-C, 143 SIGTERM).
    """
    import warnings

    from stylize3d_core.memory import keep_freed_memory

    args = build_parser().parse_args(argv)
    keep_freed_memory()  # as the viewer: each frame's tensors reuse freed memory, not fresh pages
    shown, warnings.showwarning = warnings.showwarning, show_warning
    try:
        handlers = {"render": _render, "prepare-data": _prepare_data, "prepare-styles": _prepare_styles,
                    "prepare-teacher": _prepare_teacher, "train": _train, "info": _info, "bench": _bench,
                    "models": _models}
        return handlers[args.command](args)
    except InputError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    except ExportCancelled:
        print(f"{PROG}: cancelled; nothing was written", file=sys.stderr)
        return 130
    except ExportError as e:
        print(f"{PROG}: could not write output: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        print(f"{PROG}: {interrupted_message(e)}; nothing was written", file=sys.stderr)
        return interrupted_status(e)
    except Stylize3DError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 1
    except Exception as e:  # the last line of defence: a bug, reported in one line
        return _internal_error(e, args)
    finally:
        warnings.showwarning = shown


if __name__ == "__main__":  # python -m stylize3d_app.cli (torchrun): the handlers once torch is imported
    install_signal_handlers()
    sys.exit(main())
