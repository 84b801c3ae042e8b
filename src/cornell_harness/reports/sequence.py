"""The report of ``cbox sequence``: an animated scene's renders against its per-frame references.

``sequence.html`` (self-contained, beside the results) has: the table of temporal figures per renderer (mean over
seeds with its 95% interval), the error against frame per renderer with its 95% band over seeds, the
lag-against-flicker plane (the real-time trade: a longer history flickers less and lags more; a sweep of a setting
traces the curve, the Pareto frontier marked; a renderer that did not settle within the sequence at its right edge,
marked so), a frame strip (the reference, then each renderer's first seed) and,
per renderer, a side-by-side animation of render, reference and error (an animated PNG written with Pillow,
``anim-<renderer>.png``, beside it). Images are display-encoded at each frame reference's exposure; the error is
the mean absolute error over channels, on one colour scale for every frame of a renderer.
"""

from __future__ import annotations

import math
from html import escape
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
from PIL import Image

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.convergence import mean_ci
from cornell_harness.evaluate.registry import LAG_METRIC, METRICS
from cornell_harness.evaluate.temporal import lag_over_seeds
from cornell_harness.reports.image_figure import file_stem
from cornell_harness.reports.images import apply_colormap, png_data_uri, to_uint8
from cornell_harness.reports.plots import PALETTE, Point, Series, line_plot_svg, scatter_svg
from cornell_harness.store.atomic import atomic_path, write_text_atomic

#: Frames shown in the strip, at most (evenly spaced, the first and last among them).
STRIP_FRAMES = 6
#: The animation's frame duration, milliseconds.
FRAME_MS = 80
#: The columns of the table of temporal figures.
TABLE_COLUMNS = ("flicker", "flicker_floor", "lag", "ghosting", LAG_METRIC, "time_per_frame_s")


def _encoded(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return to_uint8(metrics.display_encode(image, metrics.display_exposure(reference)))


def side_by_side(images: np.ndarray, references: np.ndarray) -> list[np.ndarray]:
    """Each frame as one uint8 picture: render | reference | error (|render − reference|, mean over channels,
    viridis from 0 to the 99th percentile of every frame's error)."""
    err = np.abs(np.asarray(images, np.float64) - references).mean(axis=-1)
    top = float(np.percentile(err, 99)) or 1.0
    return [np.hstack([_encoded(img, ref), _encoded(ref, ref), apply_colormap(e, 0.0, top, "viridis")])
            for img, ref, e in zip(images, references, err)]


def write_animation(path: Path, pictures: Sequence[np.ndarray]) -> Path:
    """``pictures`` as an animated PNG (looping), written atomically."""
    first, *rest = [Image.fromarray(np.ascontiguousarray(p)) for p in pictures]
    with atomic_path(path) as tmp:
        first.save(tmp, format="PNG", save_all=True, append_images=rest, duration=FRAME_MS, loop=0)
    return path


def _colours(names: Sequence[str]) -> dict[str, str]:
    return {n: PALETTE[i % len(PALETTE)] for i, n in enumerate(names)}


def error_plot(frames: pd.DataFrame, colours: Mapping[str, str], metric: str = LAG_METRIC) -> str:
    """Error against frame, per renderer: mean over seeds and its 95% band (frame + 1 on a log axis)."""
    series = []
    for name, rows in frames.groupby("renderer", sort=False):
        stats = [mean_ci(g[metric]) for _, g in sorted(rows.groupby("frame"))]
        x = [float(f) + 1.0 for f in sorted(rows["frame"].unique())]
        y = [m for m, _ in stats]
        half = [0.0 if math.isnan(h) else h for _, h in stats]
        series.append(Series(name, colours[name], x, y, [max(m - h, 1e-12) for m, h in zip(y, half)],
                             [m + h for m, h in zip(y, half)]))
    return line_plot_svg(series, uid="sequence-error", xlabel="frame + 1", ylabel=METRICS[metric].axis_label
                         or metric, guide_slope=None, band_label="95% CI over seeds")


def lag_text(lag: float, bound, unit: str = "", digits: str = "g") -> str:
    """A lag (frames) as text, ``unit`` after the number: ``4 frames``; for ``math.inf``, not settled within the
    sequence (:func:`cornell_harness.evaluate.temporal.lag`), ``> 83 frames (not settled)`` with the frames the
    sequence shows after its change (``bound``); ``—`` for NaN (no change to follow)."""
    unit = f" {unit}" if unit else ""
    if lag is None or math.isnan(lag):
        return "—"
    if math.isinf(lag):
        return f"> {'?' if bound is None or pd.isna(bound) else int(bound)}{unit} (not settled)"
    return f"{lag:{digits}}{unit}"


def _bound(rows: pd.DataFrame):
    """The rows' lag bound (frames shown after the change), the first known one; None without one."""
    known = pd.to_numeric(rows.get("lag_bound", pd.Series(dtype=float)), errors="coerce").dropna()
    return int(known.iloc[0]) if len(known) else None


def lag_flicker_plot(sequences: pd.DataFrame, colours: Mapping[str, str]) -> str:
    """The lag-against-flicker plane: each renderer's mean over seeds with 95% whiskers (lag + 1: log axis). A
    renderer that did not settle within the sequence at some seed (its mean lag ``inf``,
    :func:`cornell_harness.evaluate.temporal.lag_over_seeds`) is drawn at the right edge, an arrow from its bound
    (the frames shown after the change) to it, and says so."""
    points = []
    for name, rows in sequences.groupby("renderer", sort=False):
        lag, lag_h = lag_over_seeds(pd.to_numeric(rows["lag"], errors="coerce"))
        flicker, flicker_h = mean_ci(rows["flicker"])
        if math.isnan(lag) or math.isnan(flicker):
            continue
        fh = 0.0 if math.isnan(flicker_h) else flicker_h
        ys = dict(ylo=max(flicker - fh, 1e-12), yhi=flicker + fh)
        if math.isinf(lag):
            bound = _bound(rows)
            points.append(Point(name, colours[name], (bound or 0) + 1.0, flicker, f"{name}: lag "
                                f"{lag_text(lag, bound, 'frames')}, flicker {flicker:.3g}", tag="not settled",
                                censored=True, **ys))
            continue
        lh = 0.0 if math.isnan(lag_h) else lag_h
        points.append(Point(name, colours[name], lag + 1.0, flicker, f"{name}: lag {lag:.1f} frames, flicker "
                            f"{flicker:.3g}", xlo=max(lag - lh, 0.0) + 1.0, xhi=lag + lh + 1.0, **ys))
    bound = _bound(sequences)
    beyond = f"the {bound} frames after the change" if bound is not None else "the sequence"
    return scatter_svg(points, uid="sequence-lag-flicker", xlabel="lag + 1 (frames)", ylabel="flicker (RMS)",
                       censored_label=f"not settled: lag beyond {beyond}")


def _table(sequences: pd.DataFrame) -> str:
    head = "".join(f"<th title='{escape(METRICS[c].definition) if c in METRICS else ''}'>"
                   f"{escape(METRICS[c].label if c in METRICS else 'time/frame (s)')}</th>" for c in TABLE_COLUMNS)
    rows = []
    for name, g in sequences.groupby("renderer", sort=False):
        ok = g[g["status"] == "ok"]
        cells = []
        for c in TABLE_COLUMNS:
            mean = lag_over_seeds if c == "lag" else mean_ci
            m, h = mean(pd.to_numeric(ok[c], errors="coerce")) if c in ok and len(ok) else (math.nan, math.nan)
            text = lag_text(m, _bound(ok), digits=".4g") if c == "lag" else "—" if math.isnan(m) else f"{m:.4g}"
            cells.append(escape(text) + ("" if math.isnan(h) else f" ± {h:.2g}"))
        status = "" if len(ok) == len(g) else f" ({len(g) - len(ok)} not ok: {escape(str(g['reason'].iloc[0]))})"
        rows.append(f"<tr><td>{escape(name)}{status}</td><td>{len(ok)}</td>"
                    + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return f"<table><tr><th>renderer</th><th>seeds</th>{head}</tr>{''.join(rows)}</table>"


def _strip(images: Mapping[str, np.ndarray], references: np.ndarray, frames: Sequence[int]) -> str:
    picks = sorted({int(round(k)) for k in np.linspace(0, len(frames) - 1, min(STRIP_FRAMES, len(frames)))})
    rows = [("reference", references)] + list(images.items())
    out = ["<table class='strip'><tr><th></th>" + "".join(f"<th>frame {frames[k]}</th>" for k in picks) + "</tr>"]
    for name, seq in rows:
        out.append(f"<tr><td>{escape(name)}</td>" + "".join(
            f"<td><img alt='{escape(name)} frame {frames[k]}' src='{png_data_uri(_encoded(seq[k], references[k]))}'>"
            "</td>" for k in picks) + "</tr>")
    return "".join(out) + "</table>"


def write_sequence_report(folder: str | Path, scene: str, frame_rows: list[dict], sequence_rows: list[dict],
                          images: Mapping[str, np.ndarray], references: Sequence[np.ndarray], command: str) -> Path:
    """``sequence.html`` and the animations in ``folder`` (module docstring), ``references`` the frames'
    reference images; its path."""
    folder, references = Path(folder), np.stack(references)
    frames_df, seq_df = pd.DataFrame(frame_rows), pd.DataFrame(sequence_rows)
    colours = _colours(list(dict.fromkeys(seq_df["renderer"])))
    frames = sorted(int(f) for f in frames_df["frame"].unique()) if len(frames_df) else []
    parts = [f"<h1>Sequence — {escape(scene)}</h1><p><code>{escape(command)}</code></p>",
             "<h2>Temporal figures</h2>", _table(seq_df)]
    if len(frames_df):
        floor = float(seq_df["flicker_floor"].iloc[0])
        parts += ["<h2>Error against frame</h2>", error_plot(frames_df, colours),
                  "<h2>Lag against flicker</h2>",
                  f"<p>Flicker floor (two reference-quality sequences): {floor:.3g}.</p>",
                  lag_flicker_plot(seq_df[seq_df["status"] == "ok"], colours),
                  "<h2>Frames</h2>", _strip(images, references, frames), "<h2>Animations</h2>",
                  "<p>Render | reference | error, per renderer (first seed).</p>"]
        for name, seq in images.items():
            anim = write_animation(folder / f"anim-{file_stem(name)}.png", side_by_side(seq, references))
            parts.append(f"<h3>{escape(name)}</h3><img alt='{escape(name)} animation' src='{anim.name}'>")
    html = ("<!doctype html><html><head><meta charset='utf-8'><title>Sequence — " + escape(scene)
            + "</title><style>body{font-family:sans-serif;max-width:70em;margin:auto}td,th{padding:0 .4em}"
            "img{image-rendering:pixelated;width:8em}h3+img{width:24em}</style></head><body>"
            + "".join(parts) + "</body></html>")
    path = folder / "sequence.html"
    write_text_atomic(path, html)
    return path
