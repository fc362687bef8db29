"""EVREAL's scoring of a reconstruction against a reference frame (Ercan et al., "EVREAL:
Towards a Comprehensive Benchmark and Analysis Suite for Event-based Video Reconstruction",
CVPRW 2023): the reconstruction first mapped by its best affine fit a * pred + b to the
reference (least squares), then MSE and SSIM on intensities in [0, 1].

SSIM (Wang, Bovik, Sheikh, Simoncelli, IEEE TIP 2004, eq. 13) with an 11 x 11 Gaussian window,
sigma 1.5, K1 = 0.01, K2 = 0.03, data range 1, population (co)variances, averaged over the
pixels whose window lies inside the image (scikit-image's `structural_similarity` with
gaussian_weights=True, use_sample_covariance=False, data_range=1)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import correlate1d

SSIM_SIGMA_PX = 1.5
SSIM_WINDOW_PX = 11
SSIM_K1, SSIM_K2 = 0.01, 0.03


def affine_fit(prediction: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(a, b) minimising sum (a * prediction + b - reference)^2; a = 0 for a flat prediction."""
    pred = np.asarray(prediction, np.float64).ravel()
    ref = np.asarray(reference, np.float64).ravel()
    centred = pred - pred.mean()
    variance = float(centred @ centred)
    a = float(centred @ (ref - ref.mean())) / variance if variance > 0 else 0.0
    return a, float(ref.mean() - a * pred.mean())


def gaussian_window(size_px: int = SSIM_WINDOW_PX, sigma_px: float = SSIM_SIGMA_PX) -> np.ndarray:
    """The normalised 2-D Gaussian window (size_px x size_px)."""
    offsets = np.arange(size_px) - (size_px - 1) / 2.0
    line = np.exp(-(offsets**2) / (2.0 * sigma_px**2))
    window = np.outer(line, line)
    return window / window.sum()


def ssim(image: np.ndarray, reference: np.ndarray, data_range: float = 1.0) -> float:
    """Mean SSIM of two images of the same shape, over the windows inside the image."""
    if image.shape != reference.shape or image.ndim != 2:
        raise ValueError(
            f"ssim: two 2-D images of one shape, got {image.shape} and {reference.shape}"
        )
    if min(image.shape) < SSIM_WINDOW_PX:
        raise ValueError(f"ssim: images need at least {SSIM_WINDOW_PX} px a side")
    x = np.asarray(image, np.float64)
    y = np.asarray(reference, np.float64)
    # The window is the outer product of a normalised 1-D Gaussian: two 1-D passes.
    line = gaussian_window()[SSIM_WINDOW_PX // 2]
    line = line / line.sum()

    def local_mean(values: np.ndarray) -> np.ndarray:
        rows = correlate1d(values, line, axis=0, mode="reflect")
        return correlate1d(rows, line, axis=1, mode="reflect")

    mu_x, mu_y = local_mean(x), local_mean(y)
    var_x = local_mean(x * x) - mu_x**2
    var_y = local_mean(y * y) - mu_y**2
    cov = local_mean(x * y) - mu_x * mu_y
    c1, c2 = (SSIM_K1 * data_range) ** 2, (SSIM_K2 * data_range) ** 2
    index = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / (
        (mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2)
    )
    pad = (SSIM_WINDOW_PX - 1) // 2
    return float(index[pad:-pad, pad:-pad].mean())


def masked_mse(prediction: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    """MSE over the pixels of `mask` after the affine fit over those pixels alone (a side
    score of the benchmark, not EVREAL's: where the events are)."""
    a, b = affine_fit(prediction[mask], reference[mask])
    return float(np.mean((a * prediction[mask] + b - reference[mask]) ** 2))


def scores(prediction: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(MSE, SSIM) of the prediction after its best affine fit to the reference."""
    a, b = affine_fit(prediction, reference)
    fitted = a * np.asarray(prediction, np.float64) + b
    reference = np.asarray(reference, np.float64)
    return float(np.mean((fitted - reference) ** 2)), ssim(fitted, reference)
