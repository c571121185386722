"""``bench quality``: the measurement the model is steered by (:mod:`stylize3d_core.eval.quality`).

For every photo x style pair of :data:`~stylize3d_core.eval.quality.QUALITY_PHOTOS` x
:data:`~stylize3d_core.eval.quality.QUALITY_STYLES` (4 x 4), the same cameras are
rendered by the plain 3D photo, ours (a checkpoint, default the shipped one),
the per-frame 2D network and stylize-then-bake, and measured: Lab and
EfficientNet style distances, sharpness against the plain render, short and long
range warp RMSE. With ``eval_data`` (a held-out dataset folder written by
``stylize3d prepare-data``) the checkpoint's stage-1 PSNR / SSIM on its views is
reported beside the plain point render's.

Writes to ``out``: ``quality.md`` (the group means, then every pair),
``quality.json`` (everything, machine-readable), ``contact_sheet.png`` (every
pair) and ``contact_sheet_heldout.png`` (the pairs whose photo and style were
both held out); the inputs it made (photos as PNG, painted styles) are cached in
``out/inputs`` and reused.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Dict, List, Optional

from .report import Log, _json_value, machine, markdown_table, progress, quiet


def _clean(v):
    """JSON-safe copy of nested dicts / lists of numbers (NaN and inf as text)."""
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    return _json_value(v)


_COLUMNS = {"lab": "Lab dist", "lab_x2d": "Lab ×2D", "effnet": "EffNet dist", "effnet_x2d": "EffNet ×2D",
            "sharpness_x_plain": "sharpness ×plain", "short_rmse": "warp short", "short_x2d": "short ×2D",
            "long_rmse": "warp long", "long_x2d": "long ×2D"}


def summary_rows(summary: Dict, groups=None) -> List[dict]:
    """Table rows (group, method, n pairs, every metric) of :func:`~stylize3d_core.eval.quality.summarize`."""
    from ..eval.quality import METHOD_LABELS, METHODS, METRICS

    rows = []
    for group, by_method in summary.items():
        if groups is not None and group not in groups:
            continue
        for m in METHODS:
            if m in by_method:
                rows.append({"pairs": group, "n": int(by_method["_"]["n_pairs"]), "method": METHOD_LABELS[m],
                             **{_COLUMNS[k]: by_method[m][k] for k in METRICS}})
    return rows


def pair_rows(pairs: List[dict]) -> List[dict]:
    from ..eval.quality import METHOD_LABELS, METHODS, METRICS

    return [{"photo": p["photo"], "style": p["style"], "group": p["group"], "method": METHOD_LABELS[m],
             **{_COLUMNS[k]: p["metrics"][m][k] for k in METRICS}}
            for p in pairs for m in METHODS if m in p["metrics"]]


def run_quality(out: Path, quick: bool = False, show_progress: bool = False, log: Log = quiet,
                model: Optional[str] = None, eval_data: Optional[str] = None,
                strength: Optional[float] = None, *, preset=None, photos=None, styles=None) -> List[dict]:
    """Measure every pair (``quick``: the small preset) and write the report to ``out``; returns the summary rows.

    ``preset`` (a :class:`~stylize3d_core.eval.quality.QualityPreset`), ``photos`` and ``styles``
    (sequences of ``QualityPhoto`` / ``QualityStyle``) replace the preset and the set (tests use a tiny one).
    """
    from ..errors import InputError
    from ..eval.baseline import make_engine
    from ..eval.quality import (
        FULL, QUALITY_PHOTOS, QUALITY_STYLES, QUICK, contact_sheet, load_quality_photo, measure_pair,
        pair_group, render_methods, stage1_scores, style_image_for, summarize, view_geometries,
    )
    from ..geometry.trajectories import TrajectorySettings, make_trajectory
    from ..io.atomic import write_atomically
    from ..io.images import save_image
    from ..models.checkpoint import load_checkpoint
    from ..models.style_features import StyleEncoder
    from ..pipeline import PhotoSpec, load_photo3d
    from ..render.plain import PlainRenderer, frame_size
    from ..resources import resolve_model
    from ..stylize import Stylized3DPhoto, StylizeSettings
    t_start = time.perf_counter()
    preset = preset if preset is not None else (QUICK if quick else FULL)
    photos = tuple(QUALITY_PHOTOS if photos is None else photos)
    style_set = tuple(QUALITY_STYLES if styles is None else styles)
    if not photos or not style_set:
        raise InputError("quality set", "needs at least one photo and one style")
    out = Path(out)
    inputs = out / "inputs"
    inputs.mkdir(parents=True, exist_ok=True)
    model_path = resolve_model(model)
    settings = StylizeSettings() if strength is None else StylizeSettings(strength=strength)
    ckpt = load_checkpoint(model_path)
    encoder = StyleEncoder()
    engine = make_engine()
    styles = {s.name: style_image_for(s, inputs) for s in style_set}
    pairs: List[dict] = []
    sheet_rows = []
    jobs = [(p, s) for p in photos for s in style_set]
    bar = iter(progress(jobs, len(jobs), "quality", show_progress))
    for photo in photos:
        path = inputs / f"{photo.name}.png"
        if not path.is_file():
            save_image(path, load_quality_photo(photo.name))
        t0 = time.perf_counter()
        p3d = load_photo3d(PhotoSpec(photo=str(path), depth="prior", max_size=preset.photo_size))
        cams = make_trajectory(TrajectorySettings(n_frames=preset.trajectory_frames,
                                                  fov_y_deg=p3d.fov_y_deg))[: preset.frames]
        H, W = frame_size(p3d.size, preset.frame_size)
        plain = list(PlainRenderer(p3d.points).frames(cams, H, W))
        geometries = view_geometries(p3d.points.xyz, cams, H, W)
        ours = Stylized3DPhoto(p3d, ckpt, settings, style_encoder=encoder)
        setup = time.perf_counter() - t0
        log(f"quality: {photo.name}: {W}x{H} frames, {len(p3d.points):,} points, set up in {setup:.1f} s")
        for style in style_set:
            next(bar, None)
            timings: Dict[str, float] = {}
            frames = render_methods(p3d, styles[style.name], cams, H, W, ours=ours, plain_frames=plain,
                                    engine=engine, timings=timings)
            t0 = time.perf_counter()
            metrics = measure_pair(frames, styles[style.name], cams, geometries, preset.style_every)
            timings["measure"] = time.perf_counter() - t0
            group = pair_group(photo, style)
            pairs.append({"photo": photo.name, "style": style.name, "photo_seen": photo.seen,
                          "style_seen": style.seen, "group": group, "frame_hw": [H, W], "metrics": metrics,
                          "seconds": timings})
            k = preset.sheet_frame
            sheet_rows.append((f"{photo.name} x {style.name} ({group})",
                               {"photo": p3d.rgb, "style": styles[style.name],
                                **{m: frames[m][k] for m in frames}}))
            log(f"quality: {photo.name} x {style.name}: " + ", ".join(f"{m} {t:.0f} s" for m, t in timings.items()))
        del ours
    summary = summarize(pairs)
    stage1, stage1_note = {}, ""
    if eval_data is None:
        stage1_note = "stage-1 held-out PSNR/SSIM skipped: no --eval-data folder given"
    elif not (Path(eval_data) / "dataset.json").is_file():
        stage1_note = f"stage-1 held-out PSNR/SSIM skipped: {eval_data} holds no dataset (no dataset.json)"
    else:
        t0 = time.perf_counter()
        stage1 = stage1_scores(ckpt.model, eval_data, preset.view_samples)
        stage1_note = (f"stage-1 held-out views of {eval_data} (" + (f"first {preset.view_samples} samples"
                       if preset.view_samples else "all samples") + f"; {time.perf_counter() - t0:.0f} s)")
    log("quality: " + stage1_note)
    seconds = time.perf_counter() - t_start
    info = machine()
    description = (f"{len(photos)} photos x {len(style_set)} styles; frames {preset.frame_size} px on "
                   f"the long side, the first {preset.frames} cameras of the {preset.trajectory_frames}-frame circle; "
                   f"photos shrunk to {preset.photo_size} px, depth from the built-in prior"
                   + (" (--quick preset)" if preset == QUICK else " (full preset)" if preset == FULL else " (custom preset)"))
    notes = [description,
             f"ours: {model_path}, strength {settings.strength:g}; 2D network (per frame and baked) at strength 1",
             "Lab dist: norm of the difference of the (mean, std) of L*, a*, b* between frame and style; EffNet dist: "
             f"models.losses.style_distance on every {preset.style_every}th frame; ×2D: as a multiple of the per-frame "
             "2D network's; sharpness ×plain: std of the Laplacian of the grey frame over the plain render's, same "
             "view; warp short/long: point-cloud warp RMSE of frames 1 / 7 apart (docs/quality.md)",
             "pairs: held-out = photo and style never seen in training; seen = both seen; mixed = one of them",
             stage1_note,
             f"{seconds:.0f} s on {info['cpus']} CPUs, torch {info['torch_threads']} threads, load average "
             f"{', '.join(str(x) for x in info['load_average']) or 'unknown'} (a loaded machine is slower, "
             "the figures are not timings)"]
    md = ["# Quality: style, sharpness, consistency", "", markdown_table(summary_rows(summary),
          ["pairs", "n", "method", *_COLUMNS.values()], digits=3)]
    if stage1:
        md += ["## Held-out stage-1 view synthesis", "",
               markdown_table([{"kind": k, **v} for k, v in stage1.items()],
                              ["kind", "n_views", "model_psnr", "plain_psnr", "gap_db", "model_ssim", "plain_ssim"],
                              digits=4)]
    md += ["## Every pair", "", markdown_table(pair_rows(pairs), ["photo", "style", "group", "method",
                                                                  *_COLUMNS.values()], digits=3)]
    md += [f"* {n}" for n in notes] + [""]
    data = {"title": "Quality: style, sharpness, consistency", "preset": preset.__dict__, "quick": quick,
            "model": model_path, "strength": settings.strength, "photos": [p._asdict() for p in photos],
            "styles": [s._asdict() for s in style_set], "pairs": pairs,
            "summary": summary, "stage1": stage1, "stage1_note": stage1_note, "notes": notes, "seconds": seconds,
            "machine": info}
    write_atomically(out / "quality.json", "quality report",
                     lambda p: p.write_text(json.dumps(_clean(data), indent=1, allow_nan=False)))
    write_atomically(out / "quality.md", "quality report", lambda p: p.write_text("\n".join(md)))
    save_image(out / "contact_sheet.png", contact_sheet(sheet_rows))
    held = [r for r in sheet_rows if r[0].endswith("(held-out)")]
    if held:
        save_image(out / "contact_sheet_heldout.png", contact_sheet(held))
    log(f"quality: {len(pairs)} pairs in {seconds:.0f} s; report in {out}")
    return summary_rows(summary)

