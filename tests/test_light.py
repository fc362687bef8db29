"""Light levels: [light] counts every emitter, [[lights]] sets each one, an envmap scales to lux.

Expected values come from first principles: a constant sky of radiance L gives E = pi L on an
open floor, a point lamp of intensity I at 1 m above it gives E = I; lux = 683 int V E d lambda
(CIE 1924 table read with numpy); the floor's photocurrent follows from the camera equation.
The envmap check integrates the scaled map's radiance over the hemisphere by quadrature.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pecs.render import Simulation

H = 6.62607015e-34  # J s
C = 299792458.0  # m/s
K_B = 1.380649e-23  # J/K
Q = 1.602176634e-19  # C
DATA = Path(__file__).resolve().parents[1] / "python" / "pecs" / "scenes"
GRID_NM = np.linspace(360.0, 1100.0, 7401)
W, HGT, PITCH_UM, FILL, F_NUMBER = 32, 32, 20.0, 0.5, 2.0
AT = "at = [0, 0, 0.001]\nnormal = [0, 0, 1]"


def integral(y: np.ndarray) -> float:
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(GRID_NM)))


def table(name: str) -> tuple[np.ndarray, np.ndarray]:
    rows = np.genfromtxt(DATA / name, delimiter=",", skip_header=1)
    rows = rows[np.isfinite(rows[:, 0])]
    return rows[:, 0], rows[:, 1]


V = np.interp(GRID_NM, *table("spectra/cie1924_photopic.csv"), left=0, right=0)
QE = np.interp(GRID_NM, *table("qe/generic_silicon_fsi.csv"), left=0, right=0)


def lux(irradiance_w_m2_nm: np.ndarray) -> float:
    return 683.0 * integral(V * irradiance_w_m2_nm)


def floor_photocurrent_pa(irradiance_w_m2_nm: np.ndarray) -> float:
    """A white (0.8) Lambertian floor seen on the axis of an ideal lens: L = rho E / pi."""
    radiance = 0.8 * irradiance_w_m2_nm / math.pi
    electrons = integral(QE * radiance * GRID_NM * 1e-9 / (H * C))
    area_m2 = (PITCH_UM * 1e-6) ** 2 * FILL
    return electrons * Q * area_m2 * math.pi / (4 * F_NUMBER**2) * 1e12


SKY_FLAT = 1.0  # W / (m^2 sr nm), any value: [[lights]] rescales it
SKY_100_LUX = 100.0 / lux(np.full_like(GRID_NM, math.pi))  # the flat radiance giving 100 lux


def floor_scene(folder: Path, lamp: str, sky: float, light: str) -> Path:
    """A camera 2 m above a 10 m floor, a point lamp 1 m above its centre, a constant sky."""
    (folder / "scene.xml").write_text(
        f"""<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
  </sensor>
  <shape type="rectangle"><transform name="to_world"><scale value="5"/></transform>
    <bsdf type="diffuse"><float name="reflectance" value="0.8"/></bsdf></shape>
  <emitter type="point" id="lamp"><point name="position" value="0, 0, 1"/>
    <spectrum name="intensity" value="{lamp}"/></emitter>
  <emitter type="constant" id="sky"><spectrum name="radiance" value="360:{sky}, 1100:{sky}"/>
  </emitter>
</scene>"""
    )
    (folder / "scene.toml").write_text(
        '[scene]\nmitsuba = "scene.xml"\n[time]\nduration_s = 0.01\nrate_hz = 100\n'
        f'[sensor]\npreset = "davis346"\noverrides = {{ width = {W}, height = {HGT}, '
        f"pixel_pitch_um = {PITCH_UM}, fill_factor = {FILL} }}\n"
        f'[optics]\nmodel = "pinhole"\nefl_mm = 50.0\nf_number = {F_NUMBER}\n'
        "[render]\nspp = 64\nmax_depth = 2\n" + light
    )
    return folder / "scene.toml"


def centre_pa(path: Path) -> float:
    frame = next(iter(Simulation(path).frames())).photocurrent_pa.astype(np.float64)
    return float(np.mean(frame[HGT // 2 - 8 : HGT // 2 + 8, W // 2 - 8 : W // 2 + 8]))


def test_light_counts_the_sky_and_scales_the_lamp_to_the_rest(tmp_path: Path) -> None:
    # 100 lux of sky + a 3000 K lamp, [light] asks 300 lux: the lamp gives 200 (not 300).
    path = floor_scene(
        tmp_path,
        "$light_spectrum",
        SKY_100_LUX,
        f"[light]\ntemperature_k = 3000\nilluminance_lux = 300\n{AT}\n",
    )
    wavelength_m = GRID_NM * 1e-9
    planck = 1 / wavelength_m**5 / np.expm1(H * C / (wavelength_m * K_B * 3000.0))
    sky = np.full_like(GRID_NM, math.pi * SKY_100_LUX)
    lamp = planck * 200.0 / lux(planck)
    assert lux(sky + lamp) == pytest.approx(300.0)
    assert centre_pa(path) / floor_photocurrent_pa(sky + lamp) == pytest.approx(1.0, abs=0.02)


def test_light_refuses_when_the_other_emitters_already_exceed_it(tmp_path: Path) -> None:
    path = floor_scene(
        tmp_path,
        "$light_spectrum",
        SKY_100_LUX,
        f"[light]\ntemperature_k = 3000\nilluminance_lux = 50\n{AT}\n",
    )
    with pytest.raises(ValueError, match=r"already give 1\d\d(\.\d+)? lux there \(sky: "):
        _ = Simulation(path).renderer


def test_lights_set_each_emitter_by_lux_or_by_scale(tmp_path: Path) -> None:
    # The sky (any level) scaled to 100 lux; the lamp's own intensity doubled.
    path = floor_scene(
        tmp_path,
        "360:0.5, 1100:1.5",
        SKY_FLAT,
        f'[[lights]]\nid = "sky"\nilluminance_lux = 100\n{AT}\n'
        '[[lights]]\nid = "lamp"\nscale = 2.0\n',
    )
    sky = np.full_like(GRID_NM, math.pi * SKY_100_LUX)
    lamp = 2.0 * np.interp(GRID_NM, [360.0, 1100.0], [0.5, 1.5]) / 1.0**2  # I / d^2, d = 1 m
    simulation = Simulation(path)
    assert centre_pa(path) / floor_photocurrent_pa(sky + lamp) == pytest.approx(1.0, abs=0.02)
    scales = simulation.renderer.emitter_scales
    assert scales["lamp"] == 2.0
    # 2^18 meter samples (JIT variants): ~0.2 %; the scalar variant uses 2^12: ~1.5 %
    assert scales["sky"] == pytest.approx(SKY_100_LUX / SKY_FLAT, rel=0.02)


def test_lights_name_unknown_and_unscalable_emitters(tmp_path: Path) -> None:
    path = floor_scene(tmp_path, "360:1, 1100:1", 0.01, '[[lights]]\nid = "sun"\nscale = 2\n')
    with pytest.raises(ValueError, match=r"lights id 'sun': not an emitter .*\['lamp', 'sky'\]"):
        _ = Simulation(path).renderer
    xml = (tmp_path / "scene.xml").read_text()
    blackbody = '<spectrum type="blackbody" name="intensity"><float name="temperature" value="3000"/></spectrum>'
    xml = xml.replace('<spectrum name="intensity" value="360:1, 1100:1"/>', blackbody)
    (tmp_path / "scene.xml").write_text(xml)
    path.write_text(path.read_text().replace('"sun"', '"lamp"'))
    with pytest.raises(ValueError, match="lights id 'lamp': its spectrum has no value"):
        _ = Simulation(path).renderer


def envmap_irradiance_lux(emitter: object, normal: np.ndarray) -> float:
    """683 int V(lambda) int L(omega, lambda) cos dOmega over the hemisphere about `normal`,
    by the midpoint rule in (theta, phi), the map's radiance read with `emitter.eval`."""
    import drjit as dr
    from pecs._mitsuba import mitsuba

    mi = mitsuba()
    if not dr.is_jit_v(mi.Float):
        pytest.skip("the quadrature evaluates the map as one wavefront (JIT variants)")
    n_theta, n_phi = 128, 256
    theta = (np.arange(n_theta) + 0.5) * (math.pi / 2) / n_theta
    phi = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    theta, phi = (a.ravel() for a in np.meshgrid(theta, phi, indexing="ij"))
    tangent = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    tangent /= np.linalg.norm(tangent)
    bitangent = np.cross(normal, tangent)
    direction = (
        np.sin(theta)[:, None] * (np.cos(phi)[:, None] * tangent + np.sin(phi)[:, None] * bitangent)
        + np.cos(theta)[:, None] * normal
    )
    weight = np.cos(theta) * np.sin(theta) * (math.pi / 2 / n_theta) * (2 * math.pi / n_phi)
    wavelength_nm = np.arange(362.5, 840.0, 5.0)  # 96 bins of 5 nm, four per Mitsuba lane
    spectral = []
    for group in wavelength_nm.reshape(-1, 4):
        si = dr.zeros(mi.SurfaceInteraction3f, theta.size)
        si.wi = mi.Vector3f(*(-direction.T))  # eval looks along -wi
        si.wavelengths = mi.Spectrum(*(float(w) for w in group))
        radiance = np.array(emitter.eval(si), dtype=np.float64).reshape(4, -1)  # type: ignore[attr-defined]
        spectral.extend(radiance @ weight)
    v = np.interp(wavelength_nm, *table("spectra/cie1924_photopic.csv"), left=0, right=0)
    return 683.0 * float(np.sum(v * np.array(spectral)) * 5.0)


def test_environment_map_is_scaled_to_lux(tmp_path: Path) -> None:
    from pecs._mitsuba import mitsuba

    mi = mitsuba()
    rows, cols = np.meshgrid(np.linspace(0, 1, 16), np.linspace(0, 1, 32), indexing="ij")
    sky = np.stack([0.2 + 2 * (1 - rows), 0.5 + rows * cols, 1.0 + 0 * rows], axis=-1)
    mi.Bitmap(sky.astype(np.float32)).write(str(tmp_path / "sky.exr"))
    path = floor_scene(tmp_path, "360:1, 1100:1", 0.01, "")
    # nothing but the map: the quadrature below has no occluders
    (tmp_path / "scene.xml").write_text(
        '<scene version="3.0.0"><emitter type="envmap" id="sky">'
        '<string name="filename" value="sky.exr"/></emitter></scene>'
    )
    tilted = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    path.write_text(
        path.read_text()
        + '[[lights]]\nid = "sky"\nilluminance_lux = 250\nat = [0, 0, 3]\n'
        + f"normal = {tilted.tolist()}\n"
    )
    renderer = Simulation(path).renderer
    envmap = next(e for e in renderer.scene.emitters() if e.get_shape() is None and e.id() == "sky")
    assert envmap_irradiance_lux(envmap, tilted) == pytest.approx(250.0, rel=0.01)


def test_light_without_light_spectrum_emitters_points_to_lights(tmp_path: Path) -> None:
    path = floor_scene(
        tmp_path,
        "360:1, 1100:1",
        SKY_FLAT,
        f"[light]\ntemperature_k = 3000\nilluminance_lux = 300\n{AT}\n",
    )
    with pytest.raises(ValueError, match=r"does not use \$light_spectrum .*use \[\[lights\]\]"):
        _ = Simulation(path).renderer
