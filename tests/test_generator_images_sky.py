"""Natural-image textures and sky environment maps of the scene generators: crops are the
source's pixels, licences are recorded, the sky is the CIE sky as Mitsuba sees it, its share of
the illuminance is accounted, and a scene with both renders into events."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import tomllib
from pecs.dataset import generators
from pecs.dataset.generators import environment, images, textures
from pecs.render import Simulation
from PIL import Image


def photo_linear() -> np.ndarray:
    """grace_hopper.jpg decoded here (PIL, the sRGB formula), for comparison."""
    import matplotlib

    path = Path(matplotlib.get_data_path()) / "sample_data" / "grace_hopper.jpg"
    srgb = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255.0
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def photo_crop(angle_deg: float) -> dict:
    # Half the 512 px width at 256 px: one texel per source pixel, from the top-left corner.
    return {
        "kind": "image",
        "image": "grace_hopper",
        "colour": True,
        "crop_fraction": 0.5,
        "centre": [0.0, 0.0],
        "angle_deg": angle_deg,
        "albedo_range": [0.1, 0.6],
    }


def test_a_crop_is_the_source_pixels_mapped_into_the_albedo_range() -> None:
    source = photo_linear()[:256, :256]
    crop = textures.texture_image(photo_crop(0.0), 256)
    assert crop.shape == (256, 256, 3)
    np.testing.assert_allclose(crop, 0.1 + 0.5 * source, atol=1e-12)
    # A quarter turn turns the pixels (the square stays inside the image).
    turned = textures.texture_image(photo_crop(90.0), 256)
    np.testing.assert_allclose(turned, np.rot90(0.1 + 0.5 * source), atol=1e-9)


def test_written_images_are_srgb_reflectance_and_grey_relief_weights(tmp_path: Path) -> None:
    textures.write_texture(photo_crop(0.0), tmp_path / "photo.png")
    srgb = np.asarray(Image.open(tmp_path / "photo.png"), dtype=np.float64) / 255.0
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    expected = 0.1 + 0.5 * photo_linear()[:256, :256]
    assert np.abs(linear - expected).max() < 0.01  # 8-bit sRGB steps
    rng = np.random.default_rng(3)
    relief = next(
        t for t in (images.describe_image(rng, [0.0, 1.0]) for _ in range(20)) if not t["colour"]
    )
    textures.write_texture(relief, tmp_path / "relief.png")
    grey = np.asarray(Image.open(tmp_path / "relief.png"))
    assert grey.ndim == 2 and grey.min() == 0 and grey.max() == 255


def scene_of(draw: dict, tmp_path: Path, index: int = 0, duration_s: float = 0.5) -> tuple:
    generator = generators.make_generator("objects", draw)
    description = generator.describe(generators.scene_rng(2, index), duration_s)
    settings = generators.SceneSettings(
        duration_s=duration_s, rate_hz=1000.0, spp=1, sensor={"width": 32, "height": 24}
    )
    path = generator.write(description, tmp_path, settings)
    return description, path


def test_image_licences_are_in_the_written_description(tmp_path: Path) -> None:
    draw = {"object_count": [6, 6], "textures": ["image"], "materials": ["diffuse"]}
    description, path = scene_of(draw, tmp_path)
    written = json.loads((path.parent / "description.json").read_text())
    assert written == description
    found = {o["material"]["texture"]["image"] for o in written["objects"]}
    assert found == {"grace_hopper", "jacksboro_fault"}
    for obj in written["objects"]:
        texture = obj["material"]["texture"]
        assert texture["licence"] == images.IMAGES[texture["image"]].licence == "public domain"
        assert texture["credit"] == images.IMAGES[texture["image"]].credit
    xml = (path.parent / "scene.xml").read_text()
    assert 'name="wrap_mode" value="mirror"' in xml


def mitsuba_radiance(emitter: object, direction: np.ndarray, wavelength_nm: float) -> float:
    """The envmap's radiance seen looking towards `direction` (Mitsuba's own lookup)."""
    from pecs._mitsuba import mitsuba

    mi = mitsuba()
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*(-float(v) for v in direction))
    si.wavelengths = mi.Spectrum(*([float(wavelength_nm)] * 4))
    return float(np.ravel(np.array(emitter.eval(si)))[0])


def load_sky(sky: dict, tmp_path: Path) -> object:
    from pecs._mitsuba import mitsuba

    mi = mitsuba()
    environment.write_sky(sky, tmp_path / "sky.pfm")
    return mi.load_dict({"type": "envmap", "filename": str(tmp_path / "sky.pfm")})


def test_the_overcast_map_is_the_cie_overcast_sky_in_mitsuba(tmp_path: Path) -> None:
    sky = {"kind": "overcast", "sun_elevation_deg": 40.0, "sun_azimuth_deg": 30.0}
    emitter = load_sky(sky, tmp_path)
    zenith = mitsuba_radiance(emitter, [0.0, 1.0, 0.0], 550.0)
    # CIE type 1 (ISO 15469): no azimuth dependence, gradation 1 + 4 exp(-0.7 / cos Z), here
    # 1.000, 0.932, 0.665, 0.359 of the zenith at Z = 0, 30, 60, 80 degrees; within 3 % (the
    # map's pixels are 1.4 degrees wide, Mitsuba interpolates between them).
    for zenith_deg, azimuth_deg, expected in [(30, 10, 0.932), (60, 200, 0.665), (80, 95, 0.359)]:
        z, a = math.radians(zenith_deg), math.radians(azimuth_deg)
        d = [math.sin(z) * math.sin(a), math.cos(z), math.sin(z) * math.cos(a)]
        assert mitsuba_radiance(emitter, d, 550.0) / zenith == pytest.approx(expected, rel=0.03)
    # Below the horizon: the grey ground, dimmer than any sky.
    assert 0 < mitsuba_radiance(emitter, [0.3, -0.8, 0.2], 550.0) < 0.5 * zenith


def test_the_clear_sky_is_brightest_towards_the_sun(tmp_path: Path) -> None:
    sky = {"kind": "clear", "sun_elevation_deg": 35.0, "sun_azimuth_deg": 120.0}
    emitter = load_sky(sky, tmp_path)
    el = math.radians(35.0)

    def at(azimuth_deg: float) -> list[float]:  # azimuth from +z towards +x, as the lights'
        a = math.radians(azimuth_deg)
        return [math.cos(el) * math.sin(a), math.sin(el), math.cos(el) * math.cos(a)]

    radiance = [mitsuba_radiance(emitter, at(a), 550.0) for a in range(0, 360, 10)]
    assert int(np.argmax(radiance)) * 10 in (110, 120, 130)
    # Away from the sun the clear sky is far darker (CIE type 12: about 10x here).
    assert max(radiance) > 5.0 * min(radiance)
    # No light from 830 nm on (Mitsuba's D65 ends there), as the docs say.
    assert mitsuba_radiance(emitter, at(120.0), 900.0) == 0.0


def test_the_sky_gets_its_share_of_the_illuminance(tmp_path: Path) -> None:
    draw = {"backgrounds": ["sky"], "light_count": [2, 2], "sky_share": [0.7, 0.7]}
    description, path = scene_of(draw, tmp_path, index=5)
    table = tomllib.loads(path.read_text())
    total = description["illuminance_lux"]
    assert table["light"]["illuminance_lux"] == pytest.approx(total, rel=1e-8)
    levels = {entry["id"]: entry["illuminance_lux"] for entry in table["lights"]}
    weights = [light["weight"] for light in description["lights"]]
    assert levels["sky"] == pytest.approx(0.7 * total, rel=1e-8)
    # The second lamp's share of the lamps' 30 %; the first makes up the rest under [light].
    assert levels["light_1"] == pytest.approx(0.3 * total * weights[1] / sum(weights), rel=1e-8)
    assert (path.parent / "textures" / "sky.pfm").is_file()


def test_an_image_textured_scene_under_a_sky_renders_events(tmp_path: Path) -> None:
    draw = {
        "object_count": [3, 3],
        "textures": ["image"],
        "materials": ["diffuse", "plastic"],
        "background_textures": ["image"],
        "backgrounds": ["sky"],
        "illuminance_lux": [2000, 2000],
        "camera_speed_m_s": [1.5, 1.5],
        "camera_angular_rate_deg_s": [60, 60],
    }
    _, path = scene_of(draw, tmp_path / "scene", duration_s=0.003)
    result = Simulation(path).run(tmp_path / "out")
    assert result.frames == 4  # 32 x 24, 1 spp, 1 kHz: 0, 1, 2, 3 ms
    assert pq.read_table(result.out_dir / "events.parquet").num_rows > 0
