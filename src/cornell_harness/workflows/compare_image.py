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
variance when it reports one, so there ``mean_z`` may differ).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Collection, Sequence

import numpy as np

from cornell_harness.evaluate import flip
from cornell_harness.evaluate import regions as named_regions
from cornell_harness.evaluate.ciede2000 import srgb_eotf
from cornell_harness.evaluate.image_scores import ImageScore, InputImage, Target
from cornell_harness.evaluate.registry import region_metric
from cornell_harness.evaluate.score import every_region_key, score_image
from cornell_harness.scenes.model import Scene
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY
from cornell_harness.store.exr import ImageFileError, read_exr
from cornell_harness.store.image_files import SPP_ATTRIBUTE, ImageFile, header_spp, read_image_file
from cornell_harness.store.references import (NOISE_FILE, PROVENANCE_FILE, REFERENCE_FILE, VARIANCE_FILE, Reference,
                                      ReferenceError, load_reference)

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
        return f"no spp: the image has no {SPP_ATTRIBUTE} header and no --spp was given"
    return None


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
    parameters = flip.flip_parameters(target.reference.image) if "flip_mean" in result.metrics else None
    return ImageScore(source, result.metrics, result.noise, result.noise_note, result.regions, parameters,
                      result.delta_e_map)

