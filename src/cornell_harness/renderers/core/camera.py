"""The pinhole camera of our renderers: pixel convention, camera rays, projection.

Pixel convention (the same as Mitsuba 3's perspective sensor, which the
references come from): pixels are numbered row-major from the top-left
corner; pixel (row, col) covers image-plane coordinates
``[col, col + 1) × [row, row + 1)``, and a box filter picks a uniform point
of it by *adding* the jitter (u, v) ∈ [0, 1)² to the pixel's corner (as
pbrt-v4's ``GetCameraSample`` does with a box filter: corner + offset).
The image plane at distance 1 spans ``[-tan_x, tan_x]`` left to right and
``[tan_y, -tan_y]`` top to bottom (:meth:`cornell_harness.scenes.model.Camera.tan_half_fov`).

Path j of a pass looks through pixel ``j mod P`` (P pixels): a pass of n
samples per pixel is n·P consecutive paths, so every pixel gets its
samples in path order (:mod:`cornell_harness.renderers.core.film` relies on it).
"""

from __future__ import annotations

from typing import NamedTuple

import math

import numpy as np

from cornell_harness.scenes.model import Camera
from cornell_harness.renderers.core.rays import set_path, set_ray
from cornell_harness.renderers.core.sampler import camera_sample, path_point
from cornell_harness.renderers.core.sampling import jit


class ImagePlane(NamedTuple):
    """What :func:`camera_rays` needs of a camera, as one argument for the kernels that call it."""

    basis: np.ndarray  # camera_basis
    width: int
    height: int


def image_plane(camera: Camera) -> ImagePlane:
    return ImagePlane(camera_basis(camera), camera.width, camera.height)


def camera_basis(camera: Camera) -> np.ndarray:
    """(4, 3) float64: position, and right, up, forward scaled to the image plane at distance 1.

    Pixel (row, col) spans directions forward + sx·right + sy·up with
    sx in [-tan_x, tan_x] left to right and sy in [tan_y, -tan_y] top to bottom.
    """
    right, up, forward = camera.frame()
    tx, ty = camera.tan_half_fov()
    return np.stack([np.asarray(camera.position, dtype=np.float64), right * tx, up * ty, forward])


@jit
def camera_ray(basis, width: int, height: int, pixel: int, u1: float, u2: float):
    """Unit direction through point (u1, u2) ∈ [0, 1)² of ``pixel``, measured from its top-left corner."""
    row, col = pixel // width, pixel % width
    sx = 2.0 * (col + u1) / width - 1.0
    sy = 1.0 - 2.0 * (row + u2) / height
    d0 = basis[3, 0] + sx * basis[1, 0] + sy * basis[2, 0]
    d1 = basis[3, 1] + sx * basis[1, 1] + sy * basis[2, 1]
    d2 = basis[3, 2] + sx * basis[1, 2] + sy * basis[2, 2]
    inv = 1.0 / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return d0 * inv, d1 * inv, d2 * inv


@jit
def camera_rays(basis, width, height, first, pixels, stream, rays):
    """Camera rays for paths first .. first + len(rays) - 1 of a pass into ``rays`` (a RayBuffer).

    Path j looks through pixel j mod ``pixels``, jittered by its camera
    dimensions of ``stream`` (:func:`cornell_harness.renderers.core.sampler.camera_sample`); ray i starts
    path i of the unit with throughput 1 and pdf 0 (no sampling decision).
    """
    origin = (basis[0, 0], basis[0, 1], basis[0, 2])
    for i in range(rays.path.size):
        j = first + i
        u, v = camera_sample(stream, path_point(stream, j))
        set_ray(rays, i, origin, camera_ray(basis, width, height, j % pixels, u, v))
        set_path(rays, i, i, (1.0, 1.0, 1.0), 0.0)


def pixel_cone_widths(camera: Camera) -> np.ndarray:
    """(pixels,) √Ω of each pixel of a pinhole ``camera``, row-major: the width of its cone at distance 1
    (SPPM's initial radius, :mod:`cornell_harness.renderers.sppm`).

    Ω = (2 tan_x/W)(2 tan_y/H)·cos³θ at the pixel's centre, θ its angle off
    the optical axis (a pixel of the image plane at distance 1, seen from
    the pinhole: area over squared distance, times the cosine of its tilt).
    """
    tx, ty = camera.tan_half_fov()
    w, h = camera.width, camera.height
    sx = 2.0 * (np.arange(w) + 0.5) / w - 1.0
    sy = 1.0 - 2.0 * (np.arange(h) + 0.5) / h
    cos = 1.0 / np.sqrt(1.0 + (sx[None, :] * tx) ** 2 + (sy[:, None] * ty) ** 2)
    return np.sqrt((2.0 * tx / w) * (2.0 * ty / h) * cos ** 3).ravel()


def project_to_pixels(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where world ``points`` (n, 3) land on the image: (film (n, 2) float64, pixel (n,) int64).

    ``film`` is (x, y) in pixel units with the convention above (x = col + u,
    y = row + v), the inverse of :func:`camera_ray`; ``pixel`` is the
    row-major index, -1 for points behind the camera or outside the frame.
    For splatting light-path vertices (light tracing, photon visualisation).
    """
    right, up, forward = camera.frame()
    tx, ty = camera.tan_half_fov()
    v = np.asarray(points, dtype=np.float64).reshape(-1, 3) - np.asarray(camera.position, dtype=np.float64)
    z = v @ forward
    with np.errstate(divide="ignore", invalid="ignore"):
        sx = (v @ right) / (z * tx)
        sy = (v @ up) / (z * ty)
    film = np.stack([(sx + 1.0) * 0.5 * camera.width, (1.0 - sy) * 0.5 * camera.height], axis=1)
    inside = (z > 0) & np.all(np.isfinite(film), axis=1)
    inside &= (film[:, 0] >= 0) & (film[:, 0] < camera.width) & (film[:, 1] >= 0) & (film[:, 1] < camera.height)
    col = np.floor(np.where(inside, film[:, 0], 0)).astype(np.int64)
    row = np.floor(np.where(inside, film[:, 1], 0)).astype(np.int64)
    return film, np.where(inside, row * camera.width + col, -1)
