"""``bench quality --real DIR``: held-out real photos x real paintings, every method, measured and boarded.

The pairs: the held-out photos and paintings of ``DIR``
(:func:`~stylize3d_core.train.real_images.split_real_images`), the k-th photo of
a seeded shuffle with the k-th painting of another. For each pair the first
``frames`` cameras of the 90-frame circle are rendered by:

* ``plain``: the plain 3D photo (the content reference);
* ``ours``: the checkpoint measured (default the shipped model), and any
  ``others`` (name -> checkpoint) beside it;
* ``2d``: the per-frame 2D network;
* ``baked``: stylize-then-bake.

and measured (:mod:`stylize3d_core.eval.real_pairs`): style-embedding distance
(mean over every ``style_every``-th frame; the plain photo's own too: how far the
unstyled photo is from the painting), content edge F1 against the plain
frame, warp RMSE short / long over all co-visible pixels and over the
disoccluded ones. Frame ``board_frame`` of each method is kept; blind boards of
``ours`` against each baseline are written with their keys.

Writes to ``out``: ``real_quality.md`` (means, worst pair, ratios), ``real_quality.json`` (every pair),
``boards_<a>_vs_<b>/board_NN.png`` and ``boards_<a>_vs_<b>_key.json``; for the pairs whose hidden layer
shows, seam boards of ours against stylize-then-bake (:func:`~stylize3d_core.eval.real_pairs.seam_board`),
``seams_ours_vs_baked/board_NN.png`` and ``seams_ours_vs_baked_key.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Dict, List, Mapping, Optional

import numpy as np

from .report import Log, markdown_table, quiet


METRICS = ("style_dist", "edge_f1", "short", "long", "short_dis", "long_dis")
LABELS = {"style_dist": "style-embedding dist", "edge_f1": "edge F1", "short": "warp short", "long": "warp long",
          "short_dis": "warp short, disoccluded", "long_dis": "warp long, disoccluded"}
EDGE_METRICS = ("short_edge", "long_edge", "short_dis_edge", "long_dis_edge")
"""The warp figures again with the single-pixel co-visibility test (``warp_view(one_surface=False)``): samples
beside depth edges, which mix two surfaces, counted too. Diagnostics beside :data:`METRICS`."""
EDGE_LABELS = {"short_edge": "warp short", "long_edge": "warp long", "short_dis_edge": "warp short, disoccluded",
               "long_dis_edge": "warp long, disoccluded"}
SEAM_RATIOS = (("short", "short_dis"), ("long", "long_dis"), ("short_edge", "short_dis_edge"),
               ("long_edge", "long_dis_edge"))
"""(all pixels, disoccluded) metric pairs whose ratio of means over the pairs with disocclusions the report gives."""
SEAM_LABELS = {"short": "short", "long": "long", "short_edge": "short (single-pixel test)",
               "long_edge": "long (single-pixel test)"}


def _mean(values: List[float]) -> float:
    v = [x for x in values if np.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")


def _seam_ratios(per_pair: List[dict], methods: List[str]) -> dict:
    """Per method, for each (all, disoccluded) pair of :data:`SEAM_RATIOS`: mean disoccluded / mean all, over the
    pairs whose disoccluded figure is finite (``"pairs"``: how many have the first one)."""
    out: dict = {"pairs": sum(1 for r in per_pair if methods and np.isfinite(r["methods"][methods[0]]["short_dis"]))}
    for m in methods:
        out[m] = {}
        for a, d in SEAM_RATIOS:
            rows = [r["methods"][m] for r in per_pair if np.isfinite(r["methods"][m][d])]
            out[m][a] = _mean([r[d] for r in rows]) / _mean([r[a] for r in rows]) if rows else float("nan")
    return out


def run_real_quality(out: Path, real_dir: str, *, model: Optional[str] = None,
                     others: Optional[Mapping[str, str]] = None, pairs: int = 16, frames: int = 16,
                     frame_long_side: int = 512, photo_size: int = 768, style_every: int = 4, board_frame: int = 12,
                     seed: int = 0, log: Log = quiet) -> Dict[str, Dict[str, float]]:
    """Measure ``pairs`` held-out pairs (see the module docstring); returns ``{method: {metric: mean}}``."""
    from ..errors import InputError
    from ..eval.baseline import make_engine, stylize_frames_2d
    from ..eval.consistency import long_range_pairs, short_range_pairs
    from ..eval.quality import baked_colours, baked_renderer, view_geometries
    from ..eval.real_pairs import (SEAM_CROP, edge_f1, hidden_views, seam_board, seam_crop, style_embedding_distance, warp_split,
                                   write_boards)
    from ..geometry.trajectories import TrajectorySettings, make_trajectory
    from ..io.atomic import write_atomically
    from ..io.images import load_image
    from ..models.checkpoint import load_checkpoint
    from ..models.style_features import StyleEncoder
    from ..pipeline import PhotoSpec, load_photo3d
    from ..render.plain import PlainRenderer, frame_size
    from ..resources import resolve_model
    from ..stylize import Stylized3DPhoto, style_prior
    from ..train.real_images import split_real_images

    if not 1 <= board_frame < frames:
        raise InputError("board_frame", f"must be in [1, {frames}), got {board_frame}")
    t_start = time.perf_counter()
    split = split_real_images(real_dir)
    rng = np.random.default_rng(seed)
    photos = [split.eval_photos[i] for i in rng.permutation(len(split.eval_photos))]
    paintings = [split.eval_paintings[i] for i in rng.permutation(len(split.eval_paintings))]
    n = min(pairs, len(photos), len(paintings))
    checkpoints = {"ours": load_checkpoint(resolve_model(model))}
    checkpoints.update({name: load_checkpoint(path) for name, path in (others or {}).items()})
    encoder, engine, prior = StyleEncoder(), make_engine(), style_prior(512)
    per_pair: List[dict] = []
    board_pairs: List[dict] = []
    seam_pairs: List[dict] = []
    for k in range(n):
        photo_path, painting_path = photos[k], paintings[k]
        name = f"{photo_path.stem}+{painting_path.stem}"
        t0 = time.perf_counter()
        p3d = load_photo3d(PhotoSpec(photo=str(photo_path), max_size=photo_size))
        style_rgb = load_image(painting_path, max_size=1024).rgb
        H, W = frame_size(p3d.size, frame_long_side)
        cams = make_trajectory(TrajectorySettings(name="circle", n_frames=90, fov_y_deg=p3d.fov_y_deg))
        cams = cams[:frames]
        out_frames: Dict[str, List[np.ndarray]] = {"plain": list(PlainRenderer(p3d.points).frames(cams, H, W))}
        for method, ck in checkpoints.items():
            ours = Stylized3DPhoto(p3d, ck, style_encoder=encoder)
            ours.set_style(style_rgb)
            out_frames[method] = list(ours.frames(cams, H, W))
        out_frames["2d"] = stylize_frames_2d(out_frames["plain"], style_rgb, engine=engine)
        out_frames["baked"] = list(baked_renderer(p3d, baked_colours(p3d, style_rgb, engine=engine)).frames(cams, H, W))
        geoms = view_geometries(p3d.points.xyz, cams, H, W)
        hidden = hidden_views(p3d, cams, H, W)
        short = warp_split(out_frames, cams, geoms, hidden, short_range_pairs(frames))
        long_ = warp_split(out_frames, cams, geoms, hidden, long_range_pairs(frames))
        short_e = warp_split(out_frames, cams, geoms, hidden, short_range_pairs(frames), one_surface=False)
        long_e = warp_split(out_frames, cams, geoms, hidden, long_range_pairs(frames), one_surface=False)
        vec = prior.style_vector(style_rgb)
        row: dict = {"pair": name, "photo": photo_path.name, "painting": painting_path.name, "methods": {}}
        for method, fr in out_frames.items():  # "plain" too: the unstyled photo's figures are the floor
            row["methods"][method] = {
                "style_dist": _mean([style_embedding_distance(f, vec, prior) for f in fr[::style_every]]),
                "edge_f1": _mean([edge_f1(f, p) for f, p in zip(fr, out_frames["plain"])]),
                "short": short.all[method], "long": long_.all[method],
                "short_dis": short.disoccluded[method], "long_dis": long_.disoccluded[method],
                "short_edge": short_e.all[method], "long_edge": long_e.all[method],
                "short_dis_edge": short_e.disoccluded[method], "long_dis_edge": long_e.disoccluded[method],
            }
        per_pair.append(row)
        board_pairs.append({"name": name, "photo": p3d.rgb, "painting": style_rgb,
                            **{m: fr[board_frame] for m, fr in out_frames.items()}})
        box = seam_crop([h.numpy() for h in hidden], SEAM_CROP)
        if box is not None:  # the crop with the most hidden layer, in its frame and half a path later
            t, y0, x0 = box
            side = SEAM_CROP
            seam_pairs.append({"name": name, **{m: [fr[f][y0:y0 + side, x0:x0 + side]
                                                     for f in (t, (t + frames // 2) % frames)]
                                                 for m, fr in out_frames.items()}})
        log(f"{name}: {time.perf_counter() - t0:.0f} s " + " ".join(
            f"{m}: style {v['style_dist']:.2f} F1 {v['edge_f1']:.3f} warp {v['short']:.3f}/{v['long']:.3f}"
            for m, v in row["methods"].items() if m != "plain"))
    methods = [m for m in per_pair[0]["methods"] if m != "plain"] + ["plain"] if per_pair else []  # plain last
    means = {m: {q: _mean([r["methods"][m][q] for r in per_pair]) for q in METRICS + EDGE_METRICS} for m in methods}
    seam = _seam_ratios(per_pair, methods)
    worst = {m: max(per_pair, key=lambda r: r["methods"][m]["style_dist"])["pair"] for m in methods}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for baseline in ("baked", "2d"):
        write_boards(out / f"boards_ours_vs_{baseline}", board_pairs, ("ours", baseline), seed=seed + 1)
    if seam_pairs:
        write_boards(out / "seams_ours_vs_baked", seam_pairs, ("ours", "baked"), seed=seed + 3,
                     compose=lambda pair, a, b: seam_board(pair["plain"], pair[a], pair[b]))
    for other in (others or {}):
        write_boards(out / f"boards_ours_vs_{other}", board_pairs, ("ours", other), seed=seed + 2)
    rows = [{"method": m, **{LABELS[q]: means[m][q] for q in METRICS},
             "worst style pair": f"{worst[m]} ({max(r['methods'][m]['style_dist'] for r in per_pair):.2f})"}
            for m in methods]
    ratio_rows = []
    for ref in ("baked", "2d"):
        if ref in means:
            ratio_rows.append({"ours ×": ref, **{LABELS[q]: means["ours"][q] / means[ref][q] for q in METRICS}})
    text = "\n".join([
        "# Real photos x real paintings (held out)", "",
        f"{n} pairs, {frames} frames of the circle at {frame_long_side} px, photos at {photo_size} px; "
        f"{time.perf_counter() - t_start:.0f} s.", "",
        markdown_table(rows, ["method"] + [LABELS[q] for q in METRICS] + ["worst style pair"], digits=3), "",
        "## Ratios", "", markdown_table(ratio_rows, ["ours ×"] + [LABELS[q] for q in METRICS], digits=3), "",
        "## Seams: disoccluded / all pixels", "",
        f"Ratio of the means over the {seam['pairs']} pairs with disoccluded pixels (a pair counts where some",
        "pair of its views has 16 or more).", "",
        markdown_table([{"method": m, **{SEAM_LABELS[a]: seam[m][a] for a, _ in SEAM_RATIOS}} for m in methods],
                       ["method"] + [SEAM_LABELS[a] for a, _ in SEAM_RATIOS], digits=3), "",
        "## Warp with the single-pixel co-visibility test (diagnostic)", "",
        "Samples beside depth edges, which read two surfaces, counted too.", "",
        markdown_table([{"method": m, **{EDGE_LABELS[q]: means[m][q] for q in EDGE_METRICS}} for m in methods],
                       ["method"] + [EDGE_LABELS[q] for q in EDGE_METRICS], digits=3), "",
    ])
    write_atomically(out / "real_quality.md", "report", lambda tmp: tmp.write_text(text, encoding="utf-8"))
    blob = json.dumps({"means": means, "seam_ratios": seam, "pairs": per_pair}, indent=1, default=float)
    write_atomically(out / "real_quality.json", "report", lambda tmp: tmp.write_text(blob, encoding="utf-8"))
    return means


__all__ = ["run_real_quality", "METRICS"]
