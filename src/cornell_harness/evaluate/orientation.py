"""Whether an image looks flipped or mirrored against its reference (``cbox compare-image``'s orientation note).

An image written with its rows in the wrong order (a PFM read in file order,
a renderer whose film's y points up) or with x mirrored (a camera of the
other handedness) scores as one large error that does not say why. This
check says why, as a note on the score; it changes no number.

The rule, on the relMSE (:func:`cornell_harness.evaluate.metrics.rel_mse`) of
the image and the reference averaged over square blocks of pixels,
:data:`BLOCKS` blocks along the shorter side (:func:`block_means`: a flip
moves walls and lights, which averaging keeps, while it divides the noise's
variance by the pixels in a block), broken pixels black and the worst
:data:`TRIM` of blocks dropped so that a firefly decides nothing:

- the image transformed (:data:`TRANSFORMS`: flipped vertically, mirrored
  horizontally, both) agrees with the reference at under :data:`RATIO` of
  the relMSE it has as it is, and
- as it is, its relMSE is above :data:`NOISE_FACTOR` times the relMSE noise
  alone gives at its spp (:func:`noise_rel_mse`), where the spp and the
  reference's variance are known.

A transform does not remove noise: a correct image flipped keeps its noise
and gains the scene's asymmetry, so its relMSE only grows. The Cornell box
is nearly symmetric left to right but for its colours (red wall left, green
right) and its two blocks, so a mirror shows in the colours. A scene
symmetric under a transform (the furnaces) agrees as well transformed as not,
and is never flagged (the ratio is about 1).

Its false-alarm rate on correct renders, and how often it catches a flipped
or mirrored one, are measured by ``benchmarks/orientation.py`` (the path
tracer's renders of every stored scene, many seeds, low spp) and stated in
BENCHMARKS.md; ``tests/evaluate/test_orientation.py`` holds a fixed-seed
sample of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate import noise
from cornell_harness.evaluate.pixels import all_finite, zero_broken_pixels

if TYPE_CHECKING:
    from cornell_harness.store.references import Reference

#: The transformed image's relMSE must be under this fraction of the untransformed one's.
RATIO = 0.25
#: The untransformed relMSE must be above this multiple of what noise alone gives at the image's spp.
NOISE_FACTOR = 2.0
#: The fraction of worst blocks relMSE drops here (fireflies), as ``metrics.rel_mse``'s ``trim``.
TRIM = 0.01
#: How many blocks the shorter side is averaged into (a side shorter than this: pixels, unaveraged).
BLOCKS = 32

#: What each transform is called in the note, and what it does to an (H, W, 3) image.
TRANSFORMS = {
    "flipped vertically": lambda a: a[::-1],
    "mirrored horizontally": lambda a: a[:, ::-1],
    "flipped vertically and mirrored horizontally (rotated 180°)": lambda a: a[::-1, ::-1],
}


@dataclass(frozen=True)
class Orientation:
    """The check's numbers: relMSE as it is, under each transform, and what noise alone would give."""

    rel_mse: float  # the image as it is
    transformed: dict  # transform name -> relMSE of the image so transformed
    noise_rel_mse: float | None  # noise alone at the image's spp; None where unknown

    @property
    def looks(self) -> str | None:
        """The transform the image looks to have undergone, or None: the best one if it passes the rule."""
        name = min(self.transformed, key=self.transformed.get)
        best = self.transformed[name]
        if not best < RATIO * self.rel_mse:  # NaN: not flagged
            return None
        if self.noise_rel_mse is not None and not self.rel_mse > NOISE_FACTOR * self.noise_rel_mse:
            return None
        return name

    @property
    def note(self) -> str | None:
        """The sentence the score carries, or None."""
        name = self.looks
        if name is None:
            return None
        return (f"image looks {name}: its relMSE is {self.transformed[name]:.3g} so transformed, "
                f"{self.rel_mse:.3g} as it is")


def block_size(shape: tuple) -> int:
    """The side in pixels of the blocks an image of ``shape`` (H, W, ...) is averaged over."""
    return max(1, min(shape[0], shape[1]) // BLOCKS)


def block_means(image: np.ndarray, size: int) -> np.ndarray:
    """The mean of each ``size`` × ``size`` block of an (H, W, C) image (rows and columns beyond a whole block
    dropped)."""
    h, w = image.shape[0] // size, image.shape[1] // size
    a = np.asarray(image)[:h * size, :w * size]
    # rows, then columns: two reductions over a contiguous axis each, several times faster than one over both
    rows = a.reshape(h, size, w * size, -1).sum(axis=1, dtype=np.float64)
    return rows.reshape(h, w, size, -1).sum(axis=2) / size**2


def noise_rel_mse(reference: "Reference", spp: int) -> float:
    """The expected relMSE, on :func:`block_means`, of a correct image at ``spp`` against ``reference`` under the
    noise model (:func:`cornell_harness.evaluate.noise.difference_variance`; pixels independent, so a block
    mean's variance is its pixels' mean variance over their number)."""
    size = block_size(reference.image.shape)
    var = block_means(noise.difference_variance(reference.variance, reference.spp, spp), size) / size**2
    ref = block_means(reference.image, size)
    return float(np.mean(var / (ref**2 + metrics.REL_MSE_EPS)))


def check_orientation(image: np.ndarray, reference: "Reference", spp: int | None = None) -> Orientation:
    """The relMSE of ``image`` against ``reference`` as it is and under each of :data:`TRANSFORMS` (on
    :func:`block_means`), and the noise level at ``spp`` when it and the reference's variance are known.

    The transforms act on the block means (the same as on the pixels where the blocks tile the image; where
    they do not, on its top-left whole blocks), so the check costs one pass over the pixels of the image, of
    the reference and (with ``spp``) of its variance, the rest on the block means (1024 of them at 256²).
    """
    size = block_size(reference.image.shape)
    img = np.asarray(image)
    img = block_means(img if all_finite(img) else zero_broken_pixels(img), size)
    ref = block_means(reference.image, size)
    transformed = {name: metrics.rel_mse(f(img), ref, trim=TRIM) for name, f in TRANSFORMS.items()}
    known = spp is not None and reference.variance is not None
    return Orientation(metrics.rel_mse(img, ref, trim=TRIM), transformed,
                       noise_rel_mse(reference, spp) if known else None)
