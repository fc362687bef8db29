"""Traced lens ghosts against a paraxial (2x2 matrix) ghost analysis and closed-form energies."""

from __future__ import annotations

import numpy as np
import pytest
from pecs.lens import Lens
from pecs.lens.coating import Coating
from pecs.lens.ghosts import (
    CoverGlass,
    GhostOptions,
    GhostSystem,
    GhostTracer,
    PointSource,
)
from pecs.lens.paraxial_ghosts import ghost_table, paraxial_ghost

LAMBDA0_NM = 550.0
FILM_HALF_DIAGONAL_MM = 4.0  # DAVIS346: 8 mm diagonal


def _centroid_and_radius(rays, p: int) -> tuple[np.ndarray, float]:
    """Flux-weighted centre and the radius of the uniform disk with the same second moment
    (r = sqrt(2 <rho^2>))."""
    alive = rays.alive[p, 0]
    pos, w = rays.film_mm[p, 0][alive], rays.flux_mm2[p, 0][alive]
    centre = (pos * w[:, None]).sum(axis=0) / w.sum()
    rho2 = ((pos - centre) ** 2).sum(axis=1)
    return centre, float(np.sqrt(2 * (rho2 * w).sum() / w.sum()))


def test_path_count_is_n_choose_2_of_the_reflectors() -> None:
    lens = Lens.builtin("dgauss50")  # 11 surfaces, one the stop: 10 reflectors
    assert len(GhostSystem(lens).paths()) == 45
    plate = GhostOptions(cover_glass=CoverGlass())
    assert len(GhostSystem(lens, plate).paths()) == 66
    die = GhostOptions(cover_glass=CoverGlass(sensor_reflectance=0.1))
    assert len(GhostSystem(lens, die).paths()) == 78
    assert all(
        p.first != lens.stop_index and p.second != lens.stop_index
        for p in GhostSystem(lens).paths()
    )


@pytest.mark.parametrize("field_deg", [1.0, 2.0, 3.0])
def test_ghost_centres_and_sizes_match_the_paraxial_analysis(field_deg: float) -> None:
    # dgauss50 stopped to f/32 so that first-order optics holds, every aperture but the stop
    # opened (the paraxial ghost is the image of the stop alone), one wavelength (550 nm).
    lens = Lens.builtin("dgauss50").with_f_number(32.0)
    system = GhostSystem(lens)
    system.semi_mm = [s if k == lens.stop_index else np.inf for k, s in enumerate(system.semi_mm)]
    tracer = GhostTracer(system)
    rays = tracer.trace(PointSource.at_field_angle(field_deg), [LAMBDA0_NM], rays_per_side=64)
    slope = -np.tan(np.radians(field_deg))  # the source's rays travel towards -x
    compared = 0
    for p, path in enumerate(tracer.paths):
        paraxial = paraxial_ghost(system, path, LAMBDA0_NM)
        if paraxial.stop_crossings != 1:
            continue  # the stop crossed three times: the bundle is no single stop image
        if paraxial.energy < 1e-8 or paraxial.radius_mm > FILM_HALF_DIAGONAL_MM:
            # Ghosts off a cemented surface (its ideal film reflects ~1e-12 near normal
            # incidence, so the few steep rays carry the flux) and veils wider than the film
            # (surface 1 onto 0: 6 mm, 2-7 % from first order) are not first-order objects.
            continue
        centre, radius = _centroid_and_radius(rays, p)
        expected_centre = paraxial.centre_per_slope_mm * slope
        scale = max(abs(expected_centre), paraxial.radius_mm)
        assert centre[0] == pytest.approx(expected_centre, abs=0.02 * scale), path
        assert abs(centre[1]) < 1e-9 * scale + 1e-12
        assert radius == pytest.approx(paraxial.radius_mm, rel=0.02), path
        compared += 1
    assert compared >= 10


def _singlet() -> Lens:
    """A stop 4 mm wide 2 mm in front of an equiconvex singlet (n 1.5168, no dispersion)."""
    return Lens.from_text("0 2 0 4 -\n50 5 1.5168 20 -\n-50 46 1 20 -\n", "singlet")


@pytest.mark.parametrize("coating", [Coating(), None])
def test_ghost_energy_is_r_squared_of_the_two_surfaces(coating: Coating | None) -> None:
    lens = _singlet()
    system = GhostSystem(lens, GhostOptions(coatings=coating))
    tracer = GhostTracer(system)
    assert [(p.first, p.second) for p in tracer.paths] == [(2, 1)]
    n0, n2 = 1.0, 1.5168
    if coating is None:
        r = ((n2 - n0) / (n2 + n0)) ** 2
    else:
        n1 = 1.38  # MgF2: sqrt(1.5168) < 1.38
        r = ((n0 * n2 - n1**2) / (n0 * n2 + n1**2)) ** 2
    # Entrance pupil = the stop (in front of everything): pi 2^2 mm^2 of unit irradiance; in
    # through surface 1 (1 - R), back off 2 (R), forward off 1 (R), out through 2 (1 - R).
    expected = np.pi * 2.0**2 * (1 - r) * r * r * (1 - r)
    rays = tracer.trace(PointSource.at_field_angle(0.0), [LAMBDA0_NM], rays_per_side=96)
    assert rays.flux_mm2.sum() == pytest.approx(expected, rel=0.05)
    # The rendered image holds the same energy (film large enough for the whole ghost).
    radius = paraxial_ghost(system, tracer.paths[0], LAMBDA0_NM).radius_mm
    pitch = 0.05
    side = int(2.6 * radius / pitch)
    image = tracer.image(PointSource.at_field_angle(0.0), [LAMBDA0_NM], side, side, pitch, 96)
    assert image.sum() * pitch**2 == pytest.approx(expected, rel=0.05)
    # And the table's energy is R^2 at the design wavelength.
    assert ghost_table(lens, GhostOptions(coatings=coating))[0].energy == pytest.approx(r * r)


def test_ghost_image_lies_where_the_rays_land_and_is_deterministic() -> None:
    lens = _singlet()
    tracer = GhostTracer(GhostSystem(lens))
    source = PointSource.at_field_angle(2.0)
    system = GhostSystem(lens)
    paraxial = paraxial_ghost(system, tracer.paths[0], LAMBDA0_NM)
    expected = paraxial.centre_per_slope_mm * -np.tan(np.radians(2.0))
    pitch = 0.1  # a film that holds the whole ghost
    w = h = int(2.4 * (paraxial.radius_mm + abs(expected)) / pitch)
    a = tracer.image(source, [LAMBDA0_NM], w, h, pitch, 48)
    b = tracer.image(source, [LAMBDA0_NM], w, h, pitch, 48)
    assert np.array_equal(a, b)
    x_mm = ((np.arange(w) + 0.5) - w / 2) * pitch
    centre_x = (a[0].sum(axis=0) * x_mm).sum() / a[0].sum()
    assert centre_x == pytest.approx(expected, abs=0.02 * max(abs(expected), paraxial.radius_mm))


def test_cover_glass_and_die_ghosts() -> None:
    lens = Lens.builtin("dgauss50").with_f_number(8.0)
    options = GhostOptions(cover_glass=CoverGlass(sensor_reflectance=0.2))
    system = GhostSystem(lens, options)
    names = system.names
    table = {(g.names[0], g.names[1]): g for g in ghost_table(lens, options)}
    # Die then the plate's back face: R_die R_plate.
    plate_r = ((1.52 - 1.38**2) / (1.52 + 1.38**2)) ** 2
    assert table[("sensor", "cover glass back")].energy == pytest.approx(0.2 * plate_r)
    # The die-plate ghost: the cone converging on the die (focused without the plate, so its
    # focus lies t (1 - 1/n) behind the die, plus the focal shift from the d line to 550 nm) reflects, crosses the gap twice: blur radius =
    # slope * (2 gap - t (1 - 1/n)), the slope the exit pupil's radius over its distance.
    xp_z, xp_d = lens.exit_pupil(LAMBDA0_NM)
    slope = xp_d / 2 / (lens.geometry.film_z_mm - xp_z)
    behind_mm = 0.5 * (1 - 1 / 1.52) + lens.bfl_mm(LAMBDA0_NM) - lens.film_distance_mm
    by_hand = slope * (2 * 0.5 - behind_mm)  # (focused at the d line: 550 nm falls behind)
    paraxial = table[("sensor", "cover glass back")]
    assert paraxial.radius_mm == pytest.approx(by_hand, rel=0.01)
    tracer = GhostTracer(system)
    rays = tracer.trace(PointSource.at_field_angle(0.0), [LAMBDA0_NM], 48)
    p = [(names[q.first], names[q.second]) for q in tracer.paths].index(
        ("sensor", "cover glass back")
    )
    _, radius = _centroid_and_radius(rays, p)
    assert radius == pytest.approx(paraxial.radius_mm, rel=0.05)


def test_bad_options_are_named() -> None:
    lens = Lens.builtin("dgauss50")
    with pytest.raises(ValueError, match="coatings: 3 given"):
        GhostSystem(lens, GhostOptions(coatings=(None, None, None)))
    with pytest.raises(ValueError, match="cover_glass: the plate"):
        GhostSystem(lens.with_film_distance(0.5), GhostOptions(cover_glass=CoverGlass()))
    with pytest.raises(ValueError, match="sensor_reflectance"):
        CoverGlass(sensor_reflectance=1.5)
    with pytest.raises(ValueError, match="rays_per_side"):
        GhostOptions(rays_per_side=2)


# -- in the renderer ----------------------------------------------------------------------


def _mitsuba():
    pytest.importorskip("mitsuba")
    from pecs._mitsuba import mitsuba

    return mitsuba()


def test_a_point_light_gives_its_irradiance_at_the_lens_in_qe_film_units() -> None:
    from pecs.render.lens_ghosts import LensGhosts, ghost_settings, realistic_lens
    from pecs.render.quantum_efficiency import preset_qe
    from pecs.render.spectrum import photons_per_joule

    mi = _mitsuba()
    intensity = {"type": "uniform", "value": 2.0}  # W / sr / nm, flat (a float is D65)
    scene = mi.load_dict(
        {
            "type": "scene",
            "lamp": {"type": "point", "position": [0.3, 0.0, 5.0], "intensity": intensity},
            "sky": {"type": "constant", "radiance": 1.0},  # not a ghost source
        }
    )
    lens = realistic_lens("dgauss50", 12.0, 4.0, None)
    qe = preset_qe("davis346")
    ghosts = LensGhosts(mi, scene, lens, 64, 48, 0.1, qe, None, ghost_settings({}, lens, "x"))
    assert len(ghosts.emitters) == 1 and len(ghosts.skipped) == 1
    [(source, weights)] = ghosts.sources(np.eye(4))
    film_z = lens.geometry.film_z_mm
    # Camera space (film at the origin, looking along +z) to lens space: z_lens = film - z.
    assert source.position_mm == pytest.approx((300.0, 0.0, film_z - 5000.0))
    r_m = np.hypot(0.3, 5.0 - film_z * 1e-3)
    grid = np.arange(qe.wavelength_nm[0], qe.wavelength_nm[-1], 0.5)
    electrons = np.sum(qe(grid) * photons_per_joule(grid)) * 0.5 * 2.0 / r_m**2
    assert weights.sum() == pytest.approx(electrons, rel=0.01)
    # Hidden behind a wall: no source.
    wall = mi.load_dict(
        {
            "type": "scene",
            "lamp": {"type": "point", "position": [0.3, 0.0, 5.0], "intensity": intensity},
            "wall": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 3])},
        }
    )
    hidden = LensGhosts(mi, wall, lens, 64, 48, 0.1, qe, None, ghost_settings({}, lens, "x"))
    assert hidden.sources(np.eye(4)) == []


def _headlight(tmp_path, ghosts: bool, moving: bool = True):
    import dataclasses
    from pathlib import Path

    from pecs.config import NOISE_OFF
    from pecs.render import Simulation, load_scene

    _mitsuba()
    path = Path(__file__).resolve().parents[1] / "scenes" / "headlight" / "scene.toml"
    spec = load_scene(path)
    optics = dataclasses.replace(spec.optics, ghosts={} if ghosts else None)
    spec = dataclasses.replace(spec, optics=optics, objects=spec.objects if moving else {})
    scale = 346 / 64
    sensor = {"width": 64, "height": 48, "pixel_pitch_um": 18.5 * scale, **NOISE_OFF}
    return Simulation(spec, duration_s=0.006, spp=1, rate_hz=1000.0, sensor=sensor)


def test_a_static_scene_with_ghosts_gives_identical_frames_and_no_events(tmp_path) -> None:
    import pyarrow as pa

    sim = _headlight(tmp_path, ghosts=True, moving=False)
    frames = [f.photocurrent_pa for f in sim.frames()]
    assert all(np.array_equal(frames[0], f) for f in frames[1:])
    plain = [f.photocurrent_pa for f in _headlight(tmp_path, False, False).frames()]
    assert np.any(frames[0] > plain[0])  # the ghosts are there
    events = pa.Table.from_batches(list(_headlight(tmp_path, True, False).event_batches()))
    assert events.num_rows == 0


def test_ghost_light_is_where_the_lamps_are_not() -> None:
    import pyarrow as pa

    sim = _headlight(None, ghosts=True)
    with_ghosts = next(iter(sim.frames())).photocurrent_pa
    without = next(iter(_headlight(None, ghosts=False).frames())).photocurrent_pa
    added = with_ghosts - without
    # Pixels that Mitsuba leaves dark (nothing lit there) receive ghost light.
    dark = without <= np.percentile(without, 50)
    assert np.count_nonzero(added[dark] > 0) > 0.05 * dark.sum()
    # ... far below the lamps' own images (a ghost is ~1e-4 of the lamp).
    assert added.max() < 0.05 * without.max()
    events = pa.Table.from_batches(list(sim.event_batches()))
    assert events.num_rows > 0


def test_ghosts_need_the_realistic_lens(tmp_path) -> None:
    from pecs.render import load_scene

    (tmp_path / "s.xml").write_text('<scene version="3.0.0"/>')
    (tmp_path / "s.toml").write_text(
        '[scene]\nmitsuba = "s.xml"\n[time]\nduration_s = 0.01\nrate_hz = 100\n[sensor]\npreset = "davis346"\n'
        '[optics]\nmodel = "pinhole"\nfov_deg = 40\nghosts = true\n'
    )
    with pytest.raises(ValueError, match="optics.ghosts: lens ghosts need a realistic lens"):
        load_scene(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text(
        '[scene]\nmitsuba = "s.xml"\n[time]\nduration_s = 0.01\nrate_hz = 100\n[sensor]\npreset = "davis346"\n'
        '[optics]\nlens = "dgauss50"\nefl_mm = 12\nfocus_m = 5\n'
        "ghosts = { cover_glass = { thickness_mm = -1 } }\n"
    )
    with pytest.raises(ValueError, match="optics.ghosts: cover_glass thickness_mm"):
        load_scene(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text(
        '[scene]\nmitsuba = "s.xml"\n[time]\nduration_s = 0.01\nrate_hz = 100\n[sensor]\npreset = "davis346"\n'
        '[optics]\nlens = "dgauss50"\nefl_mm = 12\nfocus_m = 5\nghosts = { rays = 3 }\n'
    )
    with pytest.raises(ValueError, match=r"optics.ghosts.rays: unknown key"):
        load_scene(tmp_path / "s.toml")


def test_cli_lists_every_ghost_brightest_first(capsys: pytest.CaptureFixture[str]) -> None:
    from pecs.cli import main

    assert main(["lens", "ghosts", "dgauss50", "--cover-glass"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("dgauss50: 66 two-reflection ghosts")
    energies = [float(line.split()[-4]) for line in lines[2:68]]
    assert energies == sorted(energies, reverse=True) and len(energies) == 66


def test_headlight_scene_files_are_what_make_py_writes(tmp_path) -> None:
    import subprocess
    import sys
    from pathlib import Path

    library = Path(__file__).resolve().parents[1] / "scenes"
    folder = library / "headlight"
    copy = tmp_path / "headlight"
    copy.mkdir()
    (copy / "make.py").write_text((folder / "make.py").read_text())
    (tmp_path / "scene_writing.py").write_text((library / "scene_writing.py").read_text())
    subprocess.run([sys.executable, str(copy / "make.py")], check=True, capture_output=True)
    for name in ("scene.xml", "scene.toml"):
        assert (copy / name).read_text() == (folder / name).read_text(), name


def test_dispersion_traces_each_band_and_matches_one_geometry_without_dispersive_glass() -> None:
    lens = _singlet()  # n 1.5168 at every wavelength: the paths cannot differ
    source = PointSource.at_field_angle(1.5)
    bands = [450.0, 600.0, 850.0]
    one = GhostTracer(GhostSystem(lens)).image(source, bands, 120, 120, 0.1, 32)
    each = GhostTracer(GhostSystem(lens, GhostOptions(dispersion=True))).image(
        source, bands, 120, 120, 0.1, 32
    )
    np.testing.assert_allclose(each, one, rtol=1e-9, atol=1e-15)
    # Dispersive glass: the bands' ghosts differ in place, not only in brightness.
    dgauss = Lens.builtin("dgauss50").scaled_to(12.0)
    tracer = GhostTracer(GhostSystem(dgauss, GhostOptions(dispersion=True)))
    rays = tracer.trace(source, [450.0, 850.0])
    moved = np.abs(rays.film_mm[:, 0] - rays.film_mm[:, 1])[rays.alive[:, 0] & rays.alive[:, 1]]
    assert moved.max() > 1e-3


def test_per_surface_coatings_from_a_scene_file() -> None:
    from pecs.render.lens_ghosts import ghost_settings

    lens = Lens.builtin("dgauss50")
    count = len(lens.surfaces)
    coatings = ["none"] * count
    coatings[0] = {"design_wavelength_nm": 500}
    settings = ghost_settings({"coating": coatings}, lens, "optics.ghosts")
    assert settings.options.coatings[0] == Coating(500.0)
    assert settings.options.coatings[1] is None
    bare = GhostSystem(lens, settings.options).normal_reflectance()
    assert bare[1] == pytest.approx(((1.67 - 1) / (1.67 + 1)) ** 2, rel=0.01)  # N-BAF10, bare
    with pytest.raises(ValueError, match=r"optics.ghosts.coating: 2 coatings for the 11"):
        ghost_settings({"coating": ["none", "none"]}, lens, "optics.ghosts")


def test_colour_filter_array_frames_get_ghosts_too() -> None:
    import dataclasses
    from pathlib import Path

    from pecs.config import NOISE_OFF
    from pecs.render import Simulation, load_scene

    _mitsuba()
    path = Path(__file__).resolve().parents[1] / "scenes" / "headlight" / "scene.toml"
    spec = load_scene(path)
    sensor = {"width": 64, "height": 48, "pixel_pitch_um": 18.5 * 346 / 64, **NOISE_OFF}
    frames = {}
    for ghosts in (True, False):
        optics = dataclasses.replace(spec.optics, ghosts={} if ghosts else None)
        sim = Simulation(
            dataclasses.replace(spec, optics=optics, objects={}),
            duration_s=0.002,
            spp=1,
            rate_hz=1000.0,
            preset="color_davis346",
            sensor=sensor,
        )
        frames[ghosts] = [f.photocurrent_pa for f in sim.frames()]
    assert np.array_equal(frames[True][0], frames[True][-1])
    added = frames[True][0] - frames[False][0]
    assert np.all(added >= -1e-6 * frames[False][0].max()) and np.any(added > 0)
    # Behind its filter each pixel gets its own share: the 2 x 2 cell's pixels differ.
    cell = added[::2, ::2].sum(), added[::2, 1::2].sum(), added[1::2, ::2].sum()
    assert len({round(float(v), 12) for v in cell}) > 1


def test_an_area_light_split_into_points_keeps_its_irradiance() -> None:
    from pecs.render.lens_ghosts import LensGhosts, ghost_settings, realistic_lens
    from pecs.render.quantum_efficiency import preset_qe
    from pecs.render.spectrum import photons_per_joule

    mi = _mitsuba()
    radiance = {"type": "uniform", "value": 3.0}
    scene = mi.load_dict(
        {
            "type": "scene",
            "bulb": {
                "type": "sphere",
                "center": [0.2, 0.1, 4.0],
                "radius": 0.1,
                "emitter": {"type": "area", "radiance": radiance},
            },
        }
    )
    lens = realistic_lens("dgauss50", 12.0, 4.0, None)
    qe = preset_qe("davis346")
    totals = []
    for samples in (1, 3):
        settings = ghost_settings({"area_samples": samples}, lens, "x")
        ghosts = LensGhosts(mi, scene, lens, 32, 24, 0.2, qe, None, settings)
        found = ghosts.sources(np.eye(4))
        assert len(found) == samples**2
        totals.append(sum(w.sum() for _, w in found))
    # A sphere of radiance L seen from distance r: E = L pi (R / r)^2 (its solid angle, exactly
    # L pi sin^2 of the cone's half angle).
    film_z = lens.geometry.film_z_mm * 1e-3
    distance = np.linalg.norm(np.array([0.2, 0.1, 4.0]) - [0, 0, film_z])
    irradiance = 3.0 * np.pi * (0.1 / distance) ** 2
    grid = np.arange(qe.wavelength_nm[0], qe.wavelength_nm[-1], 0.5)
    electrons = np.sum(qe(grid) * photons_per_joule(grid)) * 0.5 * irradiance
    assert totals[0] == pytest.approx(electrons, rel=0.01)
    assert totals[1] == pytest.approx(totals[0], rel=1e-3)
