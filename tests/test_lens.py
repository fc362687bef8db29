"""Optics of pecs.lens checked against independent numbers: optiland (another optics library),
catalogue glass data, thin-lens and cos^4 formulas."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pecs.lens import Glass, Lens
from pecs.lens.glass import C_LINE_NM, D_LINE_NM, F_LINE_NM

BUILTINS = ["dgauss50", "wide22", "telephoto250", "fisheye10", "pecs4"]


def _optiland(lens: Lens):
    """The same prescription in optiland: ideal materials with our d-line indices, the stop
    sized by its own diameter, object at infinity."""
    from optiland.materials import IdealMaterial
    from optiland.optic import Optic

    n = lens.media_indices(D_LINE_NM)
    optic = Optic()
    optic.add_surface(index=0, radius=np.inf, thickness=np.inf)
    for i, s in enumerate(lens.surfaces):
        material = "air" if n[i + 1] == 1.0 else IdealMaterial(float(n[i + 1]))
        optic.add_surface(
            index=i + 1,
            radius=np.inf if s.radius_mm == 0 else s.radius_mm,
            thickness=s.thickness_mm,
            material=material,
            is_stop=s.is_stop,
        )
    optic.add_surface(index=len(lens.surfaces) + 1)
    optic.set_aperture(
        aperture_type="float_by_stop_size", value=lens.surfaces[lens.stop_index].aperture_mm
    )
    optic.set_field_type(field_type="angle")
    optic.add_field(y=0)
    optic.add_wavelength(value=D_LINE_NM * 1e-3, is_primary=True)
    return optic


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_efl_and_f_number_match_optiland(name):
    pytest.importorskip("optiland")
    lens = Lens.builtin(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic = _optiland(lens)
        efl = float(np.ravel(optic.paraxial.f2())[0])
        fno = float(np.ravel(optic.paraxial.FNO())[0])
        epd = float(np.ravel(optic.paraxial.EPD())[0])
    assert lens.efl_mm() == pytest.approx(efl, rel=5e-3)
    assert lens.f_number() == pytest.approx(fno, rel=5e-3)
    assert lens.entrance_pupil()[1] == pytest.approx(epd, rel=5e-3)


@pytest.mark.parametrize("name", BUILTINS)
def test_real_rays_match_optiland(name):
    # Finite rays through every surface, compared where they land on the film.
    pytest.importorskip("optiland")
    from optiland.rays import RealRays
    from pecs.lens.raytrace import propagate_to_z

    lens = Lens.builtin(name)
    rng = np.random.default_rng(3)
    count = 64
    # Rays through the paraxial entrance pupil, at field angles up to 15 % of the focal length.
    ep_z, ep_d = lens.entrance_pupil()
    theta = np.radians(
        rng.uniform(-1, 1, count) * lens.chief_ray_angle_deg(0.15 * lens.efl_mm())[0]
    )
    direction = np.column_stack([np.zeros(count), np.sin(theta), np.cos(theta)])
    on_pupil = np.column_stack([rng.uniform(-0.3, 0.3, (count, 2)) * ep_d, np.full(count, ep_z)])
    start = on_pupil - direction * ((ep_z + 1.0) / direction[:, 2])[:, None]
    ours = lens.trace_from_scene(start, direction)
    assert ours.alive.sum() > 10
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        optic = _optiland(lens)
        rays = RealRays(*start.T, *direction.T, np.ones(count), np.full(count, D_LINE_NM * 1e-3))
        optic.surface_group.trace(rays, skip=1)
        theirs = np.column_stack([np.ravel(rays.x), np.ravel(rays.y)])
    landed = propagate_to_z(ours, lens.geometry.film_z_mm)
    np.testing.assert_allclose(landed[ours.alive], theirs[ours.alive], atol=1e-7)


def test_abbe_model_reproduces_n_d_and_v_d():
    glass = Glass.from_column(1.67, "47.1")
    n_d, n_f, n_c = glass.index([D_LINE_NM, F_LINE_NM, C_LINE_NM])
    assert n_d == pytest.approx(1.67, abs=1e-12)
    assert (n_d - 1) / (n_f - n_c) == pytest.approx(47.1, rel=1e-12)


def _singlet(glass: str = "N-BK7", radius: float = 100.0, stop_mm: float = 10.0) -> Lens:
    text = f"""
        0        0.0   0     {stop_mm}  -
        {radius}     3.0   1.5168  20  {glass}
        {-radius}    95.0  1       20  -
    """
    return Lens.from_text(text, name="singlet")


def test_bk7_singlet_focal_shift_matches_thin_lens():
    # Thin lens: f(lambda) = 1 / ((n - 1) (2 / R)); the F-C focal shift is f / V_d.
    lens = _singlet()
    shift = lens.bfl_mm(C_LINE_NM) - lens.bfl_mm(F_LINE_NM)
    f = lens.efl_mm()
    assert shift == pytest.approx(f / 64.17, rel=0.03)
    assert f == pytest.approx(100.0 / (2 * 0.5168), rel=0.02)


def test_focusing_follows_the_gaussian_lens_formula():
    lens = _singlet()
    for focus_m in (0.5, 2.0):
        film = lens.focused(focus_m)
        # The singlet is nearly thin: object and image distances from its centre.
        s_image = film.film_distance_mm + 1.5
        s_object = focus_m * 1e3 - s_image
        assert 1 / s_image + 1 / s_object == pytest.approx(1 / lens.efl_mm(), rel=0.01)
        # Real rays from the focused point converge: the spot is tighter than at other focus.
        sharp = (
            film.spot_diagram(0.0, rays_per_side=24, object_distance_m=focus_m).std(axis=0).sum()
        )
        blurred = (
            film.spot_diagram(0.0, rays_per_side=24, object_distance_m=focus_m * 2)
            .std(axis=0)
            .sum()
        )
        assert sharp < 0.3 * blurred


def test_centre_irradiance_is_pi_over_4n2():
    # E / L = pi sin^2(theta') = pi / (4 N^2) for a lens obeying the sine condition.
    lens = Lens.builtin("dgauss50").scaled_to(8.0).with_f_number(4.0)
    assert lens.irradiance_ratio(0.0)[0] == pytest.approx(np.pi / (4 * 16), rel=0.01)


def test_relative_illumination_of_a_small_stop_is_cos4():
    # A small hole 20 mm from the film: E(r) / E(0) = cos^4(atan(r / 20)).
    lens = Lens.from_text("0 20 0 0.2 -\n", name="pinhole")
    radii = np.array([2.0, 6.0, 10.0])
    expected = np.cos(np.arctan(radii / 20.0)) ** 4
    assert lens.relative_illumination(radii) == pytest.approx(expected, rel=0.005)


def test_scaling_keeps_f_number_and_scales_every_length():
    lens = Lens.builtin("dgauss50")
    small = lens.scaled_to(8.0)
    assert small.efl_mm() == pytest.approx(8.0, rel=1e-12)
    assert small.f_number() == pytest.approx(lens.f_number(), rel=1e-12)
    factor = 8.0 / lens.efl_mm()
    assert small.bfl_mm() == pytest.approx(lens.bfl_mm() * factor, rel=1e-12)
    assert small.surfaces[3].aperture_mm == pytest.approx(lens.surfaces[3].aperture_mm * factor)


def test_field_of_view_of_a_distortion_free_lens_is_the_pinhole_one():
    # A long, slow lens is nearly distortion-free: FOV = 2 atan(w / 2f).
    lens = Lens.builtin("telephoto250").scaled_to(50.0)
    fov = lens.field_of_view_deg((6.4, 4.8))
    assert fov["horizontal"] == pytest.approx(2 * np.degrees(np.arctan(3.2 / 50.0)), rel=0.005)
    assert abs(lens.distortion_percent(2.0)[0]) < 0.2


def test_fisheye_has_strong_barrel_distortion():
    lens = Lens.builtin("fisheye10")
    d = lens.distortion_percent([2.0, 6.0])
    assert d[0] < 0 and d[1] < d[0] - 5  # grows with field, image compressed


def test_prescription_round_trips_through_text():
    lens = Lens.builtin("wide22")
    again = Lens.from_text(lens.to_text())
    assert again.efl_mm(F_LINE_NM) == pytest.approx(lens.efl_mm(F_LINE_NM), rel=1e-12)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("0 1 0 5 -\n50 -2 1.5 10 -\n-50 40 1 10 -\n", "surface 1: negative thickness"),
        (
            "0 1 0 5 -\n4 2 1.5 10 -\n-50 40 1 10 -\n",
            "surface 1: aperture diameter 10.0 mm is larger",
        ),
        ("50 2 1.5 10 -\n-50 40 1 10 -\n", "no aperture stop"),
        ("0 1 0 0 -\n50 2 1.5 10 -\n-50 40 1 10 -\n", "surface 0: aperture diameter must be > 0"),
        ("0 1 0 5 -\n10 0.5 1.5 10 -\n-10 40 1 10 -\n", "surfaces 1 and 2 cross"),
        ("0 1 0 5 -\n50 2 1.5 10 NOGLASS\n-50 40 1 10 -\n", "surface 1: unknown glass"),
        ("0 1 0 5\n50 2 1.5\n", "line 2, surface 1: expected 4 or 5 columns"),
    ],
)
def test_bad_prescriptions_name_the_surface(text, message):
    with pytest.raises(ValueError, match=message):
        Lens.from_text(text)


def test_missing_file_and_unknown_builtin():
    with pytest.raises(FileNotFoundError):
        Lens.from_file("no/such/lens.lens")
    with pytest.raises(ValueError, match="unknown built-in lens"):
        Lens.builtin("nope")


def test_cli_info_prints_first_order_numbers(capsys, tmp_path):
    import argparse

    from pecs.cli import lens as cli

    parser = argparse.ArgumentParser()
    cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["lens", "info", "dgauss50", "--efl-mm", "8", "--sensor", "imx636"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "EFL                8.0000 mm" in out and "imx636" in out
    png = tmp_path / "lens.png"
    args = parser.parse_args(["lens", "plot", "pecs4", "-o", str(png)])
    assert args.func(args) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("name", ["dgauss50", "fisheye10", "wide22"])
def test_exit_pupil_regions_hold_every_passing_ray(name):
    # Brute force: random rays from random film points towards a wide square on the rear plane;
    # every one that passes must start inside its bin's sampling region (box and ellipse), else
    # the camera would miss light.
    lens = Lens.builtin(name).scaled_to(8.0)
    r_max = 4.0
    bounds = lens.exit_pupil_bounds(r_max, (360.0, 830.0), bins=16)
    rng = np.random.default_rng(7)
    count = 200_000
    film_r = rng.uniform(0, r_max, count)
    wavelength = rng.uniform(360.0, 830.0, count)
    half = 1.5 * lens.surfaces[-1].aperture_mm / 2
    target = np.column_stack(
        [rng.uniform(-half, half, (count, 2)), np.full(count, bounds.rear_z_mm)]
    )
    start = np.column_stack([film_r, np.zeros(count), np.full(count, lens.geometry.film_z_mm)])
    from pecs.lens.raytrace import trace

    # As the renderer traces: past a glass's catalogue range, the index at the range's end.
    media = lens.media_indices(wavelength, clamp=True)
    alive = trace(lens.geometry, media, start, target - start, False).alive
    assert alive.sum() > 1000
    b = bounds.bin_of(film_r[alive])
    x = target[alive, 0] - bounds.shift * film_r[alive]
    y = target[alive, 1]
    x0, x1, y0, y1 = bounds.boxes_mm[b].T
    assert ((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)).all()
    scale = bounds.ellipse_scale[b]
    rho = np.hypot(
        (x - 0.5 * (x0 + x1)) / (0.5 * (x1 - x0)), (y - 0.5 * (y0 + y1)) / (0.5 * (y1 - y0))
    )
    assert (rho[scale > 0] <= scale[scale > 0]).all()


def test_fisheye_covers_its_published_field():
    # Smith, Modern Lens Design p. 164: the 16 mm f/4 fisheye covers 155.9 deg on the 24 x 36 mm
    # frame; scaled to our focal length, the frame scales with it.
    lens = Lens.builtin("fisheye10")
    scale = lens.efl_mm() / 16.0
    fov = lens.field_of_view_deg((36.0 * scale, 24.0 * scale))
    assert fov["diagonal"] == pytest.approx(155.9, rel=0.015)


def test_f_number_and_focus_limits():
    lens = Lens.builtin("dgauss50")
    widest = lens.f_number()
    with pytest.raises(ValueError, match="faster than this lens's widest aperture"):
        lens.with_f_number(1.4)
    with pytest.warns(RuntimeWarning, match="using f/2.03"):
        assert lens.with_f_number(1.4, clamp=True).f_number() == pytest.approx(widest)
    # Closing the stop scales the entrance pupil: N = f / D exactly.
    assert lens.with_f_number(5.6).f_number() == pytest.approx(5.6, rel=1e-12)
    with pytest.raises(ValueError, match="closest focus"):
        lens.focused(0.1)
