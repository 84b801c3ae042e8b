"""``cbox reference verify --report DIR``: one self-contained page, the two engines' images and the region table.

The reference and the second engine's image are shown side by side at the
reference's display exposure (:func:`cornell_harness.evaluate.metrics.display_exposure`,
the one every report image shares), with the per-pixel |z| of their difference
(magma, 0..6, as the gate's tile map: :data:`cornell_harness.reports.gate.Z_MAX`) and the
per-region table of :class:`cornell_harness.evaluate.reference_agreement.ReferenceAgreement`.
"""

from __future__ import annotations

from html import escape
from pathlib import Path

import numpy as np

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.agreement import CHANNELS
from cornell_harness.evaluate.reference_agreement import z_scores
from cornell_harness.store.atomic import write_text_atomic
from cornell_harness.store.exr import write_exr
from cornell_harness.reports.gate import Z_MAX
from cornell_harness.reports.images import apply_colormap, png_data_uri, to_uint8

#: On-screen width of each image, CSS pixels (small scenes are scaled up, pixelated).
SHOWN_PX = 320

_STYLE = ("body{font-family:system-ui,sans-serif;background:#1e1f22;color:#ddd;margin:2em}"
          "figure{display:inline-block;margin:0 1em 1em 0}img{image-rendering:pixelated}"
          "table{border-collapse:collapse;font-variant-numeric:tabular-nums}"
          "td,th{padding:2px 8px;border-bottom:1px solid #444;text-align:right}td:first-child{text-align:left}"
          "tr.fail td{color:#ff8a6a}.pass{color:#7fd37f}.fail{color:#ff8a6a}.note{color:#aaa;max-width:60em}")


def _shown(image: np.ndarray, exposure: float) -> str:
    return png_data_uri(to_uint8(metrics.display_encode(image, exposure)))


def z_map_png(reference, reference_variance, other, other_variance) -> str:
    """|z| per pixel (max over channels), magma on 0..Z_MAX, as a PNG data URI."""
    z = z_scores(np.asarray(other, np.float64) - reference, np.asarray(reference_variance, np.float64)
                 + other_variance)
    return png_data_uri(apply_colormap(np.minimum(np.nanmax(np.abs(z), axis=-1), Z_MAX), 0.0, Z_MAX, "magma"))


def verify_section(scene, reference, verification) -> str:
    """HTML fragment: verdict, the two images and the |z| map, the per-region table."""
    a, rec = verification.agreement, verification.record
    exposure = metrics.display_exposure(reference.image, reference.quantity)
    word = {"pass": "agree", "fail": "DISAGREE", "inconclusive": "INCONCLUSIVE"}[verification.verdict]
    verdict = (f'<p class="{"pass" if word == "agree" else "fail"}"><strong>{word}</strong>: '
               f'{escape(a.verdict_message(verification.margins))}</p>'
               f'<pre>{escape(chr(10).join(a.power_table(verification.margins)))}</pre>')
    width = SHOWN_PX
    figures = "".join(
        f'<figure><img width="{width}" alt="{escape(alt)}" src="{src}"><figcaption>{escape(cap)}</figcaption>'
        f'</figure>' for alt, src, cap in [
            ("reference", _shown(reference.image, exposure),
             f"reference: {reference.provenance.get('renderer_version')}, {reference.spp} spp"),
            ("engine", _shown(verification.image, exposure),
             f"{rec['engine']} {rec['engine_version']}, {rec['spp']} spp"),
            ("|z| per pixel", z_map_png(reference.image, reference.variance, verification.image,
                                        verification.variance),
             f"|z| per pixel (max over channels), 0..{Z_MAX:g}, magma")])
    head = "".join(f"<th>{h}</th>" for h in ["region", "pixels", *(f"ref {c}" for c in CHANNELS),
                                              *(f"Δ% {c}" for c in CHANNELS), *(f"z {c}" for c in CHANNELS),
                                              "min p", "pixel z sd"])
    rows = []
    for r in a.regions:
        bad = (r.p < a.level).any()
        cells = [escape(r.name), str(r.pixels), *(f"{m:.4g}" for m in r.mean_reference),
                 *(f"{100 * d:+.3f}" for d in r.relative_difference), *(f"{z:+.2f}" for z in r.z),
                 f"{float(r.p.min()):.3g}", "-" if np.isnan(r.pixel_z_sd) else f"{r.pixel_z_sd:.3f}"]
        rows.append(f'<tr class="{"fail" if bad else "pass"}">' + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    note = (f"Per region and channel, z = (engine mean − reference mean) / √(V_ref + V_engine), a region mean's "
            f"variance being the sum of its pixels' variances / n². A test fails below the Šidák per-test level "
            f"{a.level:.3g} ({a.tests} tests, family-wise α = {a.alpha:g}). Per-pixel z: sd {a.pixel_z_sd:.3f}, "
            f"robust spread {a.pixel_z_spread:.3f}, {a.pixel_z_tail:.2%} beyond |z| 3 ({a.pixel_z_below:.2%} below "
            f"−3, {a.pixel_z_above:.2%} above +3; reported, not judged). {a.spread_remark(rec['batches']) or ''} "
            f"Command: {rec['command']}")
    return (f"<h2>{escape(scene.name)}: reference against {escape(rec['engine'])}</h2>{verdict}<div>{figures}</div>"
            f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"
            f'<p class="note">{escape(note)}</p>')


def write_verify_page(folder: Path, scene, reference, verification) -> Path:
    """Write ``folder/reference-verify-<scene>.html`` (atomically), and beside it the engine's image and its
    variance of the mean as ``reference-verify-<scene>-image.exr`` and ``-variance.exr``; the page's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in scene.name)
    path = folder / f"reference-verify-{safe}.html"
    meta = {"engine": str(verification.record["engine"]), "spp": str(verification.record["spp"]),
            "batches": str(verification.record["batches"])}
    write_exr(folder / f"reference-verify-{safe}-image.exr", verification.image, meta)
    write_exr(folder / f"reference-verify-{safe}-variance.exr", verification.variance, meta)
    title = f"cbox reference verify: {scene.name} against {verification.record['engine']}"
    write_text_atomic(path, f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><title>{escape(title)}'
                            f'</title><style>{_STYLE}</style></head>\n<body>'
                            f'{verify_section(scene, reference, verification)}</body></html>\n')
    return path
