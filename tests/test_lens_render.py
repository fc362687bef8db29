"""Small renders (64 x 64, llvm variant) with the "realisticlens" sensor, checked against
analytic optics and the float64 ray tracer."""

from __future__ import annotations

import numpy as np
import pytest
from pecs.lens import Lens

mi = pytest.importorskip("mitsuba")


@pytest.fixture(scope="module")
def mitsuba():
    from pecs._mitsuba import mitsuba as load
    from pecs.lens import register_realistic_lens

    module = load()
    register_realistic_lens()
    return module


RES = 64
BANDS = {"blue": (445.0, 455.0), "red": (645.0, 655.0)}


def _band_film(band):
    """A one-channel spectral film that sees only the band (lo, hi) nm."""
    lo, hi = band
    film = {"type": "specfilm", "width": RES, "height": RES, "rfilter": {"type": "box"}}
    film["band"] = {
        "type": "spectrum",
        "value": [(lo - 0.5, 0.0), (lo, 1.0), (hi, 1.0), (hi + 0.5, 0.0)],
    }
    return film


def _render(mi, sensor, shapes, spp, film=None, seed=0):
    sensor = dict(sensor)
    sensor["film"] = film or {
        "type": "hdrfilm",
        "width": RES,
        "height": RES,
        "rfilter": {"type": "box"},
    }
    sensor["sampler"] = {"type": "independent", "sample_count": spp}
    scene = {"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor, **shapes}
    return np.array(mi.render(mi.load_dict(scene), seed=seed), dtype=np.float64)


def test_centre_irradiance_over_radiance_is_pi_over_4n2(mitsuba):
    shapes = {"sky": {"type": "constant", "radiance": 1.0}}
    lens = _render(
        mitsuba,
        {"type": "realisticlens", "lens": "dgauss50", "efl_mm": 8.0, "f_number": 4.0},
        shapes,
        64,
    )
    pinhole = _render(mitsuba, {"type": "perspective", "fov": 30.0}, shapes, 4)
    c = slice(RES // 2 - 6, RES // 2 + 6)
    ratio = lens[c, c].mean() / pinhole[c, c].mean()
    assert ratio == pytest.approx(np.pi / (4 * 4.0**2), rel=0.03)


@pytest.mark.parametrize("f_number", [18.8, 32.0])
def test_a_small_stop_renders_in_proportion_to_its_area(mitsuba, f_number):
    # pecs4 stopped down to the PECS paper's f/18.8 (and f/32) rendered black: its pupil's
    # footprint on the rear plane fell between the coarse search grid's points. The centre's
    # irradiance goes with the stop's area: (8 / N)^2 of f/8's (same lens, same field).
    shapes = {"sky": {"type": "constant", "radiance": 1.0}}

    def centre(n):
        sensor = {"type": "realisticlens", "lens": "pecs4", "f_number": n}
        image = _render(mitsuba, sensor, shapes, 64)
        c = slice(RES // 2 - 6, RES // 2 + 6)
        return image[c, c].mean()

    assert centre(f_number) / centre(8.0) == pytest.approx((8.0 / f_number) ** 2, rel=0.03)


def test_relative_illumination_at_the_corner_matches_the_tracer(mitsuba):
    shapes = {"sky": {"type": "constant", "radiance": 1.0}}
    sensor = {
        "type": "realisticlens",
        "lens": "dgauss50",
        "efl_mm": 8.0,
        "f_number": 2.8,
        "dispersion": False,
    }
    img = _render(mitsuba, sensor, shapes, 256).mean(axis=2)
    pitch_mm = 8.0 / np.hypot(RES, RES)
    corner = [(i, j) for i in (0, 1, RES - 2, RES - 1) for j in (0, 1, RES - 2, RES - 1)]
    radii = np.array([np.hypot(i + 0.5 - RES / 2, j + 0.5 - RES / 2) * pitch_mm for i, j in corner])
    c = slice(RES // 2 - 8, RES // 2 + 8)
    rendered = np.mean([img[i, j] for i, j in corner]) / img[c, c].mean()
    lens = Lens.builtin("dgauss50").scaled_to(8.0).with_f_number(2.8)
    traced = lens.relative_illumination(radii).mean()
    assert traced < 0.8  # the corner is visibly vignetted, so the check means something
    assert rendered == pytest.approx(traced, rel=0.02)


SINGLET = """# name: bk7singlet
0     10.0   0       1.0    -
8.0   2.0    1.5168  6.0    N-BK7
-8.0  6.5    1       6.0    -
"""


def _centroid(img):
    ys, xs = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    return np.array([(img * xs).sum() / img.sum(), (img * ys).sum() / img.sum()])


CROP = (48, 24, 16, 16)  # x, y, width, height: the window around the spot, in film pixels


def _band_film_cropped(band):
    film = _band_film(band)
    film.update(
        crop_offset_x=CROP[0], crop_offset_y=CROP[1], crop_width=CROP[2], crop_height=CROP[3]
    )
    return film


@pytest.mark.parametrize("dispersion", [True, False])
def test_lateral_colour_matches_the_tracer(mitsuba, tmp_path, dispersion):
    path = tmp_path / "singlet.lens"
    path.write_text(SINGLET)
    focus_m, field_deg, pitch_um = 1.5, 1.0, 5.0
    lens = Lens.from_file(path).focused(focus_m)
    # The point's place in camera space (lens x kept; z from the film), as spot_diagram puts it.
    z0 = -1.0  # spot_diagram starts its rays 1 mm before the first surface (the stop)
    distance_mm = focus_m * 1e3 - (lens.total_track_mm - z0)
    x_m = -np.tan(np.radians(field_deg)) * distance_mm * 1e-3
    shapes = {
        "point": {
            "type": "sphere",
            "center": [x_m, 0.0, focus_m],
            "radius": 0.001,  # images to a disc of 1 px radius: its centroid is the point's
            "emitter": {"type": "area", "radiance": 1.0},
        }
    }
    sensor = {
        "type": "realisticlens",
        "lens": str(path),
        "focus_m": focus_m,
        "pixel_pitch_um": pitch_um,
        "dispersion": dispersion,
    }
    # Only a window around the spot is rendered (a cropped film), at many samples per pixel.
    blue_img, red_img = (
        _render(mitsuba, sensor, shapes, 4096, film=_band_film_cropped(BANDS[b]))[:, :, 0]
        for b in ("blue", "red")
    )
    offset = np.array(CROP[:2], dtype=np.float64)
    rendered = _centroid(blue_img) - _centroid(red_img)
    predicted = 0.0
    if dispersion:
        blue, red = (
            lens.spot_diagram(field_deg, 0.5 * sum(BANDS[b]), 64, object_distance_m=focus_m).mean(
                axis=0
            )
            for b in ("blue", "red")
        )
        predicted = (blue[0] - red[0]) * 1e3 / pitch_um
        assert abs(predicted) > 0.5  # a shift worth measuring
        # Where the image lies, not only the shift: the centroid lands on the traced spot.
        col = red[0] * 1e3 / pitch_um + RES / 2 - 0.5
        assert (_centroid(red_img) + offset)[0] == pytest.approx(col, abs=0.1)
        assert (_centroid(red_img) + offset)[1] == pytest.approx(RES / 2 - 0.5, abs=0.1)
    assert rendered[0] == pytest.approx(predicted, abs=0.1)
    assert abs(rendered[1]) < 0.1


def _edge_sharpness(mitsuba, plane_m, focus_m):
    """Mean of the steepest column step across a vertical emitting edge at the image centre."""
    half = 10.0 * plane_m
    shapes = {
        "edge": {
            "type": "rectangle",
            "flip_normals": True,
            "to_world": mitsuba.ScalarTransform4f()
            .translate([-half, 0.0, plane_m])
            .scale([half, half, 1.0]),
            "emitter": {"type": "area", "radiance": 1.0},
        }
    }
    sensor = {
        "type": "realisticlens",
        "lens": "dgauss50",
        "efl_mm": 8.0,
        "f_number": 2.0,
        "focus_m": focus_m,
        "pixel_pitch_um": 18.5,
    }
    img = _render(mitsuba, sensor, shapes, 32).mean(axis=2)
    rows = img[RES // 4 : 3 * RES // 4]
    rows = rows / rows.max()
    return np.abs(np.diff(rows, axis=1)).max(axis=1).mean()


def test_the_focus_distance_renders_sharpest(mitsuba):
    focus_m = 0.5
    sharp = _edge_sharpness(mitsuba, focus_m, focus_m)
    assert sharp > 1.2 * _edge_sharpness(mitsuba, focus_m / 2, focus_m)
    assert sharp > 1.2 * _edge_sharpness(mitsuba, focus_m * 2, focus_m)


def test_xml_scene_renders_like_the_dict_scene(mitsuba):
    xml = f"""<scene version="3.0.0">
      <integrator type="direct"/>
      <sensor type="realisticlens">
        <string name="lens" value="pecs4"/>
        <float name="efl_mm" value="8"/>
        <float name="f_number" value="5.6"/>
        <float name="focus_m" value="1.5"/>
        <transform name="to_world"><translate x="0.1" y="0" z="0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{RES}"/><integer name="height" value="{RES}"/>
          <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="8"/></sampler>
      </sensor>
      <shape type="sphere"><point name="center" x="0.1" y="0.05" z="1.5"/><float name="radius" value="0.1"/>
        <emitter type="area"><rgb name="radiance" value="1, 0.5, 0.2"/></emitter></shape>
    </scene>"""
    from_xml = np.array(mitsuba.render(mitsuba.load_string(xml), seed=3))
    sensor = {
        "type": "realisticlens",
        "lens": "pecs4",
        "efl_mm": 8.0,
        "f_number": 5.6,
        "focus_m": 1.5,
        "to_world": mitsuba.ScalarTransform4f().translate([0.1, 0.0, 0.0]),
    }
    shapes = {
        "ball": {
            "type": "sphere",
            "center": [0.1, 0.05, 1.5],
            "radius": 0.1,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 0.5, 0.2]}},
        }
    }
    from_dict = _render(mitsuba, sensor, shapes, 8, seed=3)
    assert from_xml.sum() > 0
    np.testing.assert_allclose(from_xml, from_dict, rtol=1e-5, atol=1e-6)
    # The ball sits above the optical axis (+y up): the upright image has it in the top half.
    lum = from_dict.mean(axis=2)
    assert lum[: RES // 2].sum() > 3 * lum[RES // 2 :].sum()


def test_moving_the_camera_moves_the_image(mitsuba):
    scene = mitsuba.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "direct"},
            "sensor": {
                "type": "realisticlens",
                "lens": "dgauss50",
                "efl_mm": 8.0,
                "f_number": 8.0,
                "focus_m": 2.0,
                "film": {
                    "type": "hdrfilm",
                    "width": RES,
                    "height": RES,
                    "rfilter": {"type": "box"},
                },
                "sampler": {"type": "independent", "sample_count": 16},
            },
            "ball": {
                "type": "sphere",
                "center": [0.0, 0.0, 2.0],
                "radius": 0.05,
                "emitter": {"type": "area", "radiance": 1.0},
            },
        }
    )
    import drjit as dr

    params = mitsuba.traverse(scene)

    def render_at(x_m):
        params["sensor.to_world"] = mitsuba.ScalarTransform4f().translate([x_m, 0.0, 0.0])
        params.update()
        dr.kernel_history()  # clear
        centroid = _centroid(np.array(mitsuba.render(scene, seed=0)).mean(axis=2))
        kernels = {k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT}
        return centroid, kernels

    mitsuba.render(scene, seed=0)  # first frame: scene set-up kernels
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        first, kernels_before = render_at(-0.05)
        # Camera moved 0.1 m along its +x (image left): the ball appears right by f * 0.1 / 2 m.
        second, kernels_after = render_at(0.05)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    # The pose is an opaque input of the kernel: moving the camera reuses the compiled kernel.
    assert kernels_after and kernels_after == kernels_before
    pitch_mm = 8.0 / np.hypot(RES, RES)
    expected_px = 8.0 * 0.1 / 2.0 / pitch_mm
    assert second[0] - first[0] == pytest.approx(expected_px, rel=0.05)
    assert abs(second[1] - first[1]) < 0.2


_SCALAR_SCRIPT = """
import json, numpy as np
from pecs._mitsuba import mitsuba
mi = mitsuba("scalar_spectral")
from pecs.lens import register_realistic_lens
register_realistic_lens()
scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct"},
    "sensor": {"type": "realisticlens", "lens": "dgauss50", "efl_mm": 8.0, "f_number": 4.0,
               "dispersion": False,
               "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}},
               "sampler": {"type": "independent", "sample_count": 256}},
    "sky": {"type": "constant", "radiance": 1.0}})
print(json.dumps(np.array(mi.render(scene)).mean(axis=2).tolist()))
"""


def test_scalar_variant_renders_film_irradiance():
    """The fallback variant (no JIT): the same plugin, checked against the float64 tracer."""
    import json
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", _SCALAR_SCRIPT],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    img = np.array(json.loads(out.stdout.strip().splitlines()[-1]))
    pitch_mm = 8.0 / np.hypot(8, 8)
    centre = [(i, j) for i in range(2, 6) for j in range(2, 6)]
    radii = [np.hypot(i + 0.5 - 4, j + 0.5 - 4) * pitch_mm for i, j in centre]
    lens = Lens.builtin("dgauss50").scaled_to(8.0).with_f_number(4.0)
    expected = lens.irradiance_ratio(radii).mean()
    rendered = np.mean([img[i, j] for i, j in centre])
    assert rendered == pytest.approx(expected, rel=0.03)


def test_a_bad_lens_in_a_scene_names_itself(mitsuba, tmp_path):
    with pytest.raises(RuntimeError, match="'nope' is neither a built-in lens"):
        mitsuba.load_dict({"type": "scene", "sensor": {"type": "realisticlens", "lens": "nope"}})
    bad = tmp_path / "bad.lens"
    bad.write_text("0 1 0 5 -\n50 -2 1.5 10 -\n-50 40 1 10 -\n")
    with pytest.raises(RuntimeError, match="surface 1: negative thickness"):
        mitsuba.load_dict({"type": "scene", "sensor": {"type": "realisticlens", "lens": str(bad)}})


_NO_VARIANT_SCRIPT = """
import mitsuba as mi
import pecs
assert mi.variant() is None, "importing pecs must not choose a Mitsuba variant"
"""
_VARIANT_FIRST_SCRIPT = """
import mitsuba as mi
mi.set_variant("scalar_rgb")
import pecs  # registers "realisticlens" for the variant already chosen
scene = mi.load_dict({"type": "scene", "sensor": {"type": "realisticlens", "lens": "pecs4",
    "film": {"type": "hdrfilm", "width": 4, "height": 4}}})
print(type(scene.sensors()[0]).__name__)
"""


def test_importing_pecs_registers_the_sensor_for_a_chosen_variant():
    import subprocess
    import sys

    for script in (_NO_VARIANT_SCRIPT, _VARIANT_FIRST_SCRIPT):
        out = subprocess.run(
            [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
        )
        assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("RealisticLensSensor")
