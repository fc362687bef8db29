"""The pieces of benches/downstream.py (benches/reconstruction/): E2VID's voxel grid against its
per-event formula, the EVREAL affine fit against numpy's polyfit, SSIM against a per-pixel
window loop (and scikit-image where installed), and the network and its training loop (with
PyTorch only)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benches"))

from reconstruction.image_quality import affine_fit, masked_mse, scores, ssim  # noqa: E402
from reconstruction.voxel_grid import normalised, voxel_grid  # noqa: E402


@pytest.fixture
def one_thread() -> Iterator[None]:
    """Torch on one thread: on a loaded machine more threads spin and run many times slower."""
    torch = pytest.importorskip("torch")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def random_events(rng: np.random.Generator, n: int, width: int, height: int) -> tuple:
    t = np.sort(rng.integers(1_000, 41_000, n))
    return t, rng.integers(0, width, n), rng.integers(0, height, n), rng.integers(0, 2, n)


def test_voxel_grid_matches_the_per_event_formula() -> None:
    rng = np.random.default_rng(1)
    width, height, bins = 7, 5, 5
    t, x, y, p = random_events(rng, 300, width, height)
    grid = voxel_grid(t, x, y, p, (1_000, 41_000), width, height, bins)
    expected = np.zeros((bins, height, width))
    for tk, xk, yk, pk in zip(t, x, y, p):
        t_star = (bins - 1) * (tk - 1_000) / 40_000
        for b in range(bins):
            expected[b, yk, xk] += (1 if pk else -1) * max(0.0, 1.0 - abs(b - t_star))
    np.testing.assert_allclose(grid, expected, atol=1e-5)
    # Each event's weights sum to one: the grid sums to the polarity total.
    assert grid.sum() == pytest.approx(2 * p.sum() - len(p), abs=1e-3)


def test_voxel_grid_puts_an_event_on_a_bin_time_in_that_bin_and_halves_midway() -> None:
    on_bin = voxel_grid(
        np.array([10_000]), np.array([1]), np.array([0]), np.array([1]), (0, 40_000), 2, 1
    )
    assert on_bin[:, 0, 1].tolist() == [0, 1, 0, 0, 0]
    midway = voxel_grid(
        np.array([35_000]), np.array([0]), np.array([0]), np.array([0]), (0, 40_000), 2, 1
    )
    assert midway[:, 0, 0].tolist() == [0, 0, 0, -0.5, -0.5]


def test_normalised_gives_the_non_zero_cells_mean_0_and_std_1() -> None:
    grid = np.zeros((5, 4, 4), np.float32)
    grid[0, 0, :3] = [1.0, 2.0, 4.0]
    out = normalised(grid)
    values = np.array([1.0, 2.0, 4.0])
    np.testing.assert_allclose(out[0, 0, :3], (values - values.mean()) / values.std(), rtol=1e-6)
    assert np.count_nonzero(out) == 3


def test_affine_fit_recovers_a_known_map_and_agrees_with_polyfit() -> None:
    rng = np.random.default_rng(2)
    prediction = rng.uniform(0, 1, (20, 30))
    assert affine_fit(prediction, 0.7 * prediction + 0.1) == pytest.approx((0.7, 0.1))
    reference = 0.4 * prediction + 0.2 + rng.normal(0, 0.05, prediction.shape)
    a, b = np.polyfit(prediction.ravel(), reference.ravel(), 1)
    assert affine_fit(prediction, reference) == pytest.approx((a, b))


def brute_force_ssim(x: np.ndarray, y: np.ndarray) -> float:
    """Wang et al. 2004 eq. 13 at every pixel whose 11 x 11 window fits, sigma 1.5, L = 1."""
    offsets = np.arange(-5, 6)
    weight = np.exp(-(offsets[:, None] ** 2 + offsets[None, :] ** 2) / (2 * 1.5**2))
    weight /= weight.sum()
    c1, c2 = 0.01**2, 0.03**2
    values = []
    for i in range(5, x.shape[0] - 5):
        for j in range(5, x.shape[1] - 5):
            wx, wy = x[i - 5 : i + 6, j - 5 : j + 6], y[i - 5 : i + 6, j - 5 : j + 6]
            mx, my = (weight * wx).sum(), (weight * wy).sum()
            vx, vy = (weight * (wx - mx) ** 2).sum(), (weight * (wy - my) ** 2).sum()
            cov = (weight * (wx - mx) * (wy - my)).sum()
            values.append(
                (2 * mx * my + c1) * (2 * cov + c2) / ((mx**2 + my**2 + c1) * (vx + vy + c2))
            )
    return float(np.mean(values))


def test_ssim_matches_the_per_pixel_window_formula() -> None:
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, (24, 29))
    y = np.clip(x + rng.normal(0, 0.2, x.shape), 0, 1)
    assert ssim(x, x) == pytest.approx(1.0)
    assert ssim(x, y) == pytest.approx(brute_force_ssim(x, y), rel=1e-9)


def test_ssim_matches_scikit_image() -> None:
    metrics = pytest.importorskip("skimage.metrics")
    rng = np.random.default_rng(4)
    x = rng.uniform(0, 1, (40, 50))
    y = np.clip(0.8 * x + rng.normal(0, 0.1, x.shape), 0, 1)
    expected = metrics.structural_similarity(
        x, y, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0
    )
    assert ssim(x, y) == pytest.approx(expected, rel=1e-9)


def test_scores_ignore_an_affine_change_of_the_prediction() -> None:
    reference = np.random.default_rng(5).uniform(0, 1, (30, 30))
    mse, similarity = scores(3.0 * reference - 0.5, reference)
    assert mse == pytest.approx(0.0, abs=1e-20)
    assert similarity == pytest.approx(1.0)
    # A flat prediction is fitted by the frame's mean: its MSE is the frame's variance.
    assert scores(np.zeros((30, 30)), reference)[0] == pytest.approx(reference.var())


def test_masked_mse_fits_and_scores_the_masked_pixels_alone() -> None:
    rng = np.random.default_rng(8)
    reference = rng.uniform(0, 1, (20, 20))
    prediction = rng.uniform(0, 1, (20, 20))  # unrelated outside the mask
    mask = np.zeros((20, 20), bool)
    mask[5:12, 3:9] = True
    prediction[mask] = (reference[mask] - 0.3) / 2.0
    assert masked_mse(prediction, reference, mask) == pytest.approx(0.0, abs=1e-20)
    flat = masked_mse(np.zeros((20, 20)), reference, mask)
    assert flat == pytest.approx(reference[mask].var())


def test_network_shapes_and_torch_ssim_equal_the_numpy_one(one_thread: None) -> None:
    torch = pytest.importorskip("torch")
    from reconstruction.network import RecurrentUNet, padded_size, ssim_loss

    assert padded_size(260, 346) == (260, 348)
    torch.manual_seed(0)
    model = RecurrentUNet(bins=5, channels=4)
    with torch.no_grad():
        image, state = model(torch.randn(2, 5, 16, 20), None)
        image, _ = model(torch.randn(2, 5, 16, 20), state)  # the state carries on
    assert image.shape == (2, 1, 16, 20) and state.shape == (2, 16, 4, 5)
    assert float(image.min()) >= 0.0 and float(image.max()) <= 1.0
    rng = np.random.default_rng(6)
    x, y = rng.uniform(0, 1, (20, 24)), rng.uniform(0, 1, (20, 24))
    loss = ssim_loss(torch.from_numpy(x)[None, None], torch.from_numpy(y)[None, None])
    assert 1.0 - float(loss) == pytest.approx(brute_force_ssim(x, y), rel=1e-9)


def test_two_training_steps_lower_the_loss_of_a_fixed_batch(one_thread: None) -> None:
    torch = pytest.importorskip("torch")
    import downstream

    rng = np.random.default_rng(7)
    voxels = rng.normal(0, 1, (4, 3, 5, 16, 16)).astype(np.float32)
    # Bright targets, whatever the turn or mirror: the output (about 0.5 at first) must rise.
    targets = rng.uniform(0.85, 0.95, (4, 3, 16, 16)).astype(np.float32)
    before = downstream.train(voxels, targets, seed=0, steps=0, batch=4)
    after = downstream.train(voxels, targets, seed=0, steps=2, batch=4)

    def l1(model: torch.nn.Module) -> float:
        state, total = None, 0.0
        with torch.no_grad():
            for w in range(3):
                image, state = model(torch.from_numpy(voxels[:, w]), state)
                total += float((image[:, 0] - torch.from_numpy(targets[:, w])).abs().mean())
        return total

    changed = [not torch.equal(p, q) for p, q in zip(before.parameters(), after.parameters())]
    assert all(changed)
    assert l1(after) < l1(before)


def test_the_three_sensors_share_the_drawn_thresholds_and_c_has_no_noise() -> None:
    pytest.importorskip("torch")
    import downstream

    values = downstream.drawn_values(seed=0, sequence=3)
    a, b, c = (downstream.sensor(name, values, 32, seed=1) for name in downstream.CONFIGS)
    assert a.theta_on == b.theta_on == c.theta_on == values["theta_on"]
    assert b.reference_reset == "event" and b.shot_rate_hz == 0 and b.cutoff_hz == 0
    assert a.shot_rate_hz > 0 and a.leak_rate_hz > 0 and a.cutoff_hz == values["cutoff_hz"]
    assert c.shot_rate_hz == c.leak_rate_hz == c.theta_noise == c.jitter_us == 0
    assert c.cutoff_hz == a.cutoff_hz and c.refractory_us == a.refractory_us
