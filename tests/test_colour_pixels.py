"""Colour event pixels: a colour filter array (CFA) over the DVS pixels (pecs.render.cfa).

Expected numbers come from the shipped CSV curves, read and integrated here with numpy: a pixel
under filter c sees integral L(lambda) T_c(lambda) QE(lambda) lambda d lambda (the constant h c
cancels in ratios). The sensor runs in its linear (lin-log) range, where the number of events a
light change gives is proportional to the photocurrent change; in the log range it would be the
log of a ratio, the same in every channel.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pecs
import pyarrow as pa
import pytest
from pecs.config import NOISE_OFF
from pecs.render import Simulation
from pecs.render.cfa import load_cfa

DATA = Path(__file__).resolve().parents[1] / "python" / "pecs" / "scenes"
GRID_NM = np.arange(360.0, 1100.01, 0.25)
CHANNEL_FILES = {"R": "red", "G": "green", "B": "blue", "W": "white"}
W, HGT = 48, 16
FLICKER_HZ = 100.0
#: Each patch spans 16 columns; these are the columns well inside it (even count: both parities).
PATCH_COLUMNS = {450: range(3, 13), 500: range(19, 29), 600: range(35, 45)}
ROWS = range(2, 14)
FLASHES = 4
SWINGS = 2 * FLASHES  # dark to full and back, each
IDEAL_CIRCUIT = {
    "theta_on": 0.01,
    "theta_off": 0.01,
    "theta_sigma": 0.0,
    "refractory_us": 0.0,
    "cutoff_hz": 0.0,
    "latency_us": 0.0,
    "jitter_us": 0.0,
}


def table(name: str) -> tuple[np.ndarray, np.ndarray]:
    rows = np.genfromtxt(DATA / name, delimiter=",", comments="#", skip_header=1)
    rows = rows[np.isfinite(rows[:, 0])]
    return rows[:, 0], rows[:, 1]


QE = np.interp(GRID_NM, *table("qe/generic_silicon_fsi.csv"), left=0, right=0)


def transmission(channel: str) -> np.ndarray:
    curve = table(f"cfa/generic_{CHANNEL_FILES[channel]}.csv")
    return np.interp(GRID_NM, *curve, left=0, right=0)


def response(channel: str, radiance: np.ndarray) -> float:
    """Photo-electrons (up to h c) of a pixel under `channel` seeing spectral radiance."""
    y = radiance * transmission(channel) * QE * GRID_NM
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(GRID_NM)))


def band(centre_nm: float) -> np.ndarray:
    """The patches' narrow band: flat over centre +-5 nm, 5 nm ramps either side."""
    nodes = [centre_nm - 10, centre_nm - 5, centre_nm + 5, centre_nm + 10]
    return np.interp(GRID_NM, nodes, [0, 1, 1, 0], left=0, right=0)


def band_string(centre_nm: float) -> str:
    return f"{centre_nm - 10}:0, {centre_nm - 5}:1, {centre_nm + 5}:1, {centre_nm + 10}:0"


def patches_scene(folder: Path, spectra: dict[int, str], pattern: str, spp: int) -> Path:
    """Three emitting patches side by side (16 x 16 pixels each, dark gaps between), each on a
    lamp flickering fully (depth 1) at 100 Hz: dark at t = 0, 10 ms..., full at 5 ms, 15 ms..."""
    shapes = "".join(
        f'<shape type="rectangle" id="p{key}"><transform name="to_world">'
        f'<scale x="0.0055" y="0.0055"/><translate x="{0.0118 * (k - 1):.4f}"/></transform>'
        f'<emitter type="area" id="e{key}"><spectrum name="radiance" value="{value}"/></emitter>'
        "</shape>"
        for k, (key, value) in enumerate(spectra.items())
    )
    (folder / "scene.xml").write_text(
        '<scene version="3.0.0"><sensor type="perspective"><transform name="to_world">'
        '<lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>'
        f"{shapes}</scene>"
    )
    lights = "".join(
        f'[[lights]]\nid = "p{key}"\nscale = 0.05\n'
        f'flicker = {{ frequency_hz = {FLICKER_HZ}, depth = 0.99, waveform = "sine" }}\n'
        for key in spectra
    )
    (folder / "scene.toml").write_text(
        '[scene]\nmitsuba = "scene.xml"\n[time]\nduration_s = 0.01\nrate_hz = 2000\n'
        f'[sensor]\npreset = "color_davis346"\noverrides = {{ width = {W}, height = {HGT}, '
        f'cfa = "{pattern}" }}\n'
        '[optics]\nmodel = "pinhole"\nefl_mm = 50.0\nf_number = 2.0\n'
        f"[render]\nspp = {spp}\nmax_depth = 1\n" + lights
    )
    return folder / "scene.toml"


def events_of_flashes(path: Path, flashes: int) -> tuple[pa.Table, np.ndarray]:
    """Events of the rendered frames at the lamps' troughs and peaks (dark, full, dark, ...),
    with the sensor linear (lin-log knee above the brightest pixel), and the full frame."""
    simulation = Simulation(path)
    renderer = simulation.renderer
    half_period_us = round(1e6 / FLICKER_HZ / 2)
    full = renderer.render(half_period_us * 1e-6)
    # The Color-DAVIS346 without noise, mismatch, bandwidth or delays, thresholds at their
    # least, and linear: every photocurrent below the knee, so events count photocurrent change.
    config = simulation.sensor_config.replace(
        **NOISE_OFF, **IDEAL_CIRCUIT, lin_log_knee=float(full.max()) * 1.25
    )
    sensor = pecs.EventSensor(config)
    batches = []
    for k in range(2 * flashes + 1):
        t_us = k * half_period_us
        batches.append(sensor.feed(renderer.render(t_us * 1e-6), t_us))
    batches.append(sensor.flush())
    return pa.Table.from_batches(batches, schema=sensor.schema), full


def counts_per_channel(events: pa.Table, pattern: str, *patches: range) -> dict[str, float]:
    """Events per pixel of each channel over the inner pixels of the patches (columns)."""
    cfa = load_cfa(pattern)
    x = events["x"].to_numpy().astype(np.int64)
    y = events["y"].to_numpy().astype(np.int64)
    per_pixel = np.zeros((HGT, W))
    np.add.at(per_pixel, (y, x), 1.0)
    inner = np.zeros((HGT, W), bool)
    for columns in patches:
        inner[ROWS.start : ROWS.stop, columns.start : columns.stop] = True
    channel = cfa.channel_index(W, HGT)
    return {
        name: float(per_pixel[inner & (channel == k)].mean()) for k, name in enumerate(cfa.channels)
    }


def change_per_swing(events_per_pixel: float) -> float:
    """A pixel's photocurrent change per swing of the lamp, in thresholds x knee: its events per
    swing plus half an event. Each reversal of the light starts from the residual left under a
    threshold, so a swing of n.f thresholds gives n events: on average half an event is lost."""
    return events_per_pixel / SWINGS + 0.5


def test_three_monochromatic_patches_fire_the_channels_that_transmit_them(
    tmp_path: Path,
) -> None:
    # 450 nm: blue, some green; 500 nm: green and blue; 600 nm: red and green. Red passes
    # nothing at 450 or 500 nm, blue nothing at 600 nm.
    spectra = {centre: band_string(centre) for centre in PATCH_COLUMNS}
    path = patches_scene(tmp_path, spectra, "RGBG", spp=512)
    events, _ = events_of_flashes(path, FLASHES)
    for centre, columns in PATCH_COLUMNS.items():
        measured = counts_per_channel(events, "RGBG", columns)
        expected = {c: response(c, band(centre)) for c in "RGB"}
        strongest = max(expected, key=expected.__getitem__)
        for channel, value in expected.items():
            if value == 0.0:  # the filter blocks this band: not one event
                assert measured[channel] == 0.0, (centre, channel)
                continue
            ratio = change_per_swing(measured[channel]) / change_per_swing(measured[strongest])
            want = value / expected[strongest]
            assert ratio == pytest.approx(want, rel=0.02 if want > 0.2 else 0.05), (
                centre,
                channel,
            )


def test_grey_scene_fires_each_channel_in_proportion_to_its_filter_integral(
    tmp_path: Path,
) -> None:
    flat = "360:1, 1100:1"  # W / (m^2 sr nm) at every wavelength, before the lamps' scale
    path = patches_scene(tmp_path, {450: flat, 500: flat, 600: flat}, "RGBW", spp=64)
    events, _ = events_of_flashes(path, FLASHES)
    expected = {c: response(c, np.ones_like(GRID_NM)) for c in "RGBW"}
    measured = counts_per_channel(events, "RGBW", *PATCH_COLUMNS.values())
    for channel in "RGB":
        ratio = change_per_swing(measured[channel]) / change_per_swing(measured["W"])
        assert ratio == pytest.approx(expected[channel] / expected["W"], rel=0.02), channel


def test_patterns_are_named_as_libcaer_and_split_as_e2vid() -> None:
    # libcaer reads a pattern clockwise from the top-left pixel; E2VID's colour mode takes
    # R = [0::2, 0::2], G = [0::2, 1::2], the second green / white = [1::2, 0::2], B = [1::2, 1::2].
    rgbg = load_cfa("RGBG")
    names = np.array(rgbg.channels)[rgbg.channel_index(6, 4)]
    assert (names[0::2, 0::2] == "R").all() and (names[1::2, 1::2] == "B").all()
    assert (names[0::2, 1::2] == "G").all() and (names[1::2, 0::2] == "G").all()
    rgbw = load_cfa("RGBW")
    names = np.array(rgbw.channels)[rgbw.channel_index(6, 4)]
    assert (names[1::2, 0::2] == "W").all() and (names[0::2, 1::2] == "G").all()
    gbgr = load_cfa("GBGR")  # G B on top, R G below
    assert gbgr.cell().tolist() == [["G", "B"], ["R", "G"]]
    x, y = np.array([0, 1, 1, 0, 5]), np.array([0, 0, 1, 1, 3])
    assert [rgbg.channels[k] for k in rgbg.channel_of(x, y)] == ["R", "G", "B", "G", "B"]


def test_unknown_pattern_is_refused_naming_the_field() -> None:
    with pytest.raises(ValueError, match=r"^cfa: unknown colour filter pattern 'RGGB'; choose"):
        pecs.SensorConfig(cfa="RGGB")


def test_color_davis346_is_the_davis346_under_an_rgbg_filter() -> None:
    colour = pecs.SensorConfig.preset("color_davis346")
    grey = pecs.SensorConfig.preset("davis346")
    assert colour.cfa == "RGBG" and grey.cfa is None
    assert colour.replace(cfa=None, preset_name="davis346") == grey
    # The pattern travels with every event file, in the sensor metadata.
    assert '"cfa": "RGBG"' in pecs.EventSensor(colour).schema.metadata[b"pecs.sensor"].decode()


def test_rgb_frames_fire_only_the_pixels_whose_filter_sees_the_change() -> None:
    config = pecs.SensorConfig.preset("ideal", width=6, height=4, cfa="RGBW")
    sensor = pecs.EventSensor(config)
    before = np.full((4, 6, 3), 0.2, np.float32)
    after = before.copy()
    after[..., 2] = 0.8  # only blue light rises, by ln 4 = 1.39: 6 events at theta 0.2
    sensor.feed(before, 0)
    events = pa.Table.from_batches([sensor.feed(after, 1000), sensor.flush()])
    x, y = events["x"].to_numpy(), events["y"].to_numpy()
    per_pixel = np.zeros((4, 6), int)
    np.add.at(per_pixel, (y, x), 1)
    # Blue pixels (odd x, odd y): 6 events each. White (even x, odd y): luminance 0.2 + 0.0722 *
    # 0.6 rises by ln(0.2433 / 0.2) = 0.196, under one threshold. Red and green: none.
    assert (per_pixel[1::2, 1::2] == 6).all()
    assert per_pixel.sum() == 6 * per_pixel[1::2, 1::2].size


def test_frames2events_takes_each_pixels_channel_of_rgb_images(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    import cv2
    from cli_run import run_cli

    folder = tmp_path / "frames"
    folder.mkdir()
    for k, red in enumerate((60, 120, 240)):
        image = np.zeros((4, 6, 3), np.uint8)
        image[..., 2] = red  # OpenCV writes BGR: channel 2 is red
        image[..., 1] = 100  # steady green
        cv2.imwrite(str(folder / f"{k:03d}.png"), image)
    out = tmp_path / "events.parquet"
    code, _, err = run_cli(
        capsys, "frames2events", str(folder), "-o", str(out), "--fps", "100",
        "--preset", "color_davis346",
        *(f"--set={field}=0" for field in (*NOISE_OFF, "theta_sigma")),
    )  # fmt: skip
    assert code == 0, err
    events = pecs.read_events(out)
    x, y = events["x"].to_numpy(), events["y"].to_numpy()
    assert len(x) > 0
    # Only red pixels (even x, even y) see the red light change.
    assert (x % 2 == 0).all() and (y % 2 == 0).all()


def test_view_draws_each_event_in_its_filters_colour() -> None:
    from pecs.render.cfa import CHANNEL_COLOURS_RGB

    sensor = pecs.EventSensor(pecs.SensorConfig.preset("ideal", width=4, height=2, cfa="RGBG"))
    table = pa.table(
        {
            "t": pa.array([1, 2, 3, 4], pa.int64()),
            "x": pa.array([0, 1, 1, 0], pa.uint16()),
            "y": pa.array([0, 0, 1, 1], pa.uint16()),
            "p": pa.array([1, 1, 1, 0], pa.int8()),
        },
        schema=sensor.schema,
    )
    image = pecs.viz.event_frame(table, background="black")
    assert tuple(image[0, 0]) == CHANNEL_COLOURS_RGB["R"]
    assert tuple(image[0, 1]) == CHANNEL_COLOURS_RGB["G"]
    assert tuple(image[1, 1]) == CHANNEL_COLOURS_RGB["B"]
    # OFF: the green halfway to the black background.
    assert tuple(image[1, 0]) == tuple(round(v / 2) for v in CHANNEL_COLOURS_RGB["G"])
    assert tuple(image[0, 2]) == (0, 0, 0)  # no event there
