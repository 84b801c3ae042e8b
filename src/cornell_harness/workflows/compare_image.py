"""Scoring images made outside the harness (``cbox compare-image``): load them, check them, score them.

An idiff- or FLIP-style comparison of image files against a reference,
with the harness's own numbers: every image metric, by the one scorer
``cbox compare`` scores a render with
(:func:`cornell_harness.evaluate.score.score_image`), so a file written by
``cbox render`` scores exactly as ``cbox compare`` scored that render.
A check scores a chosen set (:func:`score`'s ``keys``), each value the same
as in the full set.

The reference is a stored scene's (:func:`load_scene_target`: its image,
variance and noise batch, and its named regions) or an image file
(:func:`load_file_target`: variance and noise only when they are stored
beside it, as a reference folder holds them,
:mod:`cornell_harness.store.references`).

Inputs are checked before anything is scored, and refused with one line
naming the file (:class:`cornell_harness.store.exr.ImageFileError`):

- a display-referred file (integer pixels: PNG, JPEG, 8/16-bit TIFF) unless
  a transfer says how to linearise it (:data:`INPUT_TRANSFERS`;
  floating-point files are linear already and are read as they are);
- an image whose size is not the reference's;
- a ``cbox:spp`` header that is not a positive integer, or that contradicts
  the spp given.

NaN, Inf and negative pixels are not refused: they are counted, as for any
render (:func:`cornell_harness.evaluate.metrics.invalid_pixel_counts`).

The noise yardsticks need the image's spp (its ``cbox:spp`` header, which
``cbox render`` writes, or one given) and a reference variance; without
either they are skipped, and the score says why (``noise_note``). A region's
``mean_z`` takes the image's variance from the noise model at that spp (a
file carries no variance of its own; ``cbox compare`` uses a renderer's own
variance when it reports one, so there ``mean_z`` may differ); without an
spp it is left out, not computed as if the image were noise-free (a
correct render's z would read in the tens), and a threshold on it or on a
yardstick is refused (:func:`check_spp`).

Each score carries an orientation note where the image agrees with the
reference far better flipped or mirrored than as it is
(:mod:`cornell_harness.evaluate.orientation`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Collection, Sequence

import numpy as np

from cornell_harness.evaluate import flip
from cornell_harness.evaluate import regions as named_regions
from cornell_harness.evaluate.ciede2000 import srgb_eotf
from cornell_harness.evaluate.image_scores import ImageScore, InputImage, Target
from cornell_harness.evaluate.metrics import DELTA_E_KEYS
from cornell_harness.evaluate.orientation import check_orientation
from cornell_harness.evaluate.registry import COLOUR_METRICS, check_metrics, region_metric
from cornell_harness.evaluate.score import NOISE_PREFIX, every_region_key, score_image
from cornell_harness.evaluate.thresholds import (GREY_PIXEL_METRIC, PIXEL_METRIC, Threshold, broken, fraction_above,
                                                 percent_line)
from cornell_harness.scenes.model import Scene
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY, has_colour
from cornell_harness.store.atomic import json_safe
from cornell_harness.store.exr import ImageFileError, read_exr
from cornell_harness.store.image_files import SPP_ATTRIBUTE, ImageFile, header_spp, read_image_file
from cornell_harness.store.references import (NOISE_FILE, PROVENANCE_FILE, REFERENCE_FILE, VARIANCE_FILE, Reference,
                                      ReferenceError, load_reference)
from cornell_harness.suggest import did_you_mean

#: How a display-referred (integer) file is turned into linear values, by name.
INPUT_TRANSFERS = {
    "srgb": "undo the sRGB transfer function (the EOTF of IEC 61966-2-1)",
    "linear": "take the stored values as linear, scaled to [0, 1] (a linear 16-bit image)",
}


# --------------------------------------------------------------------------
# Loading and checking
# --------------------------------------------------------------------------


def linear_pixels(image: ImageFile, transfer: str | None, exposure: float | None = None) -> np.ndarray:
    """The file's pixels as linear values: floating-point files as they are, integer ones through ``transfer``.

    An integer (display-referred) file without a transfer is refused: its
    code values are not radiance, and scoring them as if they were would give
    confident, wrong numbers. ``exposure`` is the exposure in stops the
    display-referred file was made at (its values were radiance × 2^exposure
    before the transfer); the linear values are divided by 2^exposure back.
    It does not apply to floating-point files, which are radiance already.
    """
    if image.scene_linear:
        return image.pixels
    if transfer is None:
        raise ImageFileError(f"{image.path}: {image.file_format} with {image.pixel_type} pixels is display-referred, "
                             f"not linear; say how to linearise it with --input-transfer "
                             f"({' or '.join(INPUT_TRANSFERS)})")
    if transfer not in INPUT_TRANSFERS:  # the CLI has matched its case already (cornell_harness.cli.choices)
        raise ValueError(f"unknown input transfer {transfer!r}; expected one of {', '.join(INPUT_TRANSFERS)}")
    linear = image.pixels if transfer == "linear" else srgb_eotf(image.pixels)
    if exposure:
        linear = linear / 2.0 ** exposure
    return np.asarray(linear, dtype=np.float32)


def clipped_fraction(image: ImageFile) -> float | None:
    """The fraction of a display-referred file's pixels with a channel at 0 or at the maximum code value
    (information the encoding lost: those pixels' errors are not the renderer's); None for a linear file."""
    if image.scene_linear:
        return None
    clipped = np.any((image.pixels <= 0.0) | (image.pixels >= 1.0), axis=-1)
    return float(np.count_nonzero(clipped) / clipped.size)


def image_spp(image: ImageFile, given: int | None) -> int | None:
    """The image's spp: its header's, or ``given``; a header that contradicts ``given`` is refused."""
    recorded = header_spp(image)
    if recorded is not None and given is not None and recorded != given:
        raise ImageFileError(f"{image.path}: --spp {given}, but its header {SPP_ATTRIBUTE} says {recorded}")
    return recorded if recorded is not None else given


def unique_labels(paths: Sequence[Path]) -> list[str]:
    """A label per path: its file stem, with ``-2``, ``-3``... where stems repeat."""
    seen: dict[str, int] = {}
    out = []
    for p in paths:
        stem = Path(p).stem or "image"
        seen[stem] = seen.get(stem, 0) + 1
        out.append(stem if seen[stem] == 1 else f"{stem}-{seen[stem]}")
    return out


def load_scene_target(scene: Scene) -> Target:
    """A stored scene's reference (refused when stale, :func:`cornell_harness.store.references.load_reference`)."""
    ref = load_reference(scene)
    return Target(ref, ref.folder / REFERENCE_FILE, scene)


def load_file_target(path: Path, transfer: str | None = None, exposure: float | None = None,
                     noise: bool = True) -> Target:
    """A reference image file; its variance and noise batch when a reference folder's files lie beside it.

    That is: ``path`` is a folder's ``reference.exr`` and the folder holds
    ``variance.exr``, ``noise.exr`` and ``provenance.json`` (with ``spp`` and
    ``noise_spp``), as :mod:`cornell_harness.store.references` stores them. A bare
    image is scored as radiance (a scene says otherwise: use one). ``noise=False``
    reads the image only (no noise yardstick asked for: two files fewer to read).
    """
    path = Path(path)
    file = read_image_file(path)
    image = linear_pixels(file, transfer, exposure)
    folder = path.parent
    stored = [folder / f for f in (VARIANCE_FILE, NOISE_FILE, PROVENANCE_FILE)]
    if not noise:
        return Target(Reference(image, None, None, {}, folder, DEFAULT_QUANTITY), path,
                      noise_note="no noise yardstick asked for", clipped=clipped_fraction(file))
    if path.name != REFERENCE_FILE or not all(f.is_file() for f in stored):
        note = (f"no reference variance: {path} is not a reference folder's {REFERENCE_FILE} with "
                f"{', '.join(f.name for f in stored)} beside it")
        return Target(Reference(image, None, None, {}, folder, DEFAULT_QUANTITY), path, noise_note=note,
                      clipped=clipped_fraction(file))
    try:
        provenance = json.loads((folder / PROVENANCE_FILE).read_text())
        int(provenance["spp"]), int(provenance["noise_spp"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ReferenceError(f"{folder / PROVENANCE_FILE}: unreadable, or no spp and noise_spp ({e})") from None
    variance, noise_batch = read_exr(stored[0]), read_exr(stored[1])
    for f, a in ((stored[0], variance), (stored[1], noise_batch)):
        if a.shape != image.shape:
            raise ReferenceError(f"{f}: {a.shape[1]}x{a.shape[0]}, but {path} is {image.shape[1]}x{image.shape[0]}")
    return Target(Reference(image, variance, noise_batch, provenance, folder, DEFAULT_QUANTITY), path)


def load_images(paths: Sequence[Path], target: Target, transfer: str | None = None,
               spp: int | None = None, exposure: float | None = None) -> list[InputImage]:
    """Every test image read, linearised and checked against ``target``; the first bad one is refused."""
    ref = target.reference.image
    out = []
    for path, label in zip(paths, unique_labels(paths)):
        file = read_image_file(path)
        pixels = linear_pixels(file, transfer, exposure)
        if pixels.shape != ref.shape:
            raise ImageFileError(f"{path}: image is {file.size}, but the reference {target.path} is "
                                 f"{ref.shape[1]}x{ref.shape[0]}; images of different sizes are not compared")
        out.append(InputImage(Path(path), label, pixels, image_spp(file, spp), clipped_fraction(file)))
    return out


# --------------------------------------------------------------------------
# Scoring
# --------------------------------------------------------------------------

def noise_gap(target: Target, spp: int | None) -> str | None:
    """Why the noise yardsticks cannot be computed for an image at ``spp`` against ``target``; None if they can."""
    if target.noise_note is not None:
        return target.noise_note
    if spp is None:
        return (f"no spp: the image has no {SPP_ATTRIBUTE} header and no --spp was given (--spp N gives the noise "
                "yardsticks and the regions' mean_z)")
    return None


#: The region metric that needs the image's spp (the noise model's variance at it); left out without one.
REGION_Z = "mean_z"


def needs_spp(metric: str) -> bool:
    """Whether ``metric`` (a threshold's) is computed from the image's spp: a noise yardstick or a region's z."""
    parts = region_metric(metric)
    return metric.startswith(NOISE_PREFIX) if parts is None else parts[1] == REGION_Z


def check_spp(thresholds: Sequence[Threshold], sources: Sequence[InputImage]) -> None:
    """A threshold on a metric that needs the image's spp (:func:`needs_spp`) is refused, before anything is
    scored, for an image whose spp is unknown: it could only fail (its value n/a) or, taken as noise-free, mislead."""
    for t in thresholds:
        for source in sources:
            if needs_spp(t.metric) and source.spp is None:
                raise OptionError(f"{t.metric}: {source.path} has no {SPP_ATTRIBUTE} header, and this metric "
                                  "needs the image's spp: give it with --spp N", "--spp")


def score(source: InputImage, target: Target, with_flip: bool = True,
          keys: Collection[str] | None = None) -> ImageScore:
    """Every metric of one test image against the target, by the scorer ``cbox compare`` scores a render with
    (:func:`cornell_harness.evaluate.score.score_image`; ``flip_mean`` only ``with_flip``).

    ``keys`` (:func:`cornell_harness.evaluate.registry.check_metrics`' choice for a check) computes only what they
    name, each value the same as with every metric; a ``region.*`` key scores every region of the scene, as
    the table and ``--json`` show them all.
    """
    masks = None
    if target.scene is not None and (keys is None or any(region_metric(k) for k in keys)):
        masks = named_regions.region_masks(target.scene)
        if keys is not None:
            keys = {*keys, *every_region_key(masks)}
    result = score_image(source.image, target.reference, source.spp, masks=masks, keys=keys, with_flip=with_flip,
                         noise_note=noise_gap(target, source.spp))
    regions = result.regions
    if source.spp is None:  # the region z needs the image's noise: unknown without its spp
        regions = {name: {k: v for k, v in values.items() if k != REGION_Z} for name, values in regions.items()}
    parameters = flip.flip_parameters(target.reference.image) if "flip_mean" in result.metrics else None
    orientation = check_orientation(source.image, target.reference, source.spp).note
    return ImageScore(source, result.metrics, result.noise, result.noise_note, regions, parameters,
                      result.delta_e_map, orientation)


# --------------------------------------------------------------------------
# The command's flow: what to score, scoring every image, the verdicts
# --------------------------------------------------------------------------


class OptionError(ValueError):
    """Bad input that one option of the command gave (exit 2, the message naming that option)."""

    def __init__(self, message: str, option: str):
        super().__init__(message)
        self.option = option


@dataclass
class Checks:
    """The pass/warn/fail criteria of a check: thresholds on metrics (``--fail``/``--warn``) and the share of
    pixels above a per-pixel ΔE00 (``--fail-percent`` of ``--pixel-threshold``). None of them: no check."""

    thresholds: Sequence[Threshold] = ()
    fail_percent: float | None = None
    pixel_threshold: float | None = None

    def __bool__(self) -> bool:
        return bool(self.thresholds) or self.fail_percent is not None


@dataclass
class Checked:
    """One image's score, and with checks its verdict (``--json``'s) and the broken criteria's lines."""

    score: ImageScore
    verdict: dict | None = None
    broken: list[tuple[str, str]] = field(default_factory=list)  # (level, line), fails first


@dataclass
class ImageComparison:
    """What ``cbox compare-image`` computed: the target, and each image scored and checked, in order."""

    target: Target
    images: list[Checked]
    error_maps: bool  # whether each image's ΔE00 error map is to be written

    @property
    def failed(self) -> bool:
        return any(c.verdict is not None and c.verdict["status"] == "fail" for c in self.images)


def compare_images(paths: Sequence[Path], scene: Scene | None = None, reference: Path | None = None,
                   transfer: str | None = None, spp: int | None = None, exposure: float | None = None,
                   checks: Checks = Checks(), with_flip: bool = False, every: bool = False,
                   error_maps: bool | None = None) -> ImageComparison:
    """Score ``paths`` against ``scene``'s stored reference or the ``reference`` file, and check them.

    Without checks every metric is scored and the error maps are made; a check scores what its criteria name
    and the cheap metrics (:func:`scored_keys`; ``every``: every metric) and makes the error maps only when
    ``error_maps`` asks. HDR-FLIP (``flip_mean``, more than every other metric together) is scored
    ``with_flip`` or where a threshold names it. Inputs are checked before anything is scored: refused with
    :class:`OptionError` or, naming the file, ``ImageFileError``.
    """
    maps = error_maps if error_maps is not None else not checks
    keys = scored_keys([t.metric for t in checks.thresholds], checks.fail_percent is not None or maps, with_flip,
                       every or not checks)
    target = (load_scene_target(scene) if scene is not None else
              load_file_target(reference, transfer, exposure,
                               noise=keys is None or any(k.startswith(NOISE_PREFIX) for k in keys)))
    check_regions(checks.thresholds, target)
    check_quantity(checks, target)
    sources = load_images(paths, target, transfer, spp, exposure)
    check_spp(checks.thresholds, sources)
    if exposure is not None and all(s.clipped is None for s in (*sources, target)):
        raise OptionError("applies to display-referred (integer) images only, and every image given is "
                          "floating-point (radiance already)", "--exposure")
    flip_too = with_flip or any(t.metric == "flip_mean" for t in checks.thresholds)
    scored = [check(score(source, target, with_flip=flip_too, keys=keys), checks, target) for source in sources]
    return ImageComparison(target, scored, maps)


def scored_keys(named: Sequence[str], de_map: bool, with_flip: bool, every: bool) -> frozenset[str] | None:
    """The metrics a check scores (:func:`cornell_harness.evaluate.registry.check_metrics`: the ``named`` ones and
    the cheap ones; the ΔE00 statistics too where the map is made anyway, ``de_map``: for --fail-percent or the
    error map), or None for every metric (``every``: not a check, --all-metrics, --report)."""
    if every:
        return None
    return check_metrics([*named, *(DELTA_E_KEYS if de_map else ()), *(["flip_mean"] if with_flip else [])])


def check_regions(thresholds: Sequence[Threshold], target: Target) -> None:
    """A region threshold needs a scene that names the region: refused otherwise, before anything is scored."""
    for t in thresholds:
        parts = region_metric(t.metric)
        if parts is None:
            continue
        regions = target.scene.regions if target.scene is not None else {}
        if parts[0] not in regions:
            where = f"scene {target.scene.name!r}" if target.scene is not None else "a --reference file"
            raise OptionError(f"{t.metric}: {where} has no region {parts[0]!r}{did_you_mean(parts[0], regions)}",
                              f"--{t.level}")


def check_quantity(checks: Checks, target: Target) -> None:
    """A threshold the target's quantity does not define is refused, before anything is scored: an image
    without colour (ambient occlusion, one value per pixel) has no ΔE00 or HDR-FLIP (the registry's
    COLOUR_METRICS), so a threshold on them could never pass. (--fail-percent counts its pixels by their own
    error, :func:`pixel_errors`.)"""
    quantity = target.reference.quantity
    if has_colour(quantity):
        return
    what = f"scene {target.label!r} holds {quantity}, which has no colour"
    for t in checks.thresholds:
        if (region_metric(t.metric) or (None, t.metric))[1] in COLOUR_METRICS:
            raise OptionError(f"{t.metric}: {what}: a colour metric (ΔE00, HDR-FLIP) is not defined on it; "
                              "use rmse, rel_mse, psnr or ssim", f"--{t.level}")


def pixel_errors(result: ImageScore, target: Target) -> tuple[str, str, np.ndarray]:
    """What --fail-percent counts per pixel: (its name in a line, its --json key, the (H, W) errors). ΔE00 of a
    radiance image (the error map's); for a quantity without colour (ambient occlusion, grey) the absolute
    difference of its one value."""
    if has_colour(target.reference.quantity):
        return PIXEL_METRIC, "percent_pixels_delta_e2000_above", result.delta_e_map
    img, ref = np.asarray(result.source.image, np.float64), np.asarray(target.reference.image, np.float64)
    return GREY_PIXEL_METRIC, "percent_pixels_abs_error_above", np.abs(img - ref).mean(axis=-1)


def check(result: ImageScore, checks: Checks, target: Target) -> Checked:
    """One score against the checks: the verdict for --json and the broken criteria's lines (no checks: none)."""
    if not checks:
        return Checked(result)
    label, row = result.source.label, result.row()
    rows = [{"metric": t.metric, "level": t.level, "limit": t.value, "value": row.get(t.metric),
             "broken": t.exceeded(row.get(t.metric))} for t in checks.thresholds]
    lines = [(t.level, t.line(label, row.get(t.metric))) for t in broken(checks.thresholds, row)]
    if checks.fail_percent is not None:
        name, key, errors = pixel_errors(result, target)
        percent = 100 * fraction_above(errors, checks.pixel_threshold)
        rows.append({"metric": key, "level": "fail", "limit": checks.fail_percent,
                     "pixel_threshold": checks.pixel_threshold, "value": percent,
                     "broken": percent > checks.fail_percent})
        if percent > checks.fail_percent:
            lines.append(("fail", percent_line(label, percent, checks.fail_percent, checks.pixel_threshold, name)))
    status = ("fail" if any(c["broken"] and c["level"] == "fail" for c in rows)
              else "warn" if any(c["broken"] for c in rows) else "pass")
    return Checked(result, json_safe({"status": status, "checks": rows}), lines)
