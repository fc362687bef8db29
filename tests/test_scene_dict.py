"""Scenes built in Python (Mitsuba's dict format): the same images as the equivalent XML."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pecs.render import Simulation
from pecs.render.animation import Track
from pecs.render.scene_file import load_scene

W, H = 48, 32
BOARD_XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/></transform>
  </sensor>
  <shape type="rectangle" id="board">
    <transform name="to_world"><scale value="0.5"/></transform>
    <bsdf type="diffuse">
      <texture type="checkerboard" name="reflectance">
        <float name="color0" value="0.1"/>
        <float name="color1" value="0.8"/>
        <transform name="to_uv"><scale x="4" y="4"/></transform>
      </texture>
    </bsdf>
  </shape>
  <emitter type="point" id="lamp">
    <point name="position" value="0.3, 0.2, 1.0"/>
    <spectrum name="intensity" value="400:0.5, 700:1.5"/>
  </emitter>
  <emitter type="constant" id="sky"><spectrum name="radiance" value="400:0.01, 1000:0.03"/></emitter>
</scene>
"""
MOVE = [
    {"t_s": 0.0, "position": [0.0, 0.0, 0.0]},
    {"t_s": 0.02, "position": [0.05, 0.0, 0.0]},
]
SETTINGS: dict[str, Any] = {
    "time": {"duration_s": 0.02, "rate_hz": 50},
    "sensor": {
        "preset": "davis346",
        "overrides": {"width": W, "height": H, "pixel_pitch_um": 40.0},
    },
    "optics": {"model": "pinhole", "efl_mm": 8.0},
    "render": {"spp": 4, "max_depth": 3, "seed": 3},
    "objects": [{"id": "board", "keyframes": MOVE}],
}


def board_dict() -> dict[str, Any]:
    """BOARD_XML, written in Mitsuba's dict format."""
    from pecs._mitsuba import mitsuba

    mi = mitsuba()
    transform = mi.ScalarTransform4f()
    return {
        "type": "scene",
        "camera": {
            "type": "perspective",
            "fov": 40.0,
            "to_world": transform.look_at(origin=[0, 0, 2], target=[0, 0, 0], up=[0, 1, 0]),
        },
        "board": {
            "type": "rectangle",
            "to_world": transform.scale([0.5, 0.5, 0.5]),
            "bsdf": {
                "type": "diffuse",
                "reflectance": {
                    "type": "checkerboard",
                    "color0": 0.1,
                    "color1": 0.8,
                    "to_uv": transform.scale([4, 4, 1]),
                },
            },
        },
        "lamp": {
            "type": "point",
            "position": [0.3, 0.2, 1.0],
            "intensity": {"type": "spectrum", "value": [(400.0, 0.5), (700.0, 1.5)]},
        },
        "sky": {
            "type": "constant",
            "radiance": {"type": "spectrum", "value": [(400.0, 0.01), (1000.0, 0.03)]},
        },
    }


def xml_scene(folder: Path) -> Path:
    (folder / "board.xml").write_text(BOARD_XML)
    toml = (
        '[scene]\nmitsuba = "board.xml"\n[time]\nduration_s = 0.02\nrate_hz = 50\n'
        f'[sensor]\npreset = "davis346"\noverrides = {{ width = {W}, height = {H}, '
        "pixel_pitch_um = 40.0 }\n"
        '[optics]\nmodel = "pinhole"\nefl_mm = 8.0\n[render]\nspp = 4\nmax_depth = 3\nseed = 3\n'
        '[[objects]]\nid = "board"\nkeyframes = [{ t_s = 0.0, position = [0, 0, 0] }, '
        "{ t_s = 0.02, position = [0.05, 0, 0] }]\n"
    )
    (folder / "board.toml").write_text(toml)
    return folder / "board.toml"


def frames(simulation: Simulation) -> list[np.ndarray]:
    return [frame.photocurrent_pa for frame in simulation.frames()]


def test_dict_scene_renders_the_same_as_the_xml_and_animates_by_id(tmp_path: Path) -> None:
    from_xml = frames(Simulation(xml_scene(tmp_path)))
    from_dict = frames(Simulation(copy.deepcopy(SETTINGS), scene_dict=board_dict()))
    assert len(from_xml) == len(from_dict) == 2
    for a, b in zip(from_xml, from_dict, strict=True):
        assert a.mean() > 0
        np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-6 * a.max())
    # the board moved: a 5 cm shift of a 25 cm checker square changes many pixels
    changed = np.abs(from_dict[1] - from_dict[0]) > 0.1 * from_dict[0].mean()
    assert changed.mean() > 0.05


def test_a_scene_file_can_take_a_dict_in_place_of_its_xml(tmp_path: Path) -> None:
    # the file's settings with the user's geometry; the TOML still names its XML
    simulation = Simulation(xml_scene(tmp_path), scene_dict=board_dict(), duration_s=0.01)
    assert simulation.spec.mitsuba_xml is None and simulation.spec.mitsuba_dict is not None
    assert simulation.metadata()["pecs.scene"].find("scene dict") > 0


def test_tracks_from_python_replace_the_files(tmp_path: Path) -> None:
    track = Track.from_samples(
        np.array([0.0, 1.0]), np.array([[0, 0, 0], [1, 0, 0]]), np.tile([1.0, 0, 0, 0], (2, 1))
    )
    simulation = Simulation(xml_scene(tmp_path), camera=track, objects={"board": track})
    assert simulation.spec.camera is track and simulation.spec.objects["board"] is track
    with pytest.raises(TypeError, match="camera: expected a pecs Track"):
        Simulation(xml_scene(tmp_path), camera=np.eye(4))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("board"), r"objects id 'board' is not a key of the scene dict .*'lamp'"),
        (lambda d: d.update(type="shape"), r"expected a Mitsuba scene dict"),
        (lambda d: d.update(extra=[1, 2]), r"scene_dict\['extra'\]: expected a plugin dict"),
    ],
)
def test_bad_scene_dicts_are_named(edit: Any, message: str) -> None:
    scene_dict = board_dict()
    edit(scene_dict)
    with pytest.raises(ValueError, match=message):
        load_scene(copy.deepcopy(SETTINGS), scene_dict=scene_dict)


def test_unsupported_plugin_type_is_a_clear_error() -> None:
    scene_dict = board_dict()
    scene_dict["board"]["bsdf"] = {"type": "no_such_bsdf"}
    simulation = Simulation(copy.deepcopy(SETTINGS), scene_dict=scene_dict)
    with pytest.raises(ValueError, match="Mitsuba cannot load the scene dict: .*no_such_bsdf"):
        _ = simulation.renderer


def test_settings_dict_needs_a_scene_or_a_dict() -> None:
    with pytest.raises(ValueError, match=r"settings: scene: missing required key"):
        load_scene(copy.deepcopy(SETTINGS))


def test_light_spectrum_placeholder_works_in_a_dict(tmp_path: Path) -> None:
    # The lamp's spectrum is "$light_spectrum" in both; [light] scales it the same way.
    light = {
        "temperature_k": 4000,
        "illuminance_lux": 5000,
        "at": [0, 0, 0.001],
        "normal": [0, 0, 1],
    }
    toml = xml_scene(tmp_path)
    (tmp_path / "board.xml").write_text(
        BOARD_XML.replace('value="400:0.5, 700:1.5"', 'value="$light_spectrum"')
    )
    toml.write_text(
        toml.read_text() + "[light]\ntemperature_k = 4000\nilluminance_lux = 5000\n"
        "at = [0, 0, 0.001]\nnormal = [0, 0, 1]\n"
    )
    scene_dict = board_dict()
    scene_dict["lamp"]["intensity"] = "$light_spectrum"
    from_xml = Simulation(toml, duration_s=0.01)
    from_dict = Simulation({**copy.deepcopy(SETTINGS), "light": light}, scene_dict=scene_dict)
    first_xml, first_dict = next(iter(from_xml.frames())), next(iter(from_dict.frames()))
    np.testing.assert_allclose(first_dict.photocurrent_pa, first_xml.photocurrent_pa, rtol=1e-4)
    assert from_dict.renderer.light_scale == pytest.approx(from_xml.renderer.light_scale, rel=1e-6)
    without = Simulation({**copy.deepcopy(SETTINGS), "light": light}, scene_dict=board_dict())
    with pytest.raises(ValueError, match=r"no value of its scene dict is \"\$light_spectrum\""):
        _ = without.renderer
