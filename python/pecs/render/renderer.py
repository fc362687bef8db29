"""Renders photocurrent frames of an animated scene: one Mitsuba kernel, reused every frame.

The scene is loaded once with `optimize=False` (so meshes sharing a material stay separate),
animation updates `mi.traverse` parameters (object `to_world` or vertex positions, the camera's
`to_world`), and every frame uses the same sampler seed: a static pixel sees the same Monte Carlo
samples at every time step and so cannot fire events from path-tracing noise.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pecs._mitsuba import mitsuba
from pecs.ground_truth.intrinsics import CameraModel, fitted_lens_model, pinhole_model
from pecs.ground_truth.surface import BACKGROUND, SurfaceHits
from pecs.render.cfa import ColourFilterArray
from pecs.render.film import cfa_film, qe_film
from pecs.render.light import (
    LIGHT_SPECTRUM,
    level_emitters,
    spectrum_dict,
    spectrum_parameter,
    with_light_spectrum,
)
from pecs.render.optics import horizontal_fov_deg, irradiance_per_radiance, sensor_dict
from pecs.render.pixel_geometry import PixelGeometry
from pecs.render.quantum_efficiency import QuantumEfficiency
from pecs.render.scene_file import SceneSpec
from pecs.render.spectrum import Q_ELECTRON_C

# Frames are photocurrent in picoamperes: the sensor presets' dark current of 1e-3 frame units
# is then 1 fA, the order of a DVS pixel's dark current, and a white wall at a few hundred lux
# gives about 1 pA (optics-and-spectra.md: femtoamperes dark, picoamperes in daylight).
AMPERES_PER_FRAME_UNIT = 1e-12


class Renderer:
    """Photocurrent frames (picoamperes per pixel, float32 H x W) of a scene at any time."""

    def __init__(
        self,
        spec: SceneSpec,
        geometry: PixelGeometry,
        qe: QuantumEfficiency,
        cfa: ColourFilterArray | None = None,
    ) -> None:
        self.spec, self.geometry, self.qe, self.cfa = spec, geometry, qe, cfa
        self.mi = mi = mitsuba()
        self.scene, self.light_scale = self._load_scene()
        # The XML's camera (if any) gives the default pose and field of view.
        self._xml_fov_deg: float | None = None
        self._xml_camera_pose = np.eye(4)
        if self.scene.sensors():
            xml_sensor = self.scene.sensors()[0]
            xml_params = mi.traverse(xml_sensor)
            if "x_fov" in xml_params:
                self._xml_fov_deg = float(np.ravel(xml_params["x_fov"])[0])
            self._xml_camera_pose = _to_numpy(xml_sensor.world_transform())
        sampler = {"type": "independent", "sample_count": spec.spp}
        if cfa is None:
            film = qe_film(qe, geometry.width, geometry.height)
        else:  # one film channel per filter; `render` keeps each pixel's own
            film = cfa_film(qe, cfa, geometry.width, geometry.height)
        self.sensor = mi.load_dict(
            sensor_dict(
                spec.optics,
                geometry,
                film,
                sampler,
                mi.ScalarTransform4f(self.camera_pose(0.0)),
                self._xml_fov_deg,
            )
        )
        self._sensor_params = mi.traverse(self.sensor)
        self.ghosts = self._lens_ghosts() if spec.optics.ghosts is not None else None
        self.integrator = mi.load_dict({"type": "path", "max_depth": spec.max_depth})
        self._params = mi.traverse(self.scene)
        self._animated = {oid: self._object_state(oid) for oid in spec.objects}
        # Read before any frame moves a shape: the boxes of the geometry as the scene places it.
        self._rest_boxes = np.array(
            [[list(s.bbox().min), list(s.bbox().max)] for s in self.scene.shapes()], np.float64
        ).reshape(-1, 2, 3)
        # Picoamperes per (photo-electrons / s / m^2 / sr): q * photodiode area * E / L per pixel.
        self.picoamperes_per_unit = (
            Q_ELECTRON_C
            / AMPERES_PER_FRAME_UNIT
            * geometry.photodiode_area_m2
            * irradiance_per_radiance(spec.optics, geometry, self._xml_fov_deg)
        ).astype(np.float32)

    def _load_scene(self) -> tuple[Any, float]:
        """The Mitsuba scene (XML file or dict) with its emitters at the levels asked for."""
        scene = self._load_mitsuba()
        levels = level_emitters(self.mi, scene, self.spec)
        self.emitter_scales = levels.emitter_scales
        self.flickering = levels.flickering  # lamps on mains: their level changes every frame
        return scene, levels.light_scale

    def _load_mitsuba(self) -> Any:
        """Load once, with a unit `$light_spectrum` where `[light]` asks for one."""
        mi, spec = self.mi, self.spec
        if spec.mitsuba_dict is None:
            assert spec.mitsuba_xml is not None
            parameters = {}
            if spec.light is not None:
                parameters["light_spectrum"] = spectrum_parameter(spec.light, 1.0)
            return _load_xml(mi, str(spec.mitsuba_xml), **parameters)
        scene_dict = spec.mitsuba_dict
        if spec.light is not None:
            scene_dict, count = with_light_spectrum(scene_dict, spectrum_dict(spec.light, 1.0))
            if count == 0:
                raise ValueError(
                    f"{spec.path}: the scene has [light] but no value of its scene dict is "
                    f'"{LIGHT_SPECTRUM}" (the emitters [light] scales; to set other emitters, '
                    "use [[lights]] with their ids)"
                )
        return _load_dict(mi, scene_dict, str(spec.path))

    def _lens_ghosts(self) -> Any:
        """The ghost tracer for `[optics] ghosts` (pecs.render.lens_ghosts)."""
        from pecs.render.lens_ghosts import LensGhosts, ghost_settings, realistic_lens

        optics, g = self.spec.optics, self.geometry
        assert optics.lens is not None and optics.ghosts is not None  # scene_file checks
        lens = realistic_lens(optics.lens, optics.efl_mm, optics.f_number, optics.focus_m)
        settings = ghost_settings(optics.ghosts, lens, f"{self.spec.path}: optics.ghosts")
        return LensGhosts(
            self.mi,
            self.scene,
            lens,
            g.width,
            g.height,
            g.pitch_um * 1e-3,
            self.qe,
            self.cfa,
            settings,
        )

    def _object_state(self, object_id: str) -> tuple[str, np.ndarray, np.ndarray | None]:
        params = self._params
        if f"{object_id}.to_world" in params:
            return "to_world", _to_numpy(params[f"{object_id}.to_world"]), None
        if f"{object_id}.vertex_positions" in params:
            positions = np.array(params[f"{object_id}.vertex_positions"], dtype=np.float64)
            normals_key = f"{object_id}.vertex_normals"
            normals = (
                np.array(params[normals_key], dtype=np.float64) if normals_key in params else None
            )
            return (
                "mesh",
                positions.reshape(-1, 3),
                None if normals is None or normals.size == 0 else normals.reshape(-1, 3),
            )
        shapes = sorted(
            {
                k.split(".")[0]
                for k in params.keys()
                if k.endswith((".to_world", ".vertex_positions"))
            }
        )
        raise ValueError(
            f"{self.spec.path}: objects id {object_id!r} is not a shape id of {self.spec.mitsuba_name} "
            f"(animatable shapes: {shapes})"
        )

    def camera_pose(self, t_s: float) -> np.ndarray:
        """Camera to-world 4x4 at t_s (the XML camera's pose when the scene file has no keyframes)."""
        if self.spec.camera is None:
            return self._xml_camera_pose
        return self.spec.camera.pose(t_s)

    def set_time(self, t_s: float) -> None:
        """Move camera and objects to their poses at t_s, and set flickering lamps to their level
        then (parameters only: no recompilation)."""
        mi = self.mi
        for lamp in self.flickering:
            lamp.set_time(t_s)
        self._sensor_params["to_world"] = mi.Transform4f(self.camera_pose(t_s))
        self._sensor_params.update()
        for object_id, (kind, base, normals) in self._animated.items():
            motion = self.spec.objects[object_id].pose(t_s)
            if kind == "to_world":
                self._params[f"{object_id}.to_world"] = mi.Transform4f(motion @ base)
                continue
            moved = base @ motion[:3, :3].T + motion[:3, 3]
            self._params[f"{object_id}.vertex_positions"] = mi.Float(
                moved.ravel().astype(np.float32)
            )
            if normals is not None:
                rotated = normals @ motion[:3, :3].T
                self._params[f"{object_id}.vertex_normals"] = mi.Float(
                    rotated.ravel().astype(np.float32)
                )
        if self._animated:
            self._params.update()

    def render_photoelectron_radiance(self, t_s: float) -> np.ndarray:
        """integral QE(lambda) lambda/(h c) L(lambda) d lambda per pixel, float32 H x W; with a
        colour filter array, T_c(lambda) QE(lambda) ... with c the filter over each pixel."""
        self.set_time(t_s)
        image = self.mi.render(
            self.scene,
            sensor=self.sensor,
            integrator=self.integrator,
            seed=self.spec.seed,
            spp=self.spec.spp,
        )
        channels = np.array(image, dtype=np.float32)
        frame = channels[..., 0] if self.cfa is None else self.cfa.mosaic(channels)
        if self.ghosts is not None:  # lens ghosts of the scene's lights, traced (no noise)
            frame = (frame + self.ghosts.frame(self.camera_pose(t_s))).astype(np.float32)
        return frame

    def render(self, t_s: float) -> np.ndarray:
        """Photocurrent in picoamperes per pixel at t_s, float32 H x W."""
        return self.render_photoelectron_radiance(t_s) * self.picoamperes_per_unit

    def depth(self, t_s: float) -> np.ndarray:
        """Range in metres from the camera centre to the first surface seen along each pixel's
        central ray (inf: none); `[output] depth` and `--depth` write it. Measured from the
        centre, not from the ray origin: Mitsuba's perspective rays start on the near-clip plane.
        The ground truth's depth is z-depth instead (`pecs.ground_truth`)."""
        import drjit as dr

        mi, g = self.mi, self.geometry
        self.set_time(t_s)
        ray, _ = self._central_rays(t_s)
        hit = self.scene.ray_intersect(ray)
        centre = mi.Point3f(*(float(v) for v in self.camera_pose(t_s)[:3, 3]))
        distance = dr.select(hit.is_valid(), dr.norm(hit.p - centre), dr.inf)
        distance = np.array(distance, dtype=np.float32)
        return distance.reshape(g.height, g.width)

    def surface(self, t_s: float) -> SurfaceHits:
        """The first surface along each pixel's central ray at t_s (through the pixel centre and
        the aperture's centre): world point and index into `shape_ids()`."""
        import drjit as dr

        mi, g = self.mi, self.geometry
        self.set_time(t_s)
        ray, weight = self._central_rays(t_s)
        hit = self.scene.ray_intersect(ray)
        # The realistic lens marks rays it vignettes with weight 0.
        valid = hit.is_valid() & (weight[0] > 0)
        index = dr.full(mi.Int32, BACKGROUND, g.width * g.height)
        for k, shape in enumerate(self.scene.shapes()):
            index = dr.select(valid & (hit.shape == mi.ShapePtr(shape)), k, index)
        shape_index = np.array(index, dtype=np.int32).reshape(g.height, g.width)
        points = np.array(hit.p, dtype=np.float64).reshape(3, -1).T.reshape(g.height, g.width, 3)
        points[shape_index == BACKGROUND] = np.nan
        normals = np.array(hit.sh_frame.n, dtype=np.float64).reshape(3, -1).T
        normals = normals.reshape(g.height, g.width, 3)
        normals[shape_index == BACKGROUND] = np.nan
        return SurfaceHits(points, shape_index, self.camera_pose(t_s), normals)

    def shape_boxes(self) -> np.ndarray:
        """Each shape's axis-aligned box in the world as the scene places it, before animation
        (an animated shape's box at time t is its track's pose(t) applied to this one),
        float64 (shapes, 2, 3): min and max corner, metres."""
        return self._rest_boxes.copy()

    def shape_ids(self) -> list[str]:
        """Mitsuba ids of the scene's shapes, in the order `surface().shape_index` counts them."""
        return [str(shape.id()) for shape in self.scene.shapes()]

    def camera_model(self) -> CameraModel:
        """The camera's projection: exact for pinhole and thin lens, fitted for the real lens."""
        optics, g = self.spec.optics, self.geometry
        if optics.model == "lens":
            return fitted_lens_model(
                optics.lens or "", optics.efl_mm, optics.focus_m, g.width, g.height, g.pitch_um
            )
        fov_deg = horizontal_fov_deg(optics, g, self._xml_fov_deg)
        return pinhole_model(optics.model, g.width, g.height, fov_deg)

    def _central_rays(self, t_s: float) -> tuple[Any, Any]:
        """One ray per pixel (row-major) through its centre and the aperture's centre."""
        import drjit as dr

        mi, g = self.mi, self.geometry
        index = dr.arange(mi.UInt32, g.width * g.height)
        film_position = mi.Point2f(
            (mi.Float(index % g.width) + 0.5) / g.width,
            (mi.Float(index // g.width) + 0.5) / g.height,
        )
        # The time opaque: as a literal it is compiled into the kernel, recompiled at every new
        # time (0.28 s a call at 96 x 72, against 0.015 s reused).
        return self.sensor.sample_ray(
            dr.opaque(mi.Float, t_s), mi.Float(0.5), film_position, mi.Point2f(0.5, 0.5)
        )


def _load_xml(mi: Any, path: str, **parameters: str) -> Any:
    try:
        return mi.load_file(path, optimize=False, **parameters)
    except RuntimeError as error:
        message = str(error).strip().splitlines()
        detail = message[0] if message else type(error).__name__
        if "unused parameters" in detail.lower() and parameters:
            detail = (
                "the scene has [light] but its XML does not use $light_spectrum in its emitters "
                "(to set other emitters, an envmap say, use [[lights]] with their ids)"
            )
        raise ValueError(f"{path}: Mitsuba cannot load this scene: {detail}") from error


def _load_dict(mi: Any, scene_dict: dict[str, Any], where: str) -> Any:
    try:
        return mi.load_dict(scene_dict, optimize=False)
    except (RuntimeError, TypeError) as error:
        message = str(error).strip().splitlines()
        detail = message[0] if message else type(error).__name__
        raise ValueError(f"{where}: Mitsuba cannot load the scene dict: {detail}") from error


def _to_numpy(transform: Any) -> np.ndarray:
    matrix = np.array(transform.matrix, dtype=np.float64)
    return matrix[..., 0] if matrix.ndim == 3 else matrix
