"""Reading an image file of any format OpenImageIO knows, with what its header says about the pixels.

For images made outside the harness (``cbox compare-image``). What the
pixels mean depends on how they are stored: floating-point pixels (OpenEXR,
float TIFF, Radiance HDR, PFM) are scene-linear values; integer pixels (PNG,
JPEG, 8- and 16-bit TIFF) are display-referred code values, which mean
radiance only once a transfer function is undone. This module reports which
(:attr:`ImageFile.scene_linear`) and leaves the decision to the caller. The
harness's own images are float32 OpenEXR (:mod:`cornell_harness.store.exr`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class ImageFileError(OSError):
    """An image file is missing, unreadable, or not an RGB image."""


#: The header attribute the spp of an image is written into (``cbox render``, experiment folders, references).
SPP_ATTRIBUTE = "cbox:spp"

#: OpenImageIO's names of the floating-point pixel types.
FLOAT_PIXEL_TYPES = ("half", "float", "double")


@dataclass(frozen=True)
class ImageFile:
    """An image as read from a file: its RGB pixels and what the file says about them."""

    path: Path
    pixels: np.ndarray = field(repr=False)  # (H, W, 3) float32; integer types scaled to [0, 1] by OpenImageIO
    pixel_type: str  # as stored: "half", "float", "uint8", "uint16", ...
    file_format: str  # OpenImageIO's name of the format: "openexr", "png", "jpeg", "tiff", ...
    metadata: dict = field(default_factory=dict)  # the header's string attributes (e.g. cbox:spp)

    @property
    def scene_linear(self) -> bool:
        """Floating-point pixels: linear values. Integer pixels are display-referred code values."""
        return self.pixel_type in FLOAT_PIXEL_TYPES

    @property
    def size(self) -> str:
        """``WIDTHxHEIGHT``, as messages name it."""
        return f"{self.pixels.shape[1]}x{self.pixels.shape[0]}"


def read_image_file(path: str | Path) -> ImageFile:
    """The first three channels (RGB) of ``path``'s first subimage, with its pixel type, format and header.

    A missing or unreadable file, or one with fewer than three channels, is
    :class:`ImageFileError` naming the file.
    """
    import OpenImageIO as oiio

    path = Path(path)
    if not path.is_file():
        raise ImageFileError(f"{path}: {'is a folder' if path.is_dir() else 'no such file'}")
    # PFM stores rows bottom to top; OpenImageIO returns them in file order unless told to flip.
    config = oiio.ImageSpec()
    config.attribute("pnm:pfmflip", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise ImageFileError(f"{path}: cannot read image: {oiio.geterror().strip() or 'unknown format'}")
    try:
        spec, file_format = inp.spec(), inp.format_name()
        if spec.nchannels < 3:
            raise ImageFileError(f"{path}: expected 3 channels (RGB), found {spec.nchannels}")
        data = inp.read_image(0, 0, 0, 3, oiio.FLOAT)
        metadata = {a.name: a.value for a in spec.extra_attribs if isinstance(a.value, str)}
    finally:
        inp.close()
    if data is None:
        raise ImageFileError(f"{path}: cannot read image: {oiio.geterror().strip()}")
    pixels = np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, 3)
    return ImageFile(path, pixels, str(spec.format), file_format, metadata)


def header_spp(image: ImageFile) -> int | None:
    """The spp its ``cbox:spp`` header records; None without one."""
    text = image.metadata.get(SPP_ATTRIBUTE)
    if text is None:
        return None
    try:
        spp = int(text)
    except ValueError:
        spp = 0
    if spp < 1:
        raise ImageFileError(f"{image.path}: header {SPP_ATTRIBUTE} = {text!r} is not a positive integer")
    return spp
