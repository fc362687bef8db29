"""The dataset card (`pecs.dataset.write_card`, `pecs dataset card`): its numbers against numbers
computed here from the Parquet and ground-truth files, its HTML self-contained, written at the
end of every run (`--no-card` skips it, a failure is a warning), and clear errors."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from pecs.cli import main
from pecs.dataset import parse_spec, run_dataset, write_card
from pecs.dataset.card import preview_frames
from pecs.dataset.card_stats import dataset_stats, scene_illuminance_lux
from pecs.dataset.distributions import Distribution
from pecs.render.scene_file import resolve_scene_path
from PIL import Image

# Two checkerboards with depth, flow and instances; a quadrant disk without ground truth; the
# checkerboard without its [light] table; and a sequence whose drawn latency is negative, which
# fails.
SPEC = """
[dataset]
name = "card"
seed = 5
retries = 0

[defaults]
duration_s = 0.01
rate_hz = 1000
spp = 1
preset = "davis346"

[defaults.sensor]
width = 32
height = 24

[draw]
theta_on = { uniform = [0.15, 0.3] }
refractory_us = { log_uniform = [100.0, 1000.0] }
reference_reset = { choice = ["event", "refractory_end"] }

[[sequences]]
scene = "checkerboard"
count = 2
ground_truth = "depth,flow,instances"

[[sequences]]
scene = "quadrant_disk"

[[sequences]]
scene = "nolight.toml"

[[sequences]]
scene = "checkerboard"
name = "broken"
draw = { latency_us = { normal = [-1000.0, 1.0] } }
"""
DONE = ["checkerboard-0", "checkerboard-1", "quadrant_disk", "nolight"]


def write_spec(folder: Path) -> Path:
    """The spec, and beside it the built-in checkerboard without its [light] table."""
    builtin = resolve_scene_path("checkerboard")
    text = builtin.read_text()
    start = text.index("[light]")
    end = text.index("[[objects]]")
    scene = text[:start] + text[end:]
    scene = scene.replace(
        'mitsuba = "checkerboard.xml"', f"mitsuba = {json.dumps(str(builtin.with_suffix('.xml')))}"
    )
    (folder / "nolight.toml").write_text(scene)
    spec = folder / "spec.toml"
    spec.write_text(SPEC)
    return spec


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("card")
    out = folder / "data"
    summary = run_dataset(write_spec(folder), out, workers=1)
    assert summary.failed == ["broken"] and sorted(summary.done) == sorted(DONE)
    assert summary.card == out / "card.html"
    return out


def manifest_records(root: Path) -> dict[str, dict]:
    manifest = json.loads((root / "manifest.json").read_text())
    return {r["name"]: r for r in manifest["sequences"]}


def test_event_rates_on_fractions_and_draws_match_the_files(dataset: Path) -> None:
    stats = dataset_stats(dataset)
    records = manifest_records(dataset)
    by_name = {s.name: s for s in stats.sequences}
    total = 0
    for name in DONE:
        table = pq.read_table(dataset / "events" / f"sequence={name}" / "part-0.parquet")
        p = table.column("p").to_numpy()
        assert p.size > 0
        total += p.size
        simulated_s = records[name]["simulated_s"]
        assert simulated_s == pytest.approx(0.01)
        s = by_name[name]
        assert s.status == "done" and s.events == p.size
        assert s.events_per_s == pytest.approx(p.size / 0.01, rel=1e-12)
        assert s.on_fraction == pytest.approx(np.count_nonzero(p == 1) / p.size, rel=1e-12)
        assert s.drawn == records[name]["task"]["drawn"]
        assert (s.width, s.height) == (32, 24)
    assert by_name["broken"].status == "failed" and "latency_us" in by_name["broken"].error
    assert (stats.count("done"), stats.count("failed"), stats.count("pending")) == (4, 1, 0)
    assert stats.total_events == total
    assert stats.total_duration_s == pytest.approx(0.04)
    assert stats.sensor_sizes == {(32, 24): 4}
    # The spec's own distributions, for marking the histograms; the draws lie in them.
    assert stats.draw_ranges["theta_on"] == [Distribution("uniform", (0.15, 0.3))]
    assert stats.draw_ranges["refractory_us"] == [Distribution("log_uniform", (100.0, 1000.0))]
    assert stats.draw_ranges["latency_us"] == [Distribution("normal", (-1000.0, 1.0))]
    assert all(0.15 <= v <= 0.3 for v in stats.drawn_values("theta_on"))
    assert sorted(stats.drawn_fields) == ["reference_reset", "refractory_us", "theta_on"]


def test_flow_depth_and_instances_come_from_the_stored_ground_truth(dataset: Path) -> None:
    """Flow per 100 ms: |flow_i| * 100 ms / (t_{i+1} - t_i), every stored frame pair; depth:
    finite positive z; instances: shape indices seen in any frame. None without ground truth."""
    stats = {s.name: s for s in dataset_stats(dataset, max_frames=1000, max_values=10**9).done}
    for name in ("checkerboard-0", "checkerboard-1"):
        folder = dataset / "runs" / name / "ground_truth"
        t_us = pq.read_table(folder / "cameras.parquet").column("t_us").to_numpy()
        assert t_us.size == 11  # 10 ms at 1 kHz, both ends
        flows, depths, seen = [], [], set()
        for i in range(t_us.size):
            depth = np.load(folder / "frames" / f"depth_{i:06d}.npy")
            depths.append(depth[np.isfinite(depth) & (depth > 0)])
            seen |= set(np.unique(np.load(folder / "frames" / f"instance_{i:06d}.npy")).tolist())
            if i + 1 < t_us.size:
                flow = np.load(folder / "frames" / f"flow_{i:06d}.npy").astype(np.float64)
                speed = np.sqrt(flow[..., 0] ** 2 + flow[..., 1] ** 2)
                flows.append(speed[np.isfinite(speed)] * 100_000 / (t_us[i + 1] - t_us[i]))
        expected_flow = np.sort(np.concatenate(flows))
        assert expected_flow.size > 0 and expected_flow.max() > 0
        np.testing.assert_allclose(np.sort(stats[name].flow_px_per_100ms), expected_flow, rtol=1e-6)
        np.testing.assert_array_equal(np.sort(stats[name].depth_m), np.sort(np.concatenate(depths)))
        assert stats[name].instances == len(seen - {-1}) == 1  # the board
    for name in ("quadrant_disk", "nolight"):
        assert stats[name].flow_px_per_100ms is None and stats[name].depth_m is None
        assert stats[name].instances is None


def test_thinning_keeps_at_most_max_values_spread_over_the_frames(dataset: Path) -> None:
    full = {s.name: s for s in dataset_stats(dataset, max_values=10**9).done}
    thin = {s.name: s for s in dataset_stats(dataset, max_values=1000).done}
    values = full["checkerboard-0"].depth_m
    step = -(-values.size // 1000)
    np.testing.assert_array_equal(thin["checkerboard-0"].depth_m, values[::step])
    assert thin["checkerboard-0"].depth_m.size <= 1000


def test_illuminance_is_the_scene_light_table(dataset: Path, tmp_path: Path) -> None:
    stats = {s.name: s for s in dataset_stats(dataset).done}
    # The built-in scenes' [light] illuminance_lux: 300 (checkerboard), 500 (quadrant disk).
    assert [stats[n].illuminance_lux for n in DONE] == [300.0, 300.0, 500.0, None]
    # A generated scene is kept in the run folder (runs/NAME/scene/scene.toml): it wins.
    (tmp_path / "scene").mkdir()
    (tmp_path / "scene" / "scene.toml").write_text("[light]\nilluminance_lux = 1234.5\n")
    assert scene_illuminance_lux(tmp_path, {"scene_path": "generator:objects"}) == 1234.5
    assert scene_illuminance_lux(tmp_path / "none", {"scene_path": "generator:objects"}) is None


def test_html_card_is_self_contained_and_small(dataset: Path) -> None:
    html = (dataset / "card.html").read_text()
    assert len(html.encode()) < 1_000_000
    sources = re.findall(r"""src\s*=\s*["']([^"']*)["']""", html)
    # Six distributions and three drawn fields (of the finished sequences: latency_us is drawn
    # by the failed one only), none skipped here, and four preview frames.
    assert len(sources) == 6 + 3 + 4
    for source in sources:
        assert source.startswith("data:image/png;base64,")
        assert base64.b64decode(source.split(",", 1)[1]).startswith(b"\x89PNG\r\n\x1a\n")
    assert not re.search(r"""(href|url)\s*[=(]""", html)  # nothing else to fetch
    for text in (
        "Events per second",
        "ON fraction",
        "Flow magnitude per 100 ms",
        "Depth",
        "Illuminance",
        "Instances per sequence",
        "Drawn: theta_on",
        "Drawn: refractory_us",
        "Drawn: reference_reset",
    ):
        assert text in html
    assert "5: 4 done, 1 failed, 0 pending" in html
    assert "broken" in html and "latency_us" in html  # the failed sequence and its error
    assert "1 sequences have no [light] table" in html


def test_markdown_card_links_its_pngs(dataset: Path, tmp_path: Path) -> None:
    card = tmp_path / "card.md"
    assert main(["dataset", "card", str(dataset), "-o", str(card)]) == 0
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", card.read_text())
    assert len(links) == 6 + 3 + 4
    for link in links:
        assert (tmp_path / link).read_bytes().startswith(b"\x89PNG")


def test_previews_show_each_pixels_latest_polarity_in_a_window_around_the_middle(
    dataset: Path,
) -> None:
    stats = dataset_stats(dataset)
    previews = preview_frames(stats)
    # Four of the four finished sequences, in dataset order.
    assert [p.sequence for p in previews] == DONE
    for preview in previews:
        # Within 1 to 20 ms and the 10 ms sequence, centred on its middle (5 ms).
        assert 1_000 <= preview.end_us - preview.start_us <= 10_000
        assert abs((preview.start_us + preview.end_us) / 2 - 5_000) <= 1
        table = pq.read_table(
            dataset / "events" / f"sequence={preview.sequence}" / "part-0.parquet"
        )
        t, x, y, p = (table.column(c).to_numpy() for c in "txyp")
        inside = (t >= preview.start_us) & (t < preview.end_us)
        assert inside.any()
        expected = np.full((24, 32, 3), 255, np.uint8)  # white: no event
        for u, v, q in zip(x[inside], y[inside], p[inside]):  # in time order: the latest wins
            expected[v, u] = (33, 102, 172) if q == 1 else (214, 39, 40)
        shown = np.asarray(Image.open(io.BytesIO(preview.png)).convert("RGB"))
        np.testing.assert_array_equal(shown, expected)


def test_a_dataset_without_ground_truth_notes_what_is_skipped(tmp_path: Path) -> None:
    spec = parse_spec(SPEC.split("[[sequences]]")[0] + '[[sequences]]\nscene = "quadrant_disk"\n')
    run_dataset(spec, tmp_path / "data", workers=1)
    html = (tmp_path / "data" / "card.html").read_text()
    assert "Skipped: no sequence stored flow ground truth" in html
    assert "Skipped: no sequence stored depth ground truth" in html
    assert "Skipped: no sequence stored instance ground truth" in html


def test_run_writes_the_card_and_no_card_skips_it(dataset: Path, tmp_path: Path) -> None:
    copy = tmp_path / "data"
    shutil.copytree(dataset, copy)
    (copy / "card.html").unlink()
    spec = str(dataset.parent / "spec.toml")
    run = ["dataset", "run", spec, "-o", str(copy), "--workers", "1", "--quiet"]
    assert main([*run, "--no-card"]) == 1  # "broken" fails again
    assert not (copy / "card.html").exists()
    assert main(run) == 1
    assert "Dataset card: card" in (copy / "card.html").read_text()


@pytest.mark.filterwarnings("default")  # the suite turns warnings into errors; a user's does not
def test_a_card_that_fails_is_a_one_line_warning(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    import pecs.dataset.card

    def broken(*args: object) -> None:
        raise RuntimeError("no room\nleft")

    monkeypatch.setattr(pecs.dataset.card, "write_card", broken)
    copy = tmp_path / "data"
    shutil.copytree(dataset, copy)
    spec = dataset.parent / "spec.toml"
    with pytest.warns(UserWarning, match=r"dataset card not written \(no room left\)"):
        summary = run_dataset(spec, copy, workers=1)
    assert summary.card is None and summary.failed == ["broken"]
    capsys.readouterr()
    assert main(["dataset", "run", str(spec), "-o", str(copy), "--workers", "1", "--quiet"]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert f"pecs dataset: warning: {copy}: dataset card not written (no room left)" in lines
    assert not any("Traceback" in line or "Warning:" in line for line in lines)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda root: root / "missing", "no such dataset folder"),
        (lambda root: root, "no manifest.json; is this a pecs dataset folder?"),
    ],
)
def test_a_missing_or_empty_folder_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture, make: object, message: str
) -> None:
    folder = make(tmp_path)
    assert main(["dataset", "card", str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pecs dataset: error: ") and message in err
    with pytest.raises(FileNotFoundError, match=message):
        write_card(folder)


def test_an_unknown_card_format_names_the_option(
    dataset: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["dataset", "card", str(dataset), "-o", "card.pdf"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ".html" in err and ".md" in err and "-o" in err
