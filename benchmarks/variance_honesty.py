"""Variance honesty both ways (issue 29): the variance check's false alarms and power, and AO's z spread per band.

Run (7 minutes on the shared 2-core machine)::

    .venv/bin/python -m benchmarks.variance_honesty --seeds 20 --ao-seeds 8 --markdown docs/gate-detection.md

``--part check`` or ``--part ao`` runs one of the two; ``--expectation NAME``
(repeatable) runs (1) for those expectations only, and with ``--markdown``
replaces only their rows of the table, saying so under it.

(1) Every unbiased expectation of ``gate.toml`` whose renderer reports a
    variance (Mitsuba's radiance adapter reports none, so its expectations are
    skipped, said in the table), at its spp, seeds ``0 .. seeds-1`` (added to
    the expectation's seed), at a resolution of at most :data:`SIDE` pixels
    a side to keep it affordable: a larger scene is rendered with
    ``camera.resolution`` divided by k and compared with its stored reference
    averaged over k×k blocks (exact for the box filter every renderer and
    reference here uses; the reference's variance of a block mean is the
    block's sum over k⁴). The renderer's variance is then used as reported
    (F = 1: false alarms) and divided by 2 and 4 and multiplied by 4 (power),
    through :func:`cornell_harness.evaluate.variance_check.variance_check` at the
    gate's level (the Šidák share of ``alpha``).
(2) ``ao`` on ``cornell-box-ao`` at the gate's 64 spp and full resolution,
    seeds ``0 .. ao-seeds-1``: z = (render − reference)/√(reported + reference
    variance) per pixel, and per band of the reference's AO ([0, 0.1), ...,
    [0.9, 1]) its spread over the seeds: the root of the mean, over the band's
    pixels, of each pixel's sample variance of z across seeds (a pixel's own
    bias, which the agreement test judges, does not enter), and the root mean
    square of z. Pixels that agree with the reference exactly (d = 0: misses,
    AO exactly 1) say nothing and are left out, as the variance check does.
    Each band's spread is held to :func:`band_window`.

With ``--markdown``, the blocks ``variance_honesty.py`` (1) and
``variance_honesty.py#ao`` (2) of the file are rewritten, each by the part
that ran (``benchmarks/markdown_blocks.py``).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.stats import chi2

from benchmarks import markdown_blocks
from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate.variance_check import variance_check
from cornell_harness.gate.checks import statistical_alpha
from cornell_harness.gate.config import load_config
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference

ROOT = Path(__file__).resolve().parent.parent
BLOCK = "variance_honesty.py"
AO_BLOCK = "variance_honesty.py#ao"
SIDE = 64  # largest side rendered for (1)
FACTORS = (1.0, 0.5, 0.25, 4.0)  # reported / true variance
BANDS = np.round(np.arange(0.0, 1.0, 0.1), 1)
WINDOW = (0.9, 1.1)  # issue 29: the z spread per band, over 8 seeds
WINDOW_LEVEL = 1e-3  # chance, each side, that a band whose true spread is at the window's edge falls outside it


def block_mean(a: np.ndarray, k: int) -> np.ndarray:
    """Means over k×k blocks of an (H, W, 3) image."""
    h, w, c = a.shape
    return a.reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def reduced(exp) -> tuple:
    """The scene at ≤ SIDE pixels a side and its reference averaged to match: (scene, image, variance, k)."""
    base = resolve_scene(exp.scene)
    ref = load_reference(base)
    k = max(1, base.camera.width // SIDE)
    if k == 1:
        return base, ref.image.astype(np.float64), ref.variance.astype(np.float64), 1
    scene = resolve_scene(exp.scene, [f"camera.resolution=[{base.camera.width // k},{base.camera.height // k}]"])
    var = block_mean(ref.variance.astype(np.float64), k) / (k * k)
    return scene, block_mean(ref.image.astype(np.float64), k), var, k


def false_alarms(seeds: int, only: Sequence[str] = ()) -> tuple[list[str], list[str]]:
    """(1), for every unbiased expectation or those named in ``only``: the text around the table, and its rows."""
    cfg = load_config(ROOT / "gate.toml")
    level = statistical_alpha(cfg.alpha)
    rows, skipped = [], []
    for exp in (e for e in cfg.expectations if e.unbiased and (not only or e.name in only)):
        entry = resolve([exp.renderer])[0]
        scene, ref, ref_var, k = reduced(exp)
        fails = defaultdict(lambda: [0, 0])  # factor -> [understated, overstated]
        ratios, ts = [], []
        for s in range(seeds):
            r = entry.renderer.render(scene, exp.spp, exp.seed + s)
            if r.variance is None:
                skipped.append(exp.name)
                break
            img = np.where(np.isfinite(r.image), r.image, 0.0).astype(np.float64)
            for f in FACTORS:
                v = variance_check(img, r.variance.astype(np.float64) * f, ref, ref_var, exp.spp, level)
                fails[f][0] += v.understated
                fails[f][1] += v.overstated
                if f == 1.0:
                    ratios.append(v.ratio)
                    ts.append(v.t_under)
        else:
            w, h = scene.camera.width, scene.camera.height
            cells = " | ".join(f"{fails[f][0] + fails[f][1]}/{seeds}" for f in FACTORS)
            rows.append(f"| {exp.name} | {w}×{h}{f' (÷{k})' if k > 1 else ''} | {cells} | "
                        f"{min(ratios):.2f}-{max(ratios):.2f} | {max(ts):.1f} |")
            print(rows[-1], flush=True)
    head = ["| expectation | rendered at | F = 1 (false alarms) | F = ½ | F = ¼ | F = 4 | Σd²/Σv at F = 1 | "
            "largest t at F = 1 |", "|---|---|---|---|---|---|---|---|"]
    return ([f"Variance check at the gate's level (α = {cfg.alpha:g}, Šidák share {level:.3g}; understatement "
             f"t-test at half of it), seeds 0-{seeds - 1}: runs failed, by reported/true variance F:", ""]
            + head + ["ROWS"]
            + ["", "Skipped, no reported variance: " + ", ".join(sorted(set(skipped))) + "." if skipped else ""]), rows


def with_rows(old_body: str, rows: list[str], note: str) -> str:
    """The check block's ``old_body`` with the table rows of the same expectations replaced by ``rows``, and
    ``note`` (saying which rows ran again, and how) under the table, in place of any such note before."""
    new = {r.split(" | ")[0]: r for r in rows}
    out, missing = [], dict(new)
    for line in old_body.splitlines():
        if line.startswith("Rows run again"):
            continue
        key = line.split(" | ")[0]
        out.append(new.get(key, line))
        missing.pop(key, None)
    if missing:
        raise SystemExit(f"not in the table, run everything: {sorted(missing)}")
    end = max(i for i, line in enumerate(out) if line.startswith("| "))
    out = out[:end + 1] + ["", note] + out[end + 1:]
    return "\n".join(line for i, line in enumerate(out) if line or i == 0 or out[i - 1])  # one blank between


def band_window(pixels: int, seeds: int, level: float = WINDOW_LEVEL) -> tuple[float, float]:
    """The range a band's z spread over ``seeds`` seeds is held to: :data:`WINDOW`, widened by the spread's
    own sampling error where the band is small.

    With normal z of spread σ at every pixel, the band's S² (the mean over
    its N pixels of each pixel's sample variance over the seeds) is
    σ²·χ²_k/k, k = N(seeds − 1); q_lo and q_hi are χ²_k/k's quantiles at
    ``level`` and 1 − ``level``. Where a spread of exactly 1 stays inside
    0.9-1.1 with probability 1 − ``level`` each side (√q_lo ≥ 0.9 and
    √q_hi ≤ 1.1: from N = 62 pixels up at 8 seeds) the window is 0.9-1.1
    itself. A smaller band's is [0.9·√q_lo, 1.1·√q_hi]: a renderer whose
    spread is anywhere in 0.9-1.1 falls outside it with probability below
    ``level`` each side. For the 39 pixels of [0.1, 0.2) on cornell-box-ao:
    [0.78, 1.25]. (Tails heavier than normal, as z has near AO 1, widen S's
    own spread; the bands there hold thousands of pixels.)
    """
    k = pixels * (seeds - 1)
    q_lo, q_hi = chi2.ppf([level, 1.0 - level], k) / k
    lo, hi = WINDOW
    exact_one = np.sqrt(q_lo) >= lo and np.sqrt(q_hi) <= hi
    return (lo, hi) if exact_one else (lo * float(np.sqrt(q_lo)), hi * float(np.sqrt(q_hi)))


def ao_bands(seeds: int, spp: int = 64) -> list[str]:
    scene = resolve_scene("cornell-box-ao")
    ref = load_reference(scene)
    r0 = ref.image[..., 0].astype(np.float64)
    renderer = resolve(["ao"])[0].renderer
    zs = []
    for s in range(seeds):
        r = renderer.render(scene, spp, s)
        d = r.image[..., 0].astype(np.float64) - r0
        v = r.variance[..., 0].astype(np.float64) + ref.variance[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            zs.append(np.where(d == 0, np.nan, d / np.sqrt(v)))
    z = np.array(zs)
    spread, rms, counts, worst = band_spreads(z, r0)
    inf = np.any(np.isinf(z), axis=0)
    lost = [int((inf & (r0 >= lo) & ((r0 < lo + 0.1) if lo < 0.9 else (r0 <= 1.0))).sum()) for lo in BANDS]
    rows = []
    for lo, n, sp, rm, w, x in zip(BANDS, counts, spread, rms, worst, lost):
        band = f"| [{lo:.1f}, {lo + 0.1:.1f}{']' if lo == 0.9 else ')'} | "
        if n:
            win = band_window(n, seeds)
            rows.append(band + f"{n} | {sp:.3f} | {win[0]:.2f}-{win[1]:.2f} | "
                        f"{'yes' if win[0] <= sp <= win[1] else '**no**'} | {rm:.3f} | {w:.1f} | {x} |")
        else:
            rows.append(band + f"0 (every pixel exact: misses) | - | - | - | - | - | {x} |")
    return ([f"`ao` on cornell-box-ao, 64 spp, 256×256, seeds 0-{seeds - 1}: spread of z per band of the "
             "reference's AO (pixels with a finite z at every seed), and the window it is held to "
             f"(`band_window`: {WINDOW[0]}-{WINDOW[1]}, widened by the spread's own sampling error in a band "
             f"too small for it, {WINDOW_LEVEL:g} each side):", "",
             "| AO band | pixels | spread (within pixel, over seeds) | window | within | rms z | largest abs(z) | "
             "pixels left out: variance 0 and d ≠ 0 at some seed |",
             "|---|---|---|---|---|---|---|---|"] + rows)


def band_spreads(z: np.ndarray, ref: np.ndarray):
    """Per band of ``ref``: the within-pixel spread of z (seeds, H, W) over seeds, its rms, pixels, largest |z|."""
    ok = np.all(np.isfinite(z), axis=0)
    within = z.var(axis=0, ddof=1)
    out = [], [], [], []
    for lo in BANDS:
        m = (ref >= lo) & ((ref < lo + 0.1) if lo < 0.9 else (ref <= 1.0)) & ok
        n = int(m.sum())
        vals = (np.sqrt(within[m].mean()), np.sqrt((z[:, m] ** 2).mean()), n, np.abs(z[:, m]).max()) if n else \
            (np.nan, np.nan, 0, np.nan)
        for lst, x in zip(out, vals):
            lst.append(x)
    return out


def duration(seconds: float) -> str:
    return f"{seconds / 60:.0f} min" if seconds >= 90 else f"{seconds:.0f} s"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--ao-seeds", type=int, default=8)
    ap.add_argument("--part", choices=("all", "check", "ao"), default="all",
                    help="(1) the variance check, (2) ao's z spread per band, or both")
    ap.add_argument("--expectation", action="append", default=[],
                    help="run (1) for this expectation only (repeatable); --markdown replaces its rows")
    ap.add_argument("--markdown", type=Path)
    args = ap.parse_args(argv)
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    command = command.replace(".venv/bin/python benchmarks/variance_honesty.py", ".venv/bin/python -m benchmarks.variance_honesty")
    bodies, commands = {}, {}
    if args.part in ("all", "check"):
        t0 = time.perf_counter()
        text, rows = false_alarms(args.seeds, args.expectation)
        took = f"`{command}` ({duration(time.perf_counter() - t0)})"
        if args.expectation:
            note = f"Rows run again: {', '.join(args.expectation)}, by {took}."
            print(note, flush=True)
            if args.markdown:
                old = {b.name: b for b in markdown_blocks.parse(args.markdown.read_text(encoding="utf-8"))[1]}
                lines = args.markdown.read_text(encoding="utf-8").splitlines()
                bodies[BLOCK] = with_rows("\n".join(lines[old[BLOCK].begin + 1:old[BLOCK].end]), rows, note)
                commands[BLOCK] = old[BLOCK].command  # the rest of the table is still that command's
        else:
            i = text.index("ROWS")
            bodies[BLOCK] = "\n".join(text[:i] + rows + text[i + 1:] + ["", f"Command: {took}."])
            commands[BLOCK] = command
            print(bodies[BLOCK], flush=True)
    if args.part in ("all", "ao"):
        t0 = time.perf_counter()
        lines = ao_bands(args.ao_seeds)
        bodies[AO_BLOCK] = "\n".join(lines + ["", f"Command: `{command}` ({duration(time.perf_counter() - t0)})."])
        commands[AO_BLOCK] = command
        print(bodies[AO_BLOCK], flush=True)
    if args.markdown:
        for name, body in bodies.items():
            markdown_blocks.write_blocks([args.markdown], {name: body}, commands[name])
    return 0


if __name__ == "__main__":
    sys.exit(main())
