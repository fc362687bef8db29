"""The `driving` scene generator: a straight road with lane markings between rows of buildings,
vehicles driving along its lanes, seen from a camera on a vehicle that drives forward with a
little pitch and roll; by day under a drawn sky and sun, by night under street lights.

World frame: y up, the road's surface is y = 0, it runs along +z (the camera's way), its middle
at x = 0; traffic keeps right (the camera's right is -x), so lanes at x < 0 drive towards +z and
lanes at x > 0 come the other way (a one-lane-per-side road has one of each). Every value drawn
is in the description; `write` derives the rest. The `[scene.draw]` keys: `PARAMETERS`, and
docs/datasets.md.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement

import numpy as np

from pecs.dataset.generators import environment, files, materials, shapes, textures, trajectories
from pecs.dataset.generators.base import SceneGenerator, SceneSettings
from pecs.dataset.generators.lights import direction
from pecs.dataset.generators.ranges import Draws, Parameter
from pecs.render.animation import look_at_rotation

FORMAT = "pecs driving scene 1"
TIMES = ("day", "night")
VEHICLE_MATERIALS = ("plastic", "conductor")
FACADE_TEXTURES = ("noise", "stripes", "checkers", "image")
SKY_FILE = "textures/sky.pfm"
# Road layout (metres): how far the scene reaches behind the camera's start and ahead of where
# it ends, the markings (3 m dashes every 12 m, 15 cm wide, 5 mm above the asphalt), the ground
# beside the road (2 cm below it: no coplanar faces), building depths.
BEHIND_M = 20.0
AHEAD_M = 120.0
DASH_M, DASH_PERIOD_M, MARKING_WIDTH_M, MARKING_LIFT_M = 3.0, 12.0, 0.15, 0.005
GROUND_DROP_M = 0.02
BUILDING_DEPTH_M = (8.0, 20.0)
# Vehicles: body length and width, the body from 0.3 m to 1.1 m up, a cabin above it.
VEHICLE_LENGTH_M = (3.8, 5.0)
VEHICLE_WIDTH_M = (1.7, 1.95)
VEHICLE_BODY_M = (0.3, 1.1)
VEHICLE_CABIN_M = (0.5, 0.7)
VEHICLE_AHEAD_M = (6.0, 90.0)
#: Least bumper-to-bumper gap (m) between vehicles in a lane, and to the camera's vehicle.
VEHICLE_GAP_M = 2.0
_PLACEMENT_TRIES = 50
# Street lights: poles at the road's edges, lamps (spheres) at 7 m reaching 1.5 m over it.
POLE_HEIGHT_M, LAMP_REACH_M, LAMP_RADIUS_M, POLE_RADIUS_M = 7.0, 1.5, 0.2, 0.08
# Body motion of the camera's vehicle: per axis the mean of two sines of 0.5-3 Hz (suspension
# pitch and roll modes are near 1-1.5 Hz); yaw sways a fifth of the pitch.
SWAY_HZ = (0.5, 3.0)
_YAW_OF_PITCH = 0.2
# Meter heights: by day above every roof (the open sky's horizontal illuminance, no shadow), by
# night 2 m over the road's middle (above every vehicle, below the lamps).
_DAY_METER_CLEARANCE_M, NIGHT_METER_HEIGHT_M = 1.0, 2.0
# Reflectances (flat spectra): asphalt's two levels, ground, white and yellow paint, poles.
ASPHALT = ((0.06, 0.1), (0.12, 0.18))
GROUND_ALBEDO, WHITE_PAINT, POLE_ALBEDO = 0.3, 0.75, 0.4
YELLOW_PAINT = [0.05, 0.06, 0.45, 0.7, 0.72, 0.75, 0.75, 0.75]  # at materials.ALBEDO_NM

PARAMETERS = {
    "lane_count": Parameter("integer", (2, 4), 2, 8, meaning="lanes"),
    "lane_width_m": Parameter("uniform", (3.0, 3.75), 2.0, 6.0, meaning="lane width (m)"),
    "setback_m": Parameter(
        "uniform", (2.0, 6.0), 0.5, 50.0, meaning="road edge to the facades (m)"
    ),
    "building_width_m": Parameter(
        "uniform", (8.0, 25.0), 2.0, 200.0, meaning="building frontage (m)"
    ),
    "building_gap_m": Parameter("uniform", (0.0, 6.0), 0.0, 100.0, meaning="gap between (m)"),
    "building_height_m": Parameter(
        "uniform", (6.0, 30.0), 2.0, 300.0, meaning="building height (m)"
    ),
    "facade_textures": Parameter("choice", FACADE_TEXTURES, names=textures.TEXTURES),
    "texture_repeats": Parameter("integer", (2, 6), 1, 64, meaning="facade tiles"),
    "albedo": Parameter("uniform", (0.1, 0.7), 0.0, 1.0, meaning="reflectance"),
    "roughness": Parameter("uniform", (0.05, 0.4), 0.001, 1.0, meaning="GGX alpha of paint"),
    "vehicle_count": Parameter("integer", (2, 6), 0, 32, meaning="vehicles"),
    "vehicle_materials": Parameter("choice", VEHICLE_MATERIALS, names=VEHICLE_MATERIALS),
    "vehicle_textures": Parameter("choice", ("none",), names=textures.TEXTURES),
    "vehicle_speed_m_s": Parameter("uniform", (3.0, 15.0), 0.0, 70.0, meaning="vehicle speed"),
    "camera_speed_m_s": Parameter("uniform", (3.0, 15.0), 0.0, 70.0, meaning="camera speed"),
    "camera_height_m": Parameter("uniform", (1.2, 1.6), 0.2, 5.0, meaning="camera height"),
    "pitch_deg": Parameter("uniform", (0.0, 0.5), 0.0, 10.0, meaning="pitch sway amplitude"),
    "roll_deg": Parameter("uniform", (0.0, 0.3), 0.0, 10.0, meaning="roll sway amplitude"),
    "fov_deg": Parameter("uniform", (60.0, 100.0), 1.0, 170.0, meaning="horizontal field of view"),
    "times": Parameter("choice", TIMES, names=TIMES),
    "day_illuminance_lux": Parameter(
        "log_uniform", (1000.0, 100_000.0), 1e-3, 1e6, meaning="illuminance by day"
    ),
    "night_illuminance_lux": Parameter(
        "log_uniform", (2.0, 50.0), 1e-3, 1e6, meaning="illuminance by night"
    ),
    "sky_kinds": Parameter("choice", environment.SKY_KINDS, names=environment.SKY_KINDS),
    "sun_elevation_deg": Parameter("uniform", (15.0, 70.0), 1.0, 90.0, meaning="sun elevation"),
    "sun_share": Parameter(
        "uniform", (0.5, 0.85), 0.0, 0.99, meaning="the sun's share of the daylight"
    ),
    "sun_temperature_k": Parameter(
        "uniform", (4500.0, 6500.0), 1000.0, 20000.0, meaning="the sun's colour temperature"
    ),
    "street_light_spacing_m": Parameter(
        "uniform", (20.0, 40.0), 5.0, 500.0, meaning="street light spacing"
    ),
    "street_light_temperature_k": Parameter(
        "uniform", (2000.0, 4500.0), 1000.0, 20000.0, meaning="street lights' colour temperature"
    ),
}


class DrivingGenerator(SceneGenerator):
    """A road between buildings with traffic, from a moving vehicle; see the module."""

    name = "driving"
    parameters = PARAMETERS

    def describe(self, rng: np.random.Generator, duration_s: float) -> dict[str, Any]:
        draws = self.draws(rng)
        lanes, lane_width_m = draws.integer("lane_count"), draws.value("lane_width_m")
        camera = _describe_camera(draws, lanes, lane_width_m)
        length_m = camera["speed_m_s"] * duration_s + AHEAD_M
        description: dict[str, Any] = {
            "format": FORMAT,
            "generator": self.name,
            "duration_s": duration_s,
            "road": {
                "lanes": lanes,
                "lane_width_m": lane_width_m,
                "setback_m": draws.value("setback_m"),
                "start_m": -BEHIND_M,
                "end_m": length_m,
                "asphalt": _asphalt(draws.rng),
            },
            "camera": camera,
        }
        description["buildings"] = _describe_buildings(draws, -BEHIND_M, length_m)
        description["vehicles"] = _describe_vehicles(draws, lanes, camera, duration_s)
        description["lighting"] = _describe_lighting(draws)
        return description

    def write(self, description: dict[str, Any], folder: Path, settings: SceneSettings) -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        root = files.scene_root()
        _add_road(root, description, folder)
        for building in description["buildings"]:
            root.append(_building_element(building, description["road"], folder))
        for vehicle in description["vehicles"]:
            root.append(_vehicle_element(vehicle, description["road"], folder))
        _add_lighting(root, description, folder)
        files.write_xml(root, folder / "scene.xml", f"Drawn by pecs's {self.name} generator")
        path = folder / "scene.toml"
        path.write_text(_scene_toml(description, settings))
        (folder / "description.json").write_text(json.dumps(description, indent=1) + "\n")
        return path


def lane_centre_m(lane: int, lanes: int, lane_width_m: float) -> float:
    """x of lane `lane`'s middle; lane 0 is the rightmost seen from the camera (x < 0)."""
    return (lane + 0.5 - lanes / 2.0) * lane_width_m


def lane_direction(lane: int, lanes: int) -> int:
    """+1 for lanes driving towards +z (the right half, x < 0), -1 for oncoming ones."""
    return 1 if lane < lanes / 2.0 else -1


def _asphalt(rng: np.random.Generator) -> dict[str, Any]:
    """Asphalt: fractal noise weighting two dark grey levels."""
    dark, light = (float(rng.uniform(*levels)) for levels in ASPHALT)
    return {
        "kind": "diffuse",
        "albedo": [dark] * len(materials.ALBEDO_NM),
        "albedo_2": [light] * len(materials.ALBEDO_NM),
        "texture": textures.describe_texture("noise", rng),
        "repeats": 1,
    }


def _describe_camera(draws: Draws, lanes: int, lane_width_m: float) -> dict[str, Any]:
    # The camera's vehicle drives in a forward lane, near its middle.
    lane = int(draws.rng.integers(0, max(1, lanes // 2)))
    sway = {
        "pitch_deg": draws.value("pitch_deg"),
        "roll_deg": draws.value("roll_deg"),
        "frequencies_hz": [[float(v) for v in row] for row in draws.rng.uniform(*SWAY_HZ, (3, 2))],
        "phases": [[float(v) for v in row] for row in draws.rng.uniform(0, 2 * math.pi, (3, 2))],
    }
    return {
        "lane": lane,
        "offset_m": float(draws.rng.uniform(-0.3, 0.3)),
        "height_m": draws.value("camera_height_m"),
        "speed_m_s": draws.value("camera_speed_m_s"),
        "fov_deg": draws.value("fov_deg"),
        "sway": sway,
        "x_m": lane_centre_m(lane, lanes, lane_width_m),
    }


def _describe_buildings(draws: Draws, start_m: float, end_m: float) -> list[dict[str, Any]]:
    """Rows of buildings on both sides, frontage and gap drawn, from the road's start until a
    building reaches its end."""
    buildings = []
    for side in (-1, 1):
        z = start_m + draws.rng.uniform(0.0, draws.ranges["building_gap_m"][1])
        reached = start_m
        while reached < end_m:
            width = draws.value("building_width_m")
            buildings.append(
                {
                    "id": f"building_{len(buildings)}",
                    "side": side,
                    "start_m": float(z),
                    "width_m": width,
                    "depth_m": float(draws.rng.uniform(*BUILDING_DEPTH_M)),
                    "height_m": draws.value("building_height_m"),
                    "facade": materials.describe_material("diffuse", draws, "facade_textures"),
                }
            )
            reached = z + width
            z = reached + draws.value("building_gap_m")
    return buildings


def _describe_vehicles(
    draws: Draws, lanes: int, camera: dict[str, Any], duration_s: float
) -> list[dict[str, Any]]:
    vehicles: list[dict[str, Any]] = []
    for index in range(draws.integer("vehicle_count")):
        lane = int(draws.rng.integers(0, lanes))
        vehicle = {
            "id": f"vehicle_{index}",
            "class": "vehicle",
            "lane": lane,
            "direction": lane_direction(lane, lanes),
            "speed_m_s": draws.value("vehicle_speed_m_s"),
            "length_m": float(draws.rng.uniform(*VEHICLE_LENGTH_M)),
            "width_m": float(draws.rng.uniform(*VEHICLE_WIDTH_M)),
            "cabin_m": float(draws.rng.uniform(*VEHICLE_CABIN_M)),
            "material": materials.describe_material(
                draws.pick("vehicle_materials"), draws, "vehicle_textures"
            ),
        }
        vehicle["start_m"] = _free_start(draws.rng, vehicle, vehicles, camera, duration_s)
        vehicles.append(vehicle)
    return vehicles


def _free_start(
    rng: np.random.Generator,
    vehicle: dict[str, Any],
    others: list[dict[str, Any]],
    camera: dict[str, Any],
    duration_s: float,
) -> float:
    """A start (z of the middle) ahead of the camera where, over the whole sequence, the vehicle
    keeps `VEHICLE_GAP_M` from every other in its lane and from the camera's vehicle (the last
    try if none does). Positions are linear in time: checking both ends checks all of it."""
    camera_car = {
        "lane": camera["lane"],
        "start_m": -VEHICLE_LENGTH_M[1] / 2.0,  # the camera sits at its vehicle's front
        "length_m": VEHICLE_LENGTH_M[1],
        "direction": 1,
        "speed_m_s": camera["speed_m_s"],
    }
    for _ in range(_PLACEMENT_TRIES):
        start = float(rng.uniform(*VEHICLE_AHEAD_M))
        candidate = dict(vehicle, start_m=start)
        if all(_apart(candidate, o, duration_s) for o in [*others, camera_car]):
            break
    return start


def _apart(a: dict[str, Any], b: dict[str, Any], duration_s: float) -> bool:
    if a["lane"] != b["lane"]:
        return True
    reach = (a["length_m"] + b["length_m"]) / 2.0 + VEHICLE_GAP_M
    return all(abs(vehicle_z(a, t) - vehicle_z(b, t)) > reach for t in (0.0, duration_s))


def vehicle_z(vehicle: dict[str, Any], t_s: float) -> float:
    """z of a vehicle's middle at `t_s`."""
    return vehicle["start_m"] + vehicle["direction"] * vehicle["speed_m_s"] * t_s


def _describe_lighting(draws: Draws) -> dict[str, Any]:
    time = draws.pick("times")
    if time == "night":
        return {
            "time": time,
            "illuminance_lux": draws.value("night_illuminance_lux"),
            "spacing_m": draws.value("street_light_spacing_m"),
            "temperature_k": draws.value("street_light_temperature_k"),
        }
    sky = environment.describe_sky(
        draws.rng, draws.pick("sky_kinds"), draws.value("sun_elevation_deg")
    )
    # An overcast sky hides the sun: all daylight is the sky's.
    share = 0.0 if sky["kind"] == "overcast" else draws.value("sun_share")
    return {
        "time": time,
        "illuminance_lux": draws.value("day_illuminance_lux"),
        "sky": sky,
        "sun_share": share,
        "temperature_k": draws.value("sun_temperature_k"),
    }


def _flat(parent: Element, albedo: float | list[float]) -> None:
    values = albedo if isinstance(albedo, list) else [albedo] * len(materials.ALBEDO_NM)
    bsdf = SubElement(parent, "bsdf", type="diffuse")
    SubElement(bsdf, "spectrum", name="reflectance", value=materials.spectrum_value(values))


def _rectangle(
    root: Element, shape_id: str, x: tuple[float, float], z: tuple[float, float], y: float
) -> Element:
    """A horizontal rectangle facing up over [x0, x1] x [z0, z1] at height y."""
    shape = SubElement(root, "shape", type="rectangle", id=shape_id)
    half_x, half_z = (x[1] - x[0]) / 2.0, (z[1] - z[0]) / 2.0
    # Rectangle [-1, 1]^2 facing +z, turned to face +y (its v along +z) and stretched.
    matrix = np.array(
        [
            [half_x, 0, 0, (x[0] + x[1]) / 2.0],
            [0, 0, 1, y],
            [0, -half_z, 0, (z[0] + z[1]) / 2.0],
            [0, 0, 0, 1],
        ],
        dtype=np.float64,
    )
    files.transform_element(shape, matrix)
    return shape


def _add_road(root: Element, description: dict[str, Any], folder: Path) -> None:
    """The asphalt, the ground beside it to the buildings and beyond, and the markings."""
    road = description["road"]
    half = road["lanes"] * road["lane_width_m"] / 2.0
    span = (road["start_m"], road["end_m"])
    asphalt = _rectangle(root, "road", (-half, half), span, 0.0)
    material = dict(road["asphalt"], repeats=max(1, round((span[1] - span[0]) / (2 * half))))
    textures.write_texture(material["texture"], folder / "textures" / "road.png")
    asphalt.append(materials.bsdf_element(material, "textures/road.png"))
    reach = half + road["setback_m"] + BUILDING_DEPTH_M[1] + AHEAD_M
    ground = _rectangle(
        root, "ground", (-reach, reach), (span[0] - AHEAD_M, span[1] + AHEAD_M), -GROUND_DROP_M
    )
    _flat(ground, GROUND_ALBEDO)
    count = 0
    for lane in range(1, road["lanes"]):
        x = lane_centre_m(lane, road["lanes"], road["lane_width_m"]) - road["lane_width_m"] / 2
        centre_line = lane_direction(lane - 1, road["lanes"]) != lane_direction(lane, road["lanes"])
        if centre_line:  # solid yellow between the directions
            line = _rectangle(root, f"marking_{count}", _across(x), span, MARKING_LIFT_M)
            _flat(line, YELLOW_PAINT)
            count += 1
            continue
        z = span[0]
        while z < span[1]:
            dash = _rectangle(root, f"marking_{count}", _across(x), (z, z + DASH_M), MARKING_LIFT_M)
            _flat(dash, WHITE_PAINT)
            count += 1
            z += DASH_PERIOD_M
    for x in (-half + MARKING_WIDTH_M, half - MARKING_WIDTH_M):  # solid white edges
        line = _rectangle(root, f"marking_{count}", _across(x), span, MARKING_LIFT_M)
        _flat(line, WHITE_PAINT)
        count += 1


def _across(x: float) -> tuple[float, float]:
    return (x - MARKING_WIDTH_M / 2.0, x + MARKING_WIDTH_M / 2.0)


def _building_element(building: dict[str, Any], road: dict[str, Any], folder: Path) -> Element:
    """A box from the ground up, its street face `setback_m` from the road's edge."""
    half_road = road["lanes"] * road["lane_width_m"] / 2.0
    x = building["side"] * (half_road + road["setback_m"] + building["depth_m"] / 2.0)
    z = building["start_m"] + building["width_m"] / 2.0
    shape = Element("shape", type="cube", id=building["id"])
    matrix = np.diag(
        [building["depth_m"] / 2.0, building["height_m"] / 2.0, building["width_m"] / 2.0, 1.0]
    )
    matrix[:3, 3] = [x, building["height_m"] / 2.0 - GROUND_DROP_M, z]
    files.transform_element(shape, matrix)
    facade = building["facade"]
    texture_file = None
    if "texture" in facade:
        texture_file = f"textures/{building['id']}.png"
        textures.write_texture(facade["texture"], folder / texture_file)
    shape.append(materials.bsdf_element(facade, texture_file))
    return shape


def vehicle_mesh(vehicle: dict[str, Any]) -> shapes.Mesh:
    """A body box and a cabin box on it (one mesh: one instance), centred on x and z, resting
    on the road; faces flat, uv unused."""
    import trimesh.creation

    length, width = vehicle["length_m"], vehicle["width_m"]
    low, high = VEHICLE_BODY_M
    body = trimesh.creation.box(extents=[width, high - low, length])
    body.apply_translation([0.0, (low + high) / 2.0, 0.0])
    cabin = trimesh.creation.box(extents=[0.9 * width, vehicle["cabin_m"], 0.55 * length])
    cabin.apply_translation([0.0, high + vehicle["cabin_m"] / 2.0, -0.05 * length])
    corners = np.concatenate([body.vertices[body.faces], cabin.vertices[cabin.faces]])
    vertices = corners.reshape(-1, 3)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    return shapes.Mesh(vertices, faces, np.zeros((len(vertices), 2)), None)


def _vehicle_element(vehicle: dict[str, Any], road: dict[str, Any], folder: Path) -> Element:
    mesh_file = f"meshes/{vehicle['id']}.ply"
    shapes.write_ply(vehicle_mesh(vehicle), folder / mesh_file)
    shape = Element("shape", type="ply", id=vehicle["id"])
    SubElement(shape, "string", name="filename", value=mesh_file)
    pose = np.eye(4)
    if vehicle["direction"] < 0:  # oncoming: turned about y
        pose[0, 0] = pose[2, 2] = -1.0
    x = lane_centre_m(vehicle["lane"], road["lanes"], road["lane_width_m"])
    pose[:3, 3] = [x, 0.0, vehicle["start_m"]]
    files.transform_element(shape, pose)
    texture_file = None
    if "texture" in vehicle["material"]:
        texture_file = f"textures/{vehicle['id']}.png"
        textures.write_texture(vehicle["material"]["texture"], folder / texture_file)
    shape.append(materials.bsdf_element(vehicle["material"], texture_file))
    return shape


def street_lights(description: dict[str, Any]) -> list[tuple[str, np.ndarray]]:
    """(id, lamp centre) of each street light: both edges, staggered by half a spacing."""
    road, lighting = description["road"], description["lighting"]
    if lighting["time"] != "night":
        return []
    half = road["lanes"] * road["lane_width_m"] / 2.0
    lamps = []
    for side, shift in ((-1, 0.0), (1, 0.5)):
        z = road["start_m"] + shift * lighting["spacing_m"]
        while z < road["end_m"]:
            x = side * (half + 0.5 - LAMP_REACH_M)
            lamps.append((f"street_light_{len(lamps)}", np.array([x, POLE_HEIGHT_M, z])))
            z += lighting["spacing_m"]
    return lamps


def _add_lighting(root: Element, description: dict[str, Any], folder: Path) -> None:
    """By night: poles and spherical lamps of `$light_spectrum`; by day the sky's map and,
    unless overcast, the sun: a directional emitter of `$light_spectrum`."""
    lighting = description["lighting"]
    half = description["road"]["lanes"] * description["road"]["lane_width_m"] / 2.0
    for lamp_id, centre in street_lights(description):
        pole = SubElement(root, "shape", type="cylinder", id=lamp_id.replace("light", "pole"))
        side = math.copysign(1.0, centre[0])
        base = [side * (half + 0.5), -GROUND_DROP_M, float(centre[2])]
        top = [base[0], POLE_HEIGHT_M, base[2]]
        SubElement(pole, "point", name="p0", value=", ".join(files.number(v) for v in base))
        SubElement(pole, "point", name="p1", value=", ".join(files.number(v) for v in top))
        SubElement(pole, "float", name="radius", value=files.number(POLE_RADIUS_M))
        sides = SubElement(pole, "bsdf", type="twosided")
        _flat(sides, POLE_ALBEDO)
        lamp = SubElement(root, "shape", type="sphere", id=lamp_id)
        SubElement(lamp, "point", name="center", value=", ".join(files.number(v) for v in centre))
        SubElement(lamp, "float", name="radius", value=files.number(LAMP_RADIUS_M))
        area = SubElement(lamp, "emitter", type="area")
        SubElement(area, "spectrum", name="radiance", value="$light_spectrum")
    if lighting["time"] != "day":
        return
    environment.write_sky(lighting["sky"], folder / SKY_FILE)
    root.append(environment.emitter_element(SKY_FILE))
    if lighting["sun_share"] > 0.0:
        sun = SubElement(root, "emitter", type="directional", id="sun")
        towards = -_sun_direction(lighting["sky"])
        SubElement(
            sun, "vector", name="direction", value=", ".join(files.number(v) for v in towards)
        )
        SubElement(sun, "spectrum", name="irradiance", value="$light_spectrum")


def _sun_direction(sky: dict[str, Any]) -> np.ndarray:
    return direction(sky["sun_elevation_deg"], sky["sun_azimuth_deg"])


def meter_point(description: dict[str, Any]) -> np.ndarray:
    """Where the illuminance is set: by day above every roof, by night 2 m over the road's
    middle, halfway between the first two lamps ahead of the camera on one side."""
    lighting = description["lighting"]
    if lighting["time"] == "day":
        top = max([b["height_m"] for b in description["buildings"]], default=0.0)
        return np.array([0.0, top + _DAY_METER_CLEARANCE_M, 10.0])
    return np.array([0.0, NIGHT_METER_HEIGHT_M, 0.5 * lighting["spacing_m"]])


def camera_track(description: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, positions, quaternions) of the camera: forward along +z at its speed, with its
    vehicle's pitch, roll and a little yaw about the forward look."""
    camera, duration_s = description["camera"], description["duration_s"]
    times = trajectories.keyframe_times(duration_s, trajectories.CAMERA_KEYFRAME_HZ)
    start = np.array([camera["x_m"] + camera["offset_m"], camera["height_m"], 0.0])
    positions = start + np.outer(camera["speed_m_s"] * times, [0.0, 0.0, 1.0])
    look = look_at_rotation(start, start + [0.0, 0.0, 1.0], (0.0, 1.0, 0.0))
    sway = camera["sway"]
    waves = np.sin(
        2.0 * math.pi * np.asarray(sway["frequencies_hz"])[None] * times[:, None, None]
        + np.asarray(sway["phases"])[None]
    ).mean(axis=2)  # (n, 3): camera x (pitch), y (yaw), z (roll)
    amplitude = np.radians([sway["pitch_deg"], _YAW_OF_PITCH * sway["pitch_deg"], sway["roll_deg"]])
    vector = waves * amplitude
    angle = np.linalg.norm(vector, axis=1)
    safe = np.where(angle > 0, angle, 1.0)
    turn = np.column_stack([np.cos(angle / 2), np.sin(angle / 2)[:, None] * vector / safe[:, None]])
    return times, positions, trajectories.compose(look, turn)


def _scene_toml(description: dict[str, Any], settings: SceneSettings) -> str:
    parts = files.settings_tables(description, settings)
    parts.append(files.toml_table("[classes]", _classes(description)))
    parts += _light_tables(description)
    times, positions, rotations = camera_track(description)
    keyframes = [
        {"t_s": float(t), "position": p.tolist(), "quaternion": q.tolist()}
        for t, p, q in zip(times, positions, rotations, strict=True)
    ]
    parts.append(files.toml_table("[camera]", {"interpolation": "spline", "keyframes": keyframes}))
    parts += _vehicle_tables(description)
    return "\n".join(parts)


def _classes(description: dict[str, Any]) -> dict[str, str]:
    classes = {"road": "road", "ground": "ground"}
    classes.update({b["id"]: "building" for b in description["buildings"]})
    classes.update({v["id"]: v["class"] for v in description["vehicles"]})
    for lamp_id, _ in street_lights(description):
        classes[lamp_id] = "street_light"
        classes[lamp_id.replace("light", "pole")] = "pole"
    return classes


def _light_tables(description: dict[str, Any]) -> list[str]:
    """Night: `[light]` sets the lamps together. Day: `[[lights]]` gives the sky its share
    (all of it under an overcast sky) and `[light]` makes the sun up the rest."""
    lighting = description["lighting"]
    total = lighting["illuminance_lux"]
    meter = {"at": meter_point(description).tolist(), "normal": [0.0, 1.0, 0.0]}
    light = {"temperature_k": lighting["temperature_k"], "illuminance_lux": total, **meter}
    if lighting["time"] == "night":
        return [files.toml_table("[light]", light)]
    sky_lux = total * (1.0 - lighting["sun_share"])
    tables = [
        files.toml_table(
            "[[lights]]", {"id": environment.SKY_ID, "illuminance_lux": sky_lux, **meter}
        )
    ]
    if lighting["sun_share"] > 0.0:
        tables.insert(0, files.toml_table("[light]", light))
    return tables


def _vehicle_tables(description: dict[str, Any]) -> list[str]:
    """One `[[objects]]` per moving vehicle: a straight drive along its lane."""
    tables = []
    duration_s = description["duration_s"]
    times = trajectories.keyframe_times(duration_s, trajectories.OBJECT_KEYFRAME_HZ)
    for vehicle in description["vehicles"]:
        if vehicle["speed_m_s"] == 0.0:
            continue
        keyframes = [
            {
                "t_s": float(t),
                "position": [0.0, 0.0, vehicle_z(vehicle, float(t)) - vehicle["start_m"]],
                "quaternion": [1.0, 0.0, 0.0, 0.0],
            }
            for t in times
        ]
        values = {"id": vehicle["id"], "interpolation": "spline", "keyframes": keyframes}
        tables.append(files.toml_table("[[objects]]", values))
    return tables
