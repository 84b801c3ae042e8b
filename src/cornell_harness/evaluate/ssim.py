"""Mean SSIM (Wang, Bovik, Sheikh and Simoncelli, "Image quality assessment: from error visibility to
structural similarity", IEEE TIP 13(4), 2004, eqs. (6)-(13)) as ``skimage.metrics.structural_similarity``
computes it with its defaults: a 7×7 uniform window, sample covariance, K1 = 0.01, K2 = 0.03, the mean over
the pixels whose window lies inside the image (skimage crops the 3-pixel border, so its filter's boundary
mode never counts), each channel's mean SSIM averaged.

In plain numpy: skimage's module imports ``scipy.ndimage`` (~0.4 s), a third of what ``cbox compare-image``
may cost. tests/evaluate/test_ssim.py compares the two to rounding.
"""

from __future__ import annotations

import numpy as np

WINDOW = 7
K1, K2 = 0.01, 0.03


def _window_means(a: np.ndarray, size: int = WINDOW) -> np.ndarray:
    """The mean of every size×size window lying wholly inside the (H, W) array: (H - size + 1, W - size + 1)."""
    h, w = a.shape
    rows = sum(a[i:h - size + 1 + i] for i in range(size)) / size
    return sum(rows[:, j:w - size + 1 + j] for j in range(size)) / size


def ssim_channel(x: np.ndarray, y: np.ndarray, data_range: float = 1.0) -> float:
    """Mean SSIM of two (H, W) images."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if min(x.shape) < WINDOW:
        raise ValueError(f"SSIM needs images of at least {WINDOW}x{WINDOW}, got {x.shape[1]}x{x.shape[0]}")
    cov_norm = WINDOW**2 / (WINDOW**2 - 1)  # sample covariance
    ux, uy = _window_means(x), _window_means(y)
    vx = cov_norm * (_window_means(x * x) - ux * ux)
    vy = cov_norm * (_window_means(y * y) - uy * uy)
    vxy = cov_norm * (_window_means(x * y) - ux * uy)
    c1, c2 = (K1 * data_range) ** 2, (K2 * data_range) ** 2
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux**2 + uy**2 + c1) * (vx + vy + c2))
    return float(s.mean(dtype=np.float64))


def ssim(x: np.ndarray, y: np.ndarray, data_range: float = 1.0) -> float:
    """Mean SSIM of two (H, W, C) images: the mean over channels of each channel's mean SSIM."""
    return float(np.mean([ssim_channel(x[..., c], y[..., c], data_range) for c in range(x.shape[-1])]))
