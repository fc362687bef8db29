"""Scene -> spectral render -> photocurrent -> events, checked against radiometry done by hand.

Expected values are computed here from first principles (Planck's and the camera equation,
CODATA constants, the QE table read with numpy), never from pecs's own helpers.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pecs
import pyarrow.parquet as pq
import pytest
from pecs.config import NOISE_OFF
from pecs.render import Simulation, load_scene

H = 6.62607015e-34  # J s (exact, SI 2019)
C = 299792458.0  # m/s (exact)
Q = 1.602176634e-19  # C (exact)
DATA = (
    Path(__file__).resolve().parents[1] / "python" / "pecs" / "scenes"
)  # read as data files, not through pecs

W, HGT = 64, 48
PITCH_UM, FILL, EFL_MM, F_NUMBER = 20.0, 0.5, 8.0, 2.0
QUIET = {**NOISE_OFF, "theta_sigma": 0.0, "jitter_us": 0.0, "latency_us": 0.0}


def qe_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The shipped QE table, read with numpy (header row and # comments skipped)."""
    rows = np.genfromtxt(DATA / "qe" / f"{name}.csv", delimiter=",", skip_header=1)
    rows = rows[np.isfinite(rows[:, 0])]
    return rows[:, 0], rows[:, 1]


def write_scene(folder: Path, xml_body: str, toml_extra: str = "", **sections: str) -> Path:
    (folder / "scene.xml").write_text(f'<scene version="3.0.0">{xml_body}</scene>')
    toml = {
        "scene": 'mitsuba = "scene.xml"',
        "time": "duration_s = 0.01\nrate_hz = 100",
        "sensor": (
            'preset = "davis346"\n'
            f"overrides = {{ width = {W}, height = {HGT}, pixel_pitch_um = {PITCH_UM}, "
            f"fill_factor = {FILL} }}"
        ),
        "optics": f'model = "pinhole"\nefl_mm = {EFL_MM}\nf_number = {F_NUMBER}',
        "render": "spp = 4\nmax_depth = 2",
    }
    toml.update(sections)
    text = "\n".join(f"[{k}]\n{v}" for k, v in toml.items() if v is not None) + toml_extra
    path = folder / "scene.toml"
    path.write_text(text)
    return path


def first_frame(path: Path, **kwargs: object) -> np.ndarray:
    return next(iter(Simulation(path, **kwargs).frames())).photocurrent_pa.astype(np.float64)


def camera_factor() -> np.ndarray:
    """E/L of an ideal lens per pixel: pi / (4 N^2) cos^4(field angle) (camera equation)."""
    x_mm = (np.arange(W) + 0.5 - W / 2) * PITCH_UM * 1e-3
    y_mm = (np.arange(HGT) + 0.5 - HGT / 2) * PITCH_UM * 1e-3
    tan2 = (x_mm[None, :] ** 2 + y_mm[:, None] ** 2) / EFL_MM**2
    return math.pi / (4 * F_NUMBER**2) / (1 + tan2) ** 2


OPTICS = {
    "pinhole": f'model = "pinhole"\nefl_mm = {EFL_MM}\nf_number = {F_NUMBER}',
    "thinlens": f'model = "thinlens"\nefl_mm = {EFL_MM}\nf_number = {F_NUMBER}\nfocus_m = 2.0',
}


RAMP_RADIANCE = "400:0.01, 1000:0.03"  # W / (m^2 sr nm): 0.01 at 400 nm to 0.03 at 1000 nm


def uniform_emitter_scene(folder: Path, optics: str = "pinhole") -> Path:
    emitter = f'<emitter type="constant"><spectrum name="radiance" value="{RAMP_RADIANCE}"/>'
    return write_scene(folder, emitter + "</emitter>", optics=OPTICS[optics])


def uniform_emitter_expected_pa() -> np.ndarray:
    """q * A * E/L * integral QE(lambda) L(lambda) lambda / (h c) d lambda, per pixel, in pA."""
    grid_nm = np.linspace(400, 1000, 6001)
    lam_qe, qe = qe_table("generic_silicon_fsi")
    l_spec = np.interp(grid_nm, [400, 1000], [0.01, 0.03])
    integrand = np.interp(grid_nm, lam_qe, qe, left=0, right=0) * l_spec * grid_nm * 1e-9 / (H * C)
    electrons = np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(grid_nm))
    area_m2 = (PITCH_UM * 1e-6) ** 2 * FILL
    return electrons * Q * area_m2 * camera_factor() * 1e12


@pytest.mark.parametrize("optics", sorted(OPTICS))
def test_uniform_emitter_gives_the_photocurrent_of_the_radiometric_integral(
    tmp_path: Path, optics: str
) -> None:
    ratio = first_frame(uniform_emitter_scene(tmp_path, optics)) / uniform_emitter_expected_pa()
    assert abs(np.mean(ratio) - 1) < 0.02, np.mean(ratio)
    # per pixel too, away from Monte Carlo outliers: 95 % of pixels within 10 %
    assert np.mean(np.abs(ratio - 1) < 0.10) > 0.95


def test_scalar_variant_fallback_gives_the_same_radiometry(tmp_path: Path) -> None:
    # The variant is chosen once per process: the scalar fallback runs in a child process.
    path = uniform_emitter_scene(tmp_path)
    code = (
        "import sys, numpy as np, pecs\n"
        "sim = pecs.Simulation(sys.argv[1])\n"
        "frame = next(iter(sim.frames())).photocurrent_pa\n"
        "np.save(sys.argv[2], frame)\n"
        "print(sim.renderer.mi.variant())\n"
    )
    env = {**os.environ, "PECS_MITSUBA_VARIANT": "scalar_spectral"}
    out = tmp_path / "frame.npy"
    result = subprocess.run(
        [sys.executable, "-c", code, str(path), str(out)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert result.stdout.strip() == "scalar_spectral"
    ratio = np.load(out) / uniform_emitter_expected_pa()
    assert abs(np.mean(ratio) - 1) < 0.02, np.mean(ratio)


def test_realistic_lens_centre_follows_the_camera_equation(tmp_path: Path) -> None:
    # An aberration-free lens of f-number N gives E / L = pi / (4 N^2) on axis; the real
    # double Gauss at f/4 comes within a few per cent of it at the centre of the film.
    optics = 'lens = "dgauss50"\nefl_mm = 8.0\nf_number = 4.0\nfocus_m = 2.0'
    path = write_scene(
        tmp_path,
        '<emitter type="constant"><spectrum name="radiance" value="400:0.02, 1000:0.02"/></emitter>',
        optics=optics,
    )
    frame_pa = first_frame(path, spp=16)
    lam_qe, qe = qe_table("generic_silicon_fsi")
    grid_nm = np.linspace(400, 1000, 6001)
    integrand = np.interp(grid_nm, lam_qe, qe) * 0.02 * grid_nm * 1e-9 / (H * C)
    electrons = np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(grid_nm))
    expected_pa = electrons * Q * (PITCH_UM * 1e-6) ** 2 * FILL * math.pi / (4 * 4.0**2) * 1e12
    centre = frame_pa[HGT // 2 - 4 : HGT // 2 + 4, W // 2 - 4 : W // 2 + 4]
    assert np.mean(centre) / expected_pa == pytest.approx(1.0, abs=0.03)


def test_a_lens_without_f_number_renders_wide_open_without_a_warning(tmp_path: Path) -> None:
    # The scene default f/2 used to reach every lens, clamped with a warning for slower ones
    # (pecs4 is f/4.15 wide open). Left out, a lens is wide open: the same frame as its widest
    # f-number given explicitly, and no warning.
    import warnings

    from pecs.lens import Lens

    widest = Lens.load("pecs4").f_number()
    emitter = (
        '<emitter type="constant"><spectrum name="radiance" value="400:0.02, 1000:0.02"/></emitter>'
    )
    (tmp_path / "given").mkdir()
    (tmp_path / "left_out").mkdir()
    given = write_scene(
        tmp_path / "given",
        emitter,
        optics=f'lens = "pecs4"\nefl_mm = 15.0\nf_number = {widest!r}\nfocus_m = 2.0',
    )
    left_out = write_scene(
        tmp_path / "left_out", emitter, optics='lens = "pecs4"\nefl_mm = 15.0\nfocus_m = 2.0'
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame = first_frame(left_out, spp=4)
    np.testing.assert_array_equal(frame, first_frame(given, spp=4))


def led_spectrum(wavelength_nm: np.ndarray) -> np.ndarray:
    """A white-LED-like shape: a blue pump at 450 nm and a broad phosphor band at 570 nm."""
    blue = np.exp(-0.5 * ((wavelength_nm - 450) / 10) ** 2)
    phosphor = 0.6 * np.exp(-0.5 * ((wavelength_nm - 570) / 50) ** 2)
    return blue + phosphor


@pytest.mark.parametrize("source", ["blackbody", "spectrum_file"])
def test_light_is_scaled_to_the_requested_illuminance(tmp_path: Path, source: str) -> None:
    # A point lamp scaled to 250 lux at the centre of a white (0.8) Lambertian floor: the floor's
    # radiance there is rho E / pi, E(lambda) the lamp's spectral shape normalised by
    # 683 lm/W * integral V(lambda) E(lambda) = 250 lux (V: the CIE 1924 table).
    xml = """
    <sensor type="perspective">
      <transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
    </sensor>
    <shape type="rectangle"><bsdf type="diffuse"><float name="reflectance" value="0.8"/></bsdf>
    </shape>
    <emitter type="point"><point name="position" value="0, 0, 1"/>
      <spectrum name="intensity" value="$light_spectrum"/></emitter>
    """
    grid_nm = np.linspace(360, 1100, 7401)
    wavelength_m = grid_nm * 1e-9
    if source == "blackbody":
        spectrum = "temperature_k = 3000"
        k_b = 1.380649e-23
        shape = 1 / wavelength_m**5 / np.expm1(H * C / (wavelength_m * k_b * 3000.0))
    else:
        table_nm = np.arange(380.0, 781.0, 5.0)
        rows = "\n".join(f"{w:g},{x:.6f}" for w, x in zip(table_nm, led_spectrum(table_nm)))
        (tmp_path / "led.csv").write_text(f"# test LED\nwavelength_nm,power\n{rows}\n")
        spectrum = 'spectrum = "led.csv"'
        shape = np.interp(grid_nm, table_nm, led_spectrum(table_nm), left=0, right=0)
    light = f"{spectrum}\nilluminance_lux = 250\nat = [0, 0, 0]\nnormal = [0, 0, 1]"
    path = write_scene(
        tmp_path,
        xml,
        optics='model = "pinhole"\nefl_mm = 50.0\nf_number = 2.0',
        light=light,
    )
    frame_pa = first_frame(path)
    cie = np.genfromtxt(DATA / "spectra" / "cie1924_photopic.csv", delimiter=",")
    cie = cie[np.isfinite(cie[:, 0])]
    v = np.interp(grid_nm, cie[:, 0], cie[:, 1], left=0, right=0)

    def integral(y: np.ndarray) -> float:
        return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(grid_nm)))

    irradiance = shape * 250.0 / (683.0 * integral(v * shape))  # W / (m^2 nm)
    lam_qe, qe = qe_table("generic_silicon_fsi")
    qe_grid = np.interp(grid_nm, lam_qe, qe, left=0, right=0)
    electrons = integral(qe_grid * 0.8 * irradiance / math.pi * wavelength_m / (H * C))
    expected_pa = electrons * Q * (PITCH_UM * 1e-6) ** 2 * FILL * math.pi / (4 * 2.0**2) * 1e12
    centre = frame_pa[HGT // 2 - 8 : HGT // 2 + 8, W // 2 - 8 : W // 2 + 8]
    assert np.mean(centre) / expected_pa == pytest.approx(1.0, abs=0.02)


def narrow_band(centre_nm: float) -> str:
    edges = [centre_nm - 6, centre_nm - 4, centre_nm + 4, centre_nm + 6]
    return ", ".join(f"{w:g}:{v}" for w, v in zip(edges, [0, 1, 1, 0], strict=True))


def test_narrow_bands_at_450_and_650_nm_scale_as_qe_times_wavelength(tmp_path: Path) -> None:
    values = {}
    for centre in (450.0, 650.0):
        folder = tmp_path / f"band{int(centre)}"
        folder.mkdir()
        emitter = f'<emitter type="constant"><spectrum name="radiance" value="{narrow_band(centre)}"/></emitter>'
        # Most wavelength samples miss a 12 nm band: 64 spp keeps the Monte Carlo error < 1 %.
        values[centre] = first_frame(write_scene(folder, emitter), spp=64).mean()
    lam_qe, qe = qe_table("generic_silicon_fsi")
    # QE * lambda at the two wavelengths, averaged over each band's trapezoid (the tabulated QE
    # has a kink at 450 nm: the band average differs from the centre value by 0.6 %).
    grid_nm = np.linspace(430, 670, 24001)
    qe_lambda = np.interp(grid_nm, lam_qe, qe) * grid_nm

    def band_mean(centre: float) -> float:
        weight = np.interp(grid_nm, [centre - 6, centre - 4, centre + 4, centre + 6], [0, 1, 1, 0])
        return float(np.sum(weight * qe_lambda) / np.sum(weight))

    expected = band_mean(450.0) / band_mean(650.0)
    assert values[450.0] / values[650.0] == pytest.approx(expected, rel=0.03)


def test_static_scene_with_noise_off_fires_almost_no_pixel() -> None:
    sim = Simulation(
        "checkerboard",
        duration_s=0.05,
        rate_hz=1000,
        spp=4,
        sensor={"width": W, "height": HGT, "pixel_pitch_um": 140.0, **QUIET},
    )
    # freeze the board: the same pose at every time
    spec = sim.spec
    track = spec.objects["board"]
    frozen = type(track)([track.keyframes[0]])
    sim.spec = type(spec)(**{**spec.__dict__, "objects": {"board": frozen}})
    pixels = set()
    frames = 0
    for batch in sim.event_batches():
        x, y = batch.column("x").to_numpy(), batch.column("y").to_numpy()
        pixels.update(zip(x.tolist(), y.tolist(), strict=True))
        frames += 1
    assert frames == 52  # 51 frames (the first only initialises) and the flush
    assert len(pixels) < 0.001 * W * HGT


def test_moving_checkerboard_fires_on_edges_with_the_polarity_of_the_motion(tmp_path: Path) -> None:
    sensor = {"width": W, "height": HGT, "pixel_pitch_um": 140.0, **QUIET}
    sim = Simulation("checkerboard", duration_s=0.05, rate_hz=1000, spp=4, sensor=sensor)
    frames = list(sim.frames())
    summary = sim.run(tmp_path / "out")
    events = pq.read_table(summary.files["events"])
    assert events.num_rows > 100
    x = events.column("x").to_numpy().astype(int)
    y = events.column("y").to_numpy().astype(int)
    p = events.column("p").to_numpy()
    first = np.log(frames[0].photocurrent_pa + 1e-3)
    last = np.log(frames[-1].photocurrent_pa + 1e-3)
    # The board moves +x in the world; the camera at z = 1 looks down -z with +y up, so world +x
    # is image right: intensity at a pixel changes as -v dI/dx with v > 0 (pixels per second).
    gradient_x = np.zeros_like(first)
    gradient_x[:, 1:-1] = (first[:, 2:] - first[:, :-2]) / 2
    gradient_y = np.zeros_like(first)
    gradient_y[1:-1, :] = (first[2:, :] - first[:-2, :]) / 2
    edge = np.abs(gradient_x) > 0.5
    any_edge = edge | (np.abs(gradient_y) > 0.5)
    near_edge = any_edge.copy()
    for axis in (0, 1):
        for shift in (-1, 1):
            near_edge |= np.roll(any_edge, shift, axis=axis)
    assert np.mean(near_edge[y, x]) > 0.99
    on_edge = edge[y, x]
    brighter = -gradient_x[y, x] > 0
    agree = (p[on_edge] == 1) == brighter[on_edge]
    assert on_edge.sum() > 100 and np.mean(agree) > 0.95
    # and the polarity agrees with what the frames did over the run
    change = (last - first)[y, x]
    strong = np.abs(change) > 0.3
    assert np.mean((p[strong] == 1) == (change[strong] > 0)) > 0.95
    poses = pq.read_table(summary.files["ground_truth"])
    assert poses.num_rows == len(frames) == 51
    assert poses.column("t_us").to_pylist()[-1] == 50_000
    assert summary.files["preview"].stat().st_size > 0


# The adaptive stepping of a rendered moving edge: tests/test_time_stepping.py.


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace('preset = "davis346"', 'preset = "davis999"'), "sensor.preset"),
        (lambda t: t.replace("duration_s = 0.01", "duration_s = -1"), "time.duration_s"),
        (lambda t: t.replace("rate_hz = 100", ""), "time.rate_hz"),
        (lambda t: t.replace("spp = 4", "spp = 4\nsamples = 3"), "render.samples"),
    ],
)
def test_bad_scene_files_name_the_key(tmp_path: Path, edit, message: str) -> None:  # noqa: ANN001
    path = write_scene(tmp_path, '<emitter type="constant"/>')
    path.write_text(edit(path.read_text()))
    with pytest.raises(ValueError, match=message.replace(".", r"\.")) as info:
        load_scene(path)
    assert str(path) in str(info.value)


def test_unreadable_xml_and_missing_files_name_the_file(tmp_path: Path) -> None:
    path = write_scene(tmp_path, '<emitter type="constant"/>')
    (tmp_path / "scene.xml").write_text("<scene><shape></scene")
    with pytest.raises(ValueError, match="scene.xml"):
        load_scene(path)
    (tmp_path / "scene.xml").unlink()
    with pytest.raises(FileNotFoundError, match="scene.xml"):
        load_scene(path)
    with pytest.raises(FileNotFoundError, match="no_such_scene"):
        Simulation(tmp_path / "no_such_scene.toml")


def test_bad_sensor_override_names_the_field(tmp_path: Path) -> None:
    path = write_scene(tmp_path, '<emitter type="constant"/>')
    with pytest.raises(ValueError, match="theta_onn"):
        Simulation(path, sensor={"theta_onn": 0.3})


def test_cli_demo_writes_all_outputs(tmp_path: Path) -> None:
    from pecs.cli import main

    assert main(["demo", "-o", str(tmp_path), "--quiet"]) == 0
    events = pecs.read_events(tmp_path / "events.parquet")
    assert events.num_rows > 1000
    render = json.loads(events.schema.metadata[b"pecs.render"])
    assert render["mitsuba_variant"].endswith("_spectral") and render["photocurrent_unit"] == "pA"
    assert render["light_scale"] > 0 and render["seed"] == 0
    assert json.loads(events.schema.metadata[b"pecs.sensor"])["preset_name"] == "davis346"
    assert (tmp_path / "preview.png").stat().st_size > 0
    assert pq.read_table(tmp_path / "ground_truth.parquet").num_rows > 50


def test_cli_simulate_writes_exr_frames_and_depth(tmp_path: Path) -> None:
    from pecs.cli import main

    xml = """
    <sensor type="perspective">
      <transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
    </sensor>
    <shape type="rectangle"><transform name="to_world"><scale value="10"/></transform>
      <bsdf type="diffuse"><float name="reflectance" value="0.5"/></bsdf></shape>
    <emitter type="constant"><spectrum name="radiance" value="400:0.01, 1000:0.01"/></emitter>
    """
    path = write_scene(tmp_path, xml)
    out = tmp_path / "out"
    argv = ["simulate", str(path), "-o", str(out), "--duration", "0.002", "--rate", "1000"]
    assert main([*argv, "--spp", "2", "--frames", "--depth", "--quiet"]) == 0
    frames = sorted((out / "frames").glob("photocurrent_*.exr"))
    depths = sorted((out / "frames").glob("depth_*.exr"))
    assert len(frames) == len(depths) == 3
    from pecs.footage.frames import read_exr  # the Rust EXR reader, not Mitsuba's writer

    image = read_exr(frames[0])
    assert image.shape == (HGT, W) and np.all(image > 0)
    depth = read_exr(depths[0])
    # depth along each pixel's central ray to the plane z = 0 from z = 2: 2 / cos(field angle)
    x_mm = (np.arange(W) + 0.5 - W / 2) * PITCH_UM * 1e-3
    y_mm = (np.arange(HGT) + 0.5 - HGT / 2) * PITCH_UM * 1e-3
    expected = 2.0 * np.sqrt(1 + (x_mm[None, :] ** 2 + y_mm[:, None] ** 2) / EFL_MM**2)
    np.testing.assert_allclose(depth, expected, rtol=1e-4)
    assert (
        pq.read_table(out / "ground_truth.parquet").column("position_z_m").to_pylist() == [2.0] * 3
    )


def test_cli_simulate_reports_a_bad_preset(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from pecs.cli import main

    path = write_scene(tmp_path, '<emitter type="constant"/>')
    path.write_text(path.read_text().replace("davis346", "davis999"))
    assert main(["simulate", str(path), "-o", str(tmp_path / "out"), "--quiet"]) == 2
    assert "sensor.preset" in capsys.readouterr().err
    assert not (tmp_path / "out" / "events.parquet").exists()


def test_rotating_quadrant_disk_polarity_follows_the_sense_of_rotation(tmp_path: Path) -> None:
    # The disk turns counter-clockwise about +z (right-hand rule, angle increasing), seen from
    # +z with +y up and +x right: counter-clockwise in the image too. At polar angle phi the
    # intensity is I0(phi - omega t), so dL/dt = -omega dL/dphi with
    # dL/dphi = x dL/dy - y dL/dx (x right, y up, from the disk's centre).
    sensor = {"width": W, "height": HGT, "pixel_pitch_um": 140.0, **QUIET}
    sim = Simulation("quadrant_disk", duration_s=0.02, rate_hz=1000, spp=4, sensor=sensor)
    first = np.log(next(iter(sim.frames())).photocurrent_pa.astype(np.float64) + 1e-3)
    events = pq.read_table(sim.run(tmp_path / "out").files["events"])
    x = events.column("x").to_numpy().astype(int)
    y = events.column("y").to_numpy().astype(int)
    p = events.column("p").to_numpy()
    d_col = np.zeros_like(first)
    d_col[:, 1:-1] = (first[:, 2:] - first[:, :-2]) / 2
    d_row = np.zeros_like(first)
    d_row[1:-1, :] = (first[2:, :] - first[:-2, :]) / 2
    col_x = np.arange(W) + 0.5 - W / 2
    row_y = HGT / 2 - (np.arange(HGT) + 0.5)
    d_phi = col_x[None, :] * (-d_row) - row_y[:, None] * d_col
    strong = np.abs(d_phi[y, x]) > 2.0  # on a quadrant boundary, not the rim (radial gradient)
    assert strong.sum() > 50
    brighter = -d_phi[y, x][strong] > 0
    assert np.mean((p[strong] == 1) == brighter) > 0.9  # 0.965 measured; chance is 0.5


def test_a_sensor_config_file_drives_the_simulation(tmp_path: Path, monkeypatch) -> None:
    """`pecs simulate --config sensor.toml` (and `Simulation(sensor=SensorConfig)`) takes every
    field of the file and its preset's film; `--set` still applies on top."""
    fitted = pecs.SensorConfig.preset(
        "imx636", width=64, height=36, theta_on=0.31, theta_off=0.27, leak_rate_hz=0.002, seed=5
    )
    fitted.to_file(tmp_path / "sensor.toml")
    loaded = pecs.SensorConfig.from_file(tmp_path / "sensor.toml")
    sim = Simulation("checkerboard", sensor=loaded)
    assert sim.sensor_config == fitted
    assert sim.geometry.pitch_um == pytest.approx(4.86)  # the IMX636 pixels, from its preset

    import pecs.render as render
    from pecs.cli import main

    made: list[Simulation] = []

    class Capture(Simulation):
        def run(self, out_dir: object) -> object:
            made.append(self)
            raise ValueError("captured")

    monkeypatch.setattr(render, "Simulation", Capture)
    config_file = str(tmp_path / "sensor.toml")
    assert main(["simulate", "checkerboard", "--config", config_file, "--set", "theta_on=0.4"]) == 2
    assert made[0].sensor_config == fitted.replace(theta_on=0.4)
