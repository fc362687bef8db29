"""The `objects` scene generator: a few objects of random shape, size, material and texture
moving and turning independently over a textured plane or inside a room, seen by a camera on a
smooth random path (with optional hand-held shake), lit by point or spherical lights of drawn
colour temperature set to a drawn illuminance; or outdoors, over a plane under a drawn sky (an
environment map, `environment.py`) that gives a drawn share of that illuminance.

World frame: y up, the floor is y = 0, objects start within `spread_m` of the vertical axis.
Every value drawn is in the description (`describe`); `write` derives the rest (paths sampled as
keyframes, the meter point, the room's size) and writes the scene files. What each `[scene.draw]`
key means and its law: `PARAMETERS`, and docs/datasets.md.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement

import numpy as np

from pecs.dataset.generators import (
    environment,
    files,
    lights,
    materials,
    shapes,
    textures,
    trajectories,
)
from pecs.dataset.generators.base import SceneGenerator, SceneSettings
from pecs.dataset.generators.ranges import Draws, Parameter
from pecs.render.animation import look_at_rotation, matrix_from_quaternion

BACKGROUNDS = ("plane", "room", "sky")
FORMAT = "pecs objects scene 1"
# Layout constants (metres): room margin around everything in it, the meter above the objects,
# the camera's lowest height, the plane's least half-size.
_ROOM_MARGIN_M = 1.0
_METER_CLEARANCE_M = 0.05
_CAMERA_FLOOR_M = 0.1
_PLANE_HALF_SIZE_M = 30.0
SKY_FILE = "textures/sky.pfm"
# Tries to place an object where its bounding sphere meets no other at t = 0.
_PLACEMENT_TRIES = 50
# Camera turn axes are drawn in the camera frame, favouring pan (y) over tilt (x) and roll (z).
_CAMERA_AXIS_WEIGHTS = np.array([0.6, 1.0, 0.3])

PARAMETERS = {
    "object_count": Parameter("integer", (2, 8), 0, 64, meaning="objects per scene"),
    "shapes": Parameter("choice", shapes.SHAPES, names=shapes.SHAPES),
    "object_size_m": Parameter(
        "log_uniform", (0.1, 0.4), 0.005, 10.0, meaning="bounding radius (m)"
    ),
    "spread_m": Parameter(
        "uniform", (0.5, 1.2), 0.0, 50.0, meaning="half-width of the start region (m)"
    ),
    "materials": Parameter("choice", materials.MATERIALS, names=materials.MATERIALS),
    "roughness": Parameter("uniform", (0.02, 0.5), 0.001, 1.0, meaning="GGX alpha"),
    "albedo": Parameter("uniform", (0.03, 0.9), 0.0, 1.0, meaning="reflectance"),
    "ior": Parameter("uniform", (1.3, 1.8), 1.0, 4.0, meaning="refractive index"),
    "textures": Parameter("choice", textures.TEXTURES, names=textures.TEXTURES),
    "texture_repeats": Parameter("integer", (1, 4), 1, 64, meaning="tiles per uv unit"),
    "backgrounds": Parameter("choice", BACKGROUNDS, names=BACKGROUNDS),
    "background_textures": Parameter(
        "choice", ("noise", "stripes", "checkers", "image"), names=textures.TEXTURES
    ),
    "sky_kinds": Parameter("choice", environment.SKY_KINDS, names=environment.SKY_KINDS),
    "sky_share": Parameter(
        "uniform", (0.3, 0.9), 0.01, 1.0, meaning="the sky's share of the illuminance"
    ),
    "sun_elevation_deg": Parameter(
        "uniform", (10.0, 70.0), 1.0, 90.0, meaning="the sun's elevation (sky's brightest part)"
    ),
    "object_speed_m_s": Parameter("uniform", (0.0, 1.0), 0.0, 100.0, meaning="mean speed"),
    "object_angular_rate_deg_s": Parameter(
        "uniform", (0.0, 180.0), 0.0, 3600.0, meaning="mean angular rate"
    ),
    "camera_distance_m": Parameter(
        "uniform", (2.5, 5.0), 0.1, 1000.0, meaning="camera distance to its target"
    ),
    "camera_elevation_deg": Parameter(
        "uniform", (5.0, 45.0), -80.0, 80.0, meaning="camera elevation"
    ),
    "fov_deg": Parameter("uniform", (50.0, 90.0), 1.0, 170.0, meaning="horizontal field of view"),
    "camera_speed_m_s": Parameter("uniform", (0.0, 1.5), 0.0, 100.0, meaning="mean speed"),
    "camera_angular_rate_deg_s": Parameter(
        "uniform", (0.0, 60.0), 0.0, 3600.0, meaning="mean angular rate"
    ),
    "shake_deg": Parameter("uniform", (0.0, 0.3), 0.0, 10.0, meaning="shake amplitude"),
    "light_count": Parameter("integer", (1, 3), 1, 8, meaning="lights per scene"),
    "light_kinds": Parameter("choice", lights.LIGHT_KINDS, names=lights.LIGHT_KINDS),
    "illuminance_lux": Parameter(
        "log_uniform", (1.0, 100_000.0), 1e-3, 1e6, meaning="illuminance at the scene"
    ),
    "temperature_k": Parameter(
        "uniform", (2500.0, 7500.0), 1000.0, 20000.0, meaning="colour temperature"
    ),
    "light_elevation_deg": Parameter("uniform", (25.0, 80.0), 5.0, 90.0, meaning="light elevation"),
    "light_distance_m": Parameter(
        "uniform", (1.5, 5.0), 0.2, 1000.0, meaning="light distance from the meter point"
    ),
}


class ObjectsGenerator(SceneGenerator):
    """Objects over a plane or in a room; see the module's docstring."""

    name = "objects"
    parameters = PARAMETERS

    def check(self, where: str) -> None:
        # The camera starts outside the region objects start in (a camera inside an object
        # would see nothing but its inside).
        reach = self.ranges["spread_m"][1] * math.sqrt(2) + self.ranges["object_size_m"][1]
        if self.ranges["camera_distance_m"][0] <= reach:
            raise ValueError(
                f"{where}.camera_distance_m: min {self.ranges['camera_distance_m'][0]} m would "
                f"put the camera among the objects (spread_m max * sqrt 2 + object_size_m max "
                f"= {reach:.3g} m); raise it or lower those"
            )

    def describe(self, rng: np.random.Generator, duration_s: float) -> dict[str, Any]:
        draws = self.draws(rng)
        background = draws.pick("backgrounds")
        description: dict[str, Any] = {
            "format": FORMAT,
            "generator": self.name,
            "duration_s": duration_s,
            "background": {
                "kind": background,
                "floor": materials.describe_material("diffuse", draws, "background_textures"),
            },
        }
        if background == "room":
            description["background"]["walls"] = materials.describe_material(
                "diffuse", draws, "background_textures"
            )
        if background == "sky":
            sky = environment.describe_sky(
                draws.rng, draws.pick("sky_kinds"), draws.value("sun_elevation_deg")
            )
            description["background"]["sky"] = dict(sky, share=draws.value("sky_share"))
        spread_m = draws.value("spread_m")
        description["spread_m"] = spread_m
        description["objects"] = _describe_objects(draws, spread_m)
        description["camera"] = _describe_camera(draws, spread_m)
        description["lights"] = lights.describe_lights(draws)
        description["illuminance_lux"] = draws.value("illuminance_lux")
        return description

    def write(self, description: dict[str, Any], folder: Path, settings: SceneSettings) -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        layout = _Layout(description)
        root = files.scene_root()
        _add_background(root, description, layout, folder)
        for obj, centre in zip(description["objects"], layout.centres, strict=True):
            root.append(_object_element(obj, centre, folder))
        for index, light in enumerate(description["lights"]):
            position = lights.light_position(light, layout.meter_at)
            root.append(lights.emitter_element(light, position, first=index == 0))
        files.write_xml(root, folder / "scene.xml", f"Drawn by pecs's {self.name} generator")
        path = folder / "scene.toml"
        path.write_text(_scene_toml(description, layout, settings))
        (folder / "description.json").write_text(json.dumps(description, indent=1) + "\n")
        return path


def _describe_objects(draws: Draws, spread_m: float) -> list[dict[str, Any]]:
    objects: list[dict[str, Any]] = []
    for index in range(draws.integer("object_count")):
        kind = draws.pick("shapes")
        shape = shapes.describe_shape(kind, draws.value("object_size_m"), draws.rng)
        material = materials.describe_material(draws.pick("materials"), draws)
        obj = {
            "id": f"object_{index}",
            # The class a segmentation network learns: the shape's kind.
            "class": kind,
            "shape": shape,
            "material": material,
            "position": _placed(draws.rng, shape["size_m"], spread_m, objects),
            "rotation": _random_rotation(draws.rng),
            "motion": trajectories.describe_motion(
                draws.rng,
                draws.value("object_speed_m_s"),
                draws.value("object_angular_rate_deg_s"),
            ),
        }
        objects.append(obj)
    return objects


def _placed(
    rng: np.random.Generator, size_m: float, spread_m: float, others: list[dict[str, Any]]
) -> list[float]:
    """A start position within `spread_m` of the axis, resting above the floor, where the
    bounding sphere meets no other object's (the last try if none does)."""
    for _ in range(_PLACEMENT_TRIES):
        x, z = rng.uniform(-spread_m, spread_m, 2)
        y = size_m + rng.uniform(0.0, max(spread_m, size_m))
        position = np.array([x, y, z])
        if all(
            np.linalg.norm(position - np.asarray(o["position"])) > size_m + o["shape"]["size_m"]
            for o in others
        ):
            break
    return [float(v) for v in position]


def _random_rotation(rng: np.random.Generator) -> list[float]:
    """A uniformly distributed rotation (a normalised 4D Gaussian), as (w, x, y, z)."""
    q = rng.normal(size=4)
    return [float(v) for v in q / np.linalg.norm(q)]


def _describe_camera(draws: Draws, spread_m: float) -> dict[str, Any]:
    camera: dict[str, Any] = {
        "fov_deg": draws.value("fov_deg"),
        "distance_m": draws.value("camera_distance_m"),
        "elevation_deg": draws.value("camera_elevation_deg"),
        "azimuth_deg": float(draws.rng.uniform(0.0, 360.0)),
        "target": [
            float(draws.rng.uniform(-0.3, 0.3) * spread_m),
            float(draws.rng.uniform(0.3, 0.8) * spread_m),
            float(draws.rng.uniform(-0.3, 0.3) * spread_m),
        ],
    }
    motion = trajectories.describe_motion(
        draws.rng, draws.value("camera_speed_m_s"), draws.value("camera_angular_rate_deg_s")
    )
    axis = np.asarray(motion["axis"]) * _CAMERA_AXIS_WEIGHTS
    motion["axis"] = [float(v) for v in axis / np.linalg.norm(axis)]  # camera frame
    camera["motion"] = motion
    camera["shake"] = trajectories.describe_shake(draws.rng, draws.value("shake_deg"))
    return camera


class _Layout:
    """What follows from a description: object paths lifted above the floor, the camera path,
    the meter point above every object, the extent the background must cover."""

    def __init__(self, description: dict[str, Any]) -> None:
        duration_s = description["duration_s"]
        self.object_times = trajectories.keyframe_times(duration_s, trajectories.OBJECT_KEYFRAME_HZ)
        self.centres: list[np.ndarray] = []
        self.paths: list[np.ndarray] = []
        top, extent = description["spread_m"], [np.zeros(3)]
        for obj in description["objects"]:
            path = trajectories.displacement(obj["motion"], self.object_times, duration_s)
            centre = np.asarray(obj["position"], dtype=np.float64)
            size = obj["shape"]["size_m"]
            # An object whose path dips into the floor starts higher: it touches it at most.
            centre[1] += max(0.0, size - float((centre[1] + path[:, 1]).min()))
            self.centres.append(centre)
            self.paths.append(path)
            top = max(top, float((centre[1] + path[:, 1]).max()) + size)
            extent += [centre + path.min(axis=0) - size, centre + path.max(axis=0) + size]
        self.meter_at = np.array([0.0, top + _METER_CLEARANCE_M, 0.0])
        self._camera(description["camera"], duration_s)
        extent += [self.camera_positions.min(axis=0), self.camera_positions.max(axis=0)]
        for light in description["lights"]:
            reach = light.get("radius_m", 0.0)
            position = lights.light_position(light, self.meter_at)
            extent += [position - reach, position + reach]
        points = np.array(extent)
        self.low, self.high = points.min(axis=0), points.max(axis=0)

    def _camera(self, camera: dict[str, Any], duration_s: float) -> None:
        self.camera_times = trajectories.keyframe_times(duration_s, trajectories.CAMERA_KEYFRAME_HZ)
        target = np.asarray(camera["target"], dtype=np.float64)
        start = target + camera["distance_m"] * lights.direction(
            camera["elevation_deg"], camera["azimuth_deg"]
        )
        path = trajectories.displacement(camera["motion"], self.camera_times, duration_s)
        # A path that would go below the floor is lifted (with its target: same view).
        lift = max(0.0, _CAMERA_FLOOR_M - float((start[1] + path[:, 1]).min()))
        start[1] += lift
        target[1] += lift
        self.camera_positions = start + path
        look = look_at_rotation(start, target, (0.0, 1.0, 0.0))
        turn = trajectories.axis_angle_quaternions(
            camera["motion"]["axis"],
            trajectories.turn_deg(camera["motion"], self.camera_times, duration_s),
        )
        shake = trajectories.shake_quaternions(camera["shake"], self.camera_times)
        # Body-frame turn and shake after the look-at pose: q = q_look q_turn q_shake.
        self.camera_rotations = trajectories.compose(trajectories.compose(look, turn), shake)


def _add_background(
    root: Element, description: dict[str, Any], layout: _Layout, folder: Path
) -> None:
    """The floor (a rectangle at y = 0) and, for a room, a box around everything (its floor a
    centimetre below the floor rectangle's, so that the two never overlap)."""
    background = description["background"]
    if background["kind"] == "room":
        half = np.maximum(np.abs(layout.low), np.abs(layout.high))[[0, 2]] + _ROOM_MARGIN_M
        height = layout.high[1] + _ROOM_MARGIN_M
    else:
        half = np.full(
            2, max(_PLANE_HALF_SIZE_M, 3.0 * float(np.abs([layout.low, layout.high]).max()))
        )
        height = 0.0
    floor = SubElement(root, "shape", type="rectangle", id="floor")
    # Rectangle [-1, 1]^2 facing +z, turned to face +y and stretched to the floor's size.
    matrix = np.array(
        [[half[0], 0, 0, 0], [0, 0, 1, 0], [0, -half[1], 0, 0], [0, 0, 0, 1]], dtype=np.float64
    )
    files.transform_element(floor, matrix)
    floor.append(_background_bsdf(background["floor"], "floor", folder, 2.0 * half))
    if background["kind"] == "sky":
        environment.write_sky(background["sky"], folder / SKY_FILE)
        root.append(environment.emitter_element(SKY_FILE))
    if background["kind"] != "room":
        return
    walls = SubElement(root, "shape", type="cube", id="room")
    box = np.diag([half[0], height / 2.0 + 0.005, half[1], 1.0])
    box[1, 3] = height / 2.0 - 0.01 + 0.005
    files.transform_element(walls, box)
    SubElement(walls, "boolean", name="flip_normals", value="true")
    walls.append(_background_bsdf(background["walls"], "walls", folder, 2.0 * half))


def _background_bsdf(
    material: dict[str, Any], name: str, folder: Path, size_m: np.ndarray
) -> Element:
    """A background's material; its texture tiles `repeats` times per 2 m of the larger side
    (tiles of 0.5 to 2 m with the default `texture_repeats`)."""
    texture_file = None
    if "texture" in material:
        texture_file = f"textures/{name}.png"
        textures.write_texture(material["texture"], folder / texture_file)
        tiles = material["repeats"] * math.ceil(float(size_m.max()) / 2.0)
        per_metre = dict(material, repeats=int(tiles))
        return materials.bsdf_element(per_metre, texture_file)
    return materials.bsdf_element(material, texture_file)


def _object_element(obj: dict[str, Any], centre: np.ndarray, folder: Path) -> Element:
    """The object's Mitsuba shape at its start pose, with its material (and mesh, texture)."""
    shape = obj["shape"]
    pose = np.eye(4)
    pose[:3, :3] = matrix_from_quaternion(np.asarray(obj["rotation"]))
    pose[:3, 3] = centre
    if shape["kind"] in shapes.PRIMITIVES:
        element = Element("shape", type=shape["kind"], id=obj["id"])
        files.transform_element(element, pose @ shapes.primitive_scale(shape))
    else:
        mesh_file = f"meshes/{obj['id']}.ply"
        shapes.write_ply(shapes.build_mesh(shape), folder / mesh_file)
        element = Element("shape", type="ply", id=obj["id"])
        SubElement(element, "string", name="filename", value=mesh_file)
        files.transform_element(element, pose)
    texture_file = None
    if "texture" in obj["material"]:
        texture_file = f"textures/{obj['id']}.png"
        textures.write_texture(obj["material"]["texture"], folder / texture_file)
    open_surface = shape["kind"] in shapes.OPEN_SURFACES
    element.append(materials.bsdf_element(obj["material"], texture_file, open_surface))
    return element


def _scene_toml(description: dict[str, Any], layout: _Layout, settings: SceneSettings) -> str:
    """The scene file: the settings the dataset simulated it with, the light accounting, the
    camera's and objects' keyframes."""
    parts = files.settings_tables(description, settings)
    classes = {obj["id"]: obj["class"] for obj in description["objects"]}
    if classes:  # the ground truth's class of each object (the others' follow from their ids)
        parts.append(files.toml_table("[classes]", classes))
    parts += _light_tables(description, layout)
    parts.append(_camera_table(layout))
    parts += _object_tables(description, layout)
    return "\n".join(parts)


def _light_tables(description: dict[str, Any], layout: _Layout) -> list[str]:
    """`[light]`: the total at the meter point (the first light makes up what the others do not
    give); `[[lights]]`: the sky's share of the total, then each other light's share of the
    rest."""
    scene_lights = description["lights"]
    meter = {"at": layout.meter_at.tolist(), "normal": [0.0, 1.0, 0.0]}
    sky = description["background"].get("sky")
    lamps_lux = description["illuminance_lux"] * (1.0 - sky["share"] if sky else 1.0)
    tables = [
        files.toml_table(
            "[light]",
            {
                "temperature_k": scene_lights[0]["temperature_k"],
                "illuminance_lux": description["illuminance_lux"],
                **meter,
            },
        )
    ]
    if sky:
        sky_lux = description["illuminance_lux"] * sky["share"]
        tables.append(
            files.toml_table(
                "[[lights]]", {"id": environment.SKY_ID, "illuminance_lux": sky_lux, **meter}
            )
        )
    for light, share in list(zip(scene_lights, lights.shares(scene_lights), strict=True))[1:]:
        tables.append(
            files.toml_table(
                "[[lights]]", {"id": light["id"], "illuminance_lux": lamps_lux * share, **meter}
            )
        )
    return tables


def _camera_table(layout: _Layout) -> str:
    keyframes = [
        {"t_s": float(t), "position": p.tolist(), "quaternion": q.tolist()}
        for t, p, q in zip(
            layout.camera_times, layout.camera_positions, layout.camera_rotations, strict=True
        )
    ]
    return files.toml_table("[camera]", {"interpolation": "spline", "keyframes": keyframes})


def _object_tables(description: dict[str, Any], layout: _Layout) -> list[str]:
    """One `[[objects]]` per moving object: displacement and turn about its centre."""
    tables = []
    duration_s = description["duration_s"]
    for obj, centre, path in zip(description["objects"], layout.centres, layout.paths, strict=True):
        motion = obj["motion"]
        if motion["speed_m_s"] == 0.0 and motion["angular_rate_deg_s"] == 0.0:
            continue
        turn = trajectories.axis_angle_quaternions(
            motion["axis"], trajectories.turn_deg(motion, layout.object_times, duration_s)
        )
        keyframes = [
            {"t_s": float(t), "position": p.tolist(), "quaternion": q.tolist()}
            for t, p, q in zip(layout.object_times, path, turn, strict=True)
        ]
        values = {
            "id": obj["id"],
            "pivot": centre.tolist(),
            "interpolation": "spline",
            "keyframes": keyframes,
        }
        tables.append(files.toml_table("[[objects]]", values))
    return tables
