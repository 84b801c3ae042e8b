"""The least-squares constant against a reference: an oracle's fit (the ambient renderer's ``ambient = oracle``).

An image linear in one constant per channel, D + c·B (D: the image without
the term, B: the term at c = 1), is closest to the reference R in the squared
error at c = Σ B·(R − D) / Σ B² per channel over all pixels: least squares
in closed form. It is an **oracle**, not an estimate a renderer could make
from the scene, for measuring the most any such constant could buy. The render
path (:mod:`cornell_harness.workflows.render`) renders D and D + B and fits c here,
for a renderer that declares it (:class:`cornell_harness.adapters.api.ReferenceFit`).
"""

from __future__ import annotations

import numpy as np


def least_squares_constant(direct: np.ndarray, unit: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The constant c (3,) minimising Σ (D + c·B − R)² per channel: Σ B(R − D) / Σ B²; 0 where B is all 0.

    ``direct`` is D, ``unit`` is B (the term at c = 1), ``reference`` R, all (H, W, 3).
    """
    d, b, r = (np.asarray(x, np.float64) for x in (direct, unit, reference))
    num = (b * (r - d)).sum(axis=(0, 1))
    den = (b * b).sum(axis=(0, 1))
    return np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), 0.0)


def fitted_image(direct: np.ndarray, with_unit: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(D + c·B as float32, c): ``direct`` D and ``with_unit`` D + B rendered with the same seed, so B is their
    difference sample by sample; c is :func:`least_squares_constant` against ``reference``."""
    d64 = direct.astype(np.float64)
    b = with_unit.astype(np.float64) - d64
    c = least_squares_constant(d64, b, reference)
    return (d64 + c * b).astype(np.float32), c
