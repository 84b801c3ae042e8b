"""External images are read the right way up in every floating-point format compare-image accepts.

The image is asymmetric every way (a gradient down and across, a marked top-left corner, 7 wide by 5 high), written
by OpenImageIO and, for PFM and Radiance HDR, as raw bytes as a C program writes them: a reader that flips,
mirrors or transposes any of them fails here. Float TIFF and OpenEXR are written by OpenImageIO only (their
containers are not a few lines of bytes).
"""

from __future__ import annotations

import numpy as np
import pytest

from cornell_harness.store.image_files import read_image_file

HEIGHT, WIDTH = 5, 7  # odd and unequal: a flip, a mirror or a transpose all move the corner


def _known() -> np.ndarray:
    """Row 0 is the top. Red grows down the rows, green across the columns; the top-left pixel is marked (blue)."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float32)
    image = np.stack([1.0 + rows, 1.0 + 0.5 * cols, np.full_like(rows, 0.25)], axis=-1)
    image[0, 0, 2] = 8.0
    return image


def _oiio_write(path, image: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    assert out is not None and out.open(str(path), oiio.ImageSpec(WIDTH, HEIGHT, 3, oiio.FLOAT)), oiio.geterror()
    assert out.write_image(np.ascontiguousarray(image, np.float32)), oiio.geterror()
    out.close()


def _raw_pfm(path, image: np.ndarray, little_endian: bool = True) -> None:
    """As a C program writes PFM: ``PF``, the size, the scale (negative: little-endian), then float rows bottom
    to top."""
    scale = b"-1.0" if little_endian else b"1.0"
    rows = np.ascontiguousarray(image[::-1], dtype="<f4" if little_endian else ">f4")
    path.write_bytes(b"PF\n%d %d\n%s\n" % (WIDTH, HEIGHT, scale) + rows.tobytes())


def _raw_hdr(path, image: np.ndarray) -> None:
    """As a C program writes Radiance HDR: the header, ``-Y H +X W`` (top row first), then flat RGBE pixels (a
    width under 8 is always stored flat, not run-length encoded)."""
    peak = image.max(axis=-1)
    mantissa, exponent = np.frexp(peak)
    factor = mantissa * 256.0 / peak
    rgbe = np.concatenate([np.floor(image * factor[..., None]), (exponent + 128)[..., None]], axis=-1)
    header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (HEIGHT, WIDTH)
    path.write_bytes(header + rgbe.astype(np.uint8).tobytes())


WRITERS = {
    "exr (OpenImageIO)": ("x.exr", _oiio_write),
    "float tiff (OpenImageIO)": ("x.tif", _oiio_write),
    "pfm (OpenImageIO)": ("x.pfm", _oiio_write),
    "pfm (raw bytes, little-endian)": ("x.pfm", _raw_pfm),
    "pfm (raw bytes, big-endian)": ("x.pfm", lambda p, im: _raw_pfm(p, im, little_endian=False)),
    "hdr (OpenImageIO)": ("x.hdr", _oiio_write),
    "hdr (raw bytes)": ("x.hdr", _raw_hdr),
}


@pytest.mark.parametrize("how", list(WRITERS))
def test_each_format_reads_back_the_right_way_up(how, tmp_path):
    name, write = WRITERS[how]
    known = _known()
    write(tmp_path / name, known)
    image = read_image_file(tmp_path / name)
    assert image.scene_linear and image.pixels.shape == (HEIGHT, WIDTH, 3)
    pixels = image.pixels
    assert np.unravel_index(np.argmax(pixels[..., 2]), pixels.shape[:2]) == (0, 0), "the marked corner moved"
    assert np.all(np.diff(pixels[..., 0], axis=0) > 0), "red must grow down the rows (row 0 the top)"
    assert np.all(np.diff(pixels[..., 1], axis=1) > 0), "green must grow across the columns (column 0 the left)"
    # RGBE keeps 8 bits of mantissa per channel: within 1% of the peak channel; the float formats exactly
    tolerance = 0.01 * known.max(axis=-1, keepdims=True) if name.endswith(".hdr") else 0.0
    assert np.all(np.abs(pixels - known) <= tolerance), how


def test_a_pfm_reads_exactly_as_the_same_pixels_in_exr(tmp_path):
    """The PFM a C renderer writes and the EXR of the same pixels give the same array, so the same scores."""
    known = _known()
    _raw_pfm(tmp_path / "x.pfm", known)
    _oiio_write(tmp_path / "x.exr", known)
    assert np.array_equal(read_image_file(tmp_path / "x.pfm").pixels, read_image_file(tmp_path / "x.exr").pixels)
