"""Seeds and sample budgets: the one derivation every renderer uses, ours and Mitsuba's.

A render of ``spp`` samples per pixel is done in passes (:func:`spp_passes`).
Pass ``k`` of a render seeded with ``seed`` has the 64-bit key
:func:`pass_key` ``(seed, k)``, from NumPy's ``SeedSequence([seed, k])``
(hash-based, so seeds k and k + 1 give unrelated streams). Our renderers key
their counter-based generator with it (:mod:`cornell_harness.renderers.core.rng`); a renderer
that takes a 32-bit seed (Mitsuba) gets :func:`pass_seed`, the key's low
32 bits, which is exactly ``SeedSequence``'s first 32-bit word.
"""

from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np


def pass_key(seed: int, index: int, stream: int = 0) -> np.uint64:
    """64-bit key of pass ``index`` of a render seeded with ``seed``.

    ``stream`` tells apart a renderer's kinds of pass that share an index
    (SPPM's camera pass and photon pass of one iteration, a photon map's
    photons): stream 0 is ``SeedSequence([seed, index])``, the camera passes
    of every renderer; stream s > 0 is ``SeedSequence([seed, index, s])``.
    """
    if seed < 0 or index < 0 or stream < 0:
        raise ValueError(f"seed, pass index and stream must be non-negative, got {seed}, {index}, {stream}")
    entropy = [seed, index] if stream == 0 else [seed, index, stream]
    return np.random.SeedSequence(entropy).generate_state(1, dtype=np.uint64)[0]


def frame_seed(seed: int, frame: int) -> int:
    """The seed of frame ``frame`` of a sequence seeded with ``seed``: 31 bits of ``SeedSequence([seed, frame,
    FRAME_STREAM])`` (a seed any program's int reads), so the frames of one sequence draw unrelated streams and
    frame 0 is not the still image's ``seed`` (a stateless renderer renders each frame as a still image with it)."""
    if seed < 0 or frame < 0:
        raise ValueError(f"seed and frame must be non-negative, got {seed}, {frame}")
    state = np.random.SeedSequence([seed, frame, FRAME_STREAM]).generate_state(1, dtype=np.uint64)[0]
    return int(state & np.uint64(0x7FFFFFFF))


#: The stream that tells frame seeds apart from pass keys (:func:`pass_key` streams are a renderer's kinds of pass).
FRAME_STREAM = 1 << 20


def pass_seed(seed: int, index: int) -> int:
    """32-bit seed of pass ``index``: the low word of :func:`pass_key`, for renderers that take 32 bits."""
    return int(pass_key(seed, index) & np.uint64(0xFFFFFFFF))


def spp_passes(spp: int, max_per_pass: int, checkpoints: Sequence[int] = ()) -> Iterator[int]:
    """Sizes of consecutive passes summing to ``spp``.

    Passes double (1, 1, 2, 4, ...) up to ``max_per_pass``, then stay at that
    size, so every power-of-two spp up to ``max_per_pass`` is a pass boundary and
    a render's image does not depend on which of those checkpoints were
    asked for. Any other checkpoint in (0, spp) adds a boundary of its own.
    """
    if spp < 1:
        raise ValueError(f"spp must be >= 1, got {spp}")
    if max_per_pass < 1:
        raise ValueError(f"max_per_pass must be >= 1, got {max_per_pass}")
    stops = {int(c) for c in checkpoints if 0 < c < spp} | {spp}
    b = 1
    while b < spp:
        stops.add(b)
        b += min(b, max_per_pass)
    done = 0
    for stop in sorted(stops):
        yield stop - done
        done = stop
