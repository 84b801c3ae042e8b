"""Reading and writing float32 RGB OpenEXR images through OpenImageIO.

Writes are atomic (:mod:`cornell_harness.store.atomic`): an interrupted write never leaves
a truncated EXR behind.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cornell_harness.store.atomic import atomic_path
from cornell_harness.store.image_files import ImageFileError, read_image_file

__all__ = ["ImageFileError", "read_exr", "write_exr"]


def write_exr(path: str | Path, image: np.ndarray, metadata: dict[str, str] | None = None, half: bool = False) -> None:
    """Write an (H, W, 3) image as a float32 (``half``: float16), ZIP-compressed EXR.

    Half floats take about a third of the bytes of float32 pixels, noisy ones included (ZIP cannot compress
    their random low bits), for a rounding of at most 2^-11 relative, but they end at 65504 and flush values
    below about 6e-8 to zero: the caller says when that is harmless.

    ``path`` must end in ``.exr``: EXR bytes under another name (``x.png``)
    would mislead every viewer, so that is refused (:class:`ImageFileError`),
    as is a path that cannot be written (a folder, no permission).
    """
    import OpenImageIO as oiio

    path = Path(path)
    if path.suffix.lower() != ".exr":
        raise ImageFileError(f"{path}: unsupported extension {path.suffix or '(none)'!r}; "
                             "images are written as OpenEXR (.exr)")
    if path.is_dir():
        raise ImageFileError(f"{path}: is a folder, expected an .exr file name")
    img = np.ascontiguousarray(image, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) image, got shape {img.shape}")
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.HALF if half else oiio.FLOAT)
    spec.attribute("compression", "zip")
    for k, v in (metadata or {}).items():
        spec.attribute(k, str(v))
    try:
        with atomic_path(path) as tmp:
            out = oiio.ImageOutput.create("exr")
            if out is None or not out.open(str(tmp), spec):
                raise ImageFileError(f"{path}: cannot write EXR: {oiio.geterror()}")
            ok = out.write_image(img)
            out.close()
            if not ok:
                raise ImageFileError(f"{path}: cannot write EXR: {oiio.geterror()}")
    except ImageFileError:
        raise
    except OSError as e:  # the folder cannot be made or written (a file in the way, no permission, full disk)
        raise ImageFileError(f"{path}: cannot write: {e.strerror or e}") from None


def read_exr(path: str | Path) -> np.ndarray:
    """Read an RGB image as float32 (H, W, 3) (:func:`cornell_harness.store.image_files.read_image_file`'s pixels)."""
    return read_image_file(path).pixels

