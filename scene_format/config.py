"""A scene's config (`<scene>/scene.yaml`, `blender_scenes/<name>.yaml`): strict, typed, frozen dataclasses,
pure Python. The generator (datagen) reads it to render; a scene folder's reader reads the copy
written beside the data."""
from __future__ import annotations

import copy
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Mapping

from common.config import SEED_RANGE, ConfigError, check_positive, from_dict, read_yaml_mapping
from simulator.config import SimulatorConfig

MAX_RENDER_PIXELS = 4096 * 4096


@dataclass(frozen=True)
class RenderConfig:
    """engine: workbench (rasteriser, noise-free; default) | cycles | eevee. samples: anti-aliasing
    samples for workbench (1, 5, 8, 11, 16, 32), path-tracing samples for cycles, TAA samples for eevee.
    adaptive_px: 0 renders every frame of the fps time line; > 0 renders only the frames the image
    motion needs, at most adaptive_px of motion (p99 of the scene's surface points) between two rendered
    frames and at most max_stride frames apart, the kept frames always (datagen.temporal_sampling)."""
    engine: Literal["workbench", "cycles", "eevee"] = "workbench"  # Blender's renderer: workbench (rasteriser, noise-free), cycles or eevee
    samples: int = 8  # render samples per pixel (Cycles / Eevee; Workbench's anti-aliasing)
    fps: float = 3000.0  # rendered frames per second of scene time
    width: int = 346  # image width, pixels
    height: int = 260  # image height, pixels
    adaptive_px: float = 0.0  # render only where the image moves more than this many pixels since the last render, blend the rest (0: every frame)
    max_stride: int = 8  # adaptive rendering: at most this many frames between rendered ones

    def __post_init__(self):
        check_positive(self, "samples", "fps", "width", "height", "max_stride")
        if not 0 <= self.adaptive_px <= 10:
            raise ConfigError(f"adaptive_px: expected 0 (every frame rendered) or a bound in (0, 10] px of image "
                              f"motion between rendered frames, got {self.adaptive_px!r}")
        if not self.max_stride <= 1000:
            raise ConfigError(f"max_stride: expected at most 1000 frames between rendered frames, got {self.max_stride!r}")
        if self.width * self.height > MAX_RENDER_PIXELS:
            raise ConfigError(f"width, height: {self.width} x {self.height} is more than {MAX_RENDER_PIXELS:,} pixels "
                              "(4096 x 4096); every camera's frames and simulator state must fit in memory")
        if self.engine == "workbench" and self.samples not in (1, 5, 8, 11, 16, 32):
            raise ConfigError(f"samples: workbench supports 1, 5, 8, 11, 16 or 32 samples, got {self.samples}")


@dataclass(frozen=True)
class ShakeConfig:
    """High-frequency camera egomotion (a hand-held or robot-mounted rig): each camera rotates about
    its own axes by a sum of `components` sinusoids per axis, with frequencies drawn log-uniformly in
    [min_hz, max_hz] (real time, Hz) and random phases, seeded per scene and camera.

    rms_deg is the RMS rotation about the pan and tilt axes; roll gets roll_scale times that.
    rms_deg: 0 turns shake off.
    """
    rms_deg: float = 0.0  # RMS rotation of the shake, degrees (0: off)
    min_hz: float = 4.0  # lowest shake frequency
    max_hz: float = 25.0  # highest shake frequency
    components: int = 3  # sine components summed per axis
    roll_scale: float = 0.5  # roll's amplitude relative to pan and tilt

    def __post_init__(self):
        check_positive(self, "min_hz", "max_hz", "components")
        if not 0 <= self.rms_deg <= 10:
            raise ConfigError(f"rms_deg: expected 0 to 10 degrees, got {self.rms_deg!r}")
        if not self.min_hz <= self.max_hz:
            raise ConfigError(f"max_hz: expected at least min_hz ({self.min_hz}), got {self.max_hz!r}")
        if not 0 <= self.roll_scale <= 2:
            raise ConfigError(f"roll_scale: expected 0 to 2, got {self.roll_scale!r}")


@dataclass(frozen=True)
class CameraRigConfig:
    """Cameras uniformly spaced in azimuth on a spiral around `target`, at constant height.

    Camera k starts at azimuth azimuth0_deg + 360 k / n_cameras and turns by sweep_deg over the clip;
    its distance from the vertical axis through the target goes from radius to radius + radius_change.
    `shake` adds high-frequency rotation about each camera's own axes on top of the look-at pose.
    """
    n_cameras: int = 6  # cameras of the rig
    radius: float = 4.0  # distance of each camera from the target (scene units)
    height: float = 1.5  # camera height above the target (scene units)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the point every camera looks at (scene units)
    azimuth0_deg: float = 0.0  # azimuth of camera 0 at the clip's start; the others evenly spaced
    sweep_deg: float = 30.0  # azimuth each camera travels over the clip
    radius_change: float = 0.0  # change of the radius over the clip (scene units)
    fov_x_deg: float = 50.0  # horizontal field of view, degrees
    shake: ShakeConfig = field(default_factory=ShakeConfig)  # high-frequency rotation of each camera (off at rms_deg 0)

    def __post_init__(self):
        check_positive(self, "n_cameras", "radius", "fov_x_deg")
        if not self.fov_x_deg < 170:
            raise ConfigError(f"fov_x_deg: expected less than 170 degrees, got {self.fov_x_deg}")
        if not self.radius + self.radius_change > 0:
            raise ConfigError("radius_change: the spiral must keep a positive radius")


@dataclass(frozen=True)
class LightingConfig:
    """Workbench studio lighting, fixed in world space so every camera sees the same shading
    (`shading: flat` shows unlit texture colours)."""
    shading: Literal["studio", "flat"] = "studio"  # studio: lit by the studio light; flat: unlit texture colours
    studio_light: str = "Default"  # the Workbench studio light's name
    rotate_z_deg: float = 30.0  # rotation of the studio light about the vertical axis, degrees
    shadows: bool = True  # cast shadows from light_direction
    shadow_intensity: float = 0.4  # darkness of the cast shadows (0: none, 1: black)
    light_direction: tuple[float, float, float] = (0.4, -0.3, 0.85)  # the shadow light's direction (world, towards the light)
    cavity: bool = False  # Workbench's cavity shading (darkens creases)
    background: tuple[float, float, float] = (0.05, 0.05, 0.06)  # linear RGB of the empty background
    exposure: float = 1.0  # linear gain on rendered radiance (a brighter or dimmer scene)

    def __post_init__(self):
        check_positive(self, "exposure")


@dataclass(frozen=True)
class FramesConfig:
    """keep_every: store RGB frames at every n-th rendered timestamp. test_every: of those, every
    n-th one per camera is held out for testing (llffhold)."""
    keep_every: int = 30  # keep every this many rendered frames (sharp frames, blur centres)
    test_every: int = 8  # every this many kept frames is a held-out test view

    def __post_init__(self):
        check_positive(self, "keep_every", "test_every")


@dataclass(frozen=True)
class BlurConfig:
    """Motion-blur levels declared by what they do: level name -> target blur length in pixels.

    The blur length of a blurred frame is the median, over the pixels covered by geometry, of the
    length of the image path each visible surface point travels during the exposure (computed from
    the scene geometry and camera poses, `datagen.blur_geometry`). The generator picks, per level,
    the exposure (a whole number of rendered frames, at most max_exposure_ms and the clip) whose
    median over every camera and blurred frame is closest to the target; a level whose closest
    exposure misses the target by more than `tolerance` (relative) is an error, never a clamp.
    sample_stride_px: the blur length is measured on every n-th pixel in x and y.
    fit: the targets are guides rather than requirements: a ladder whose strongest target is beyond the
    longest exposure's blur is scaled by one factor so that the strongest is that blur (the levels keep
    their ratios), and each level then takes the closest exposure not taken by a weaker level, however
    far it lands (the manifest records the target and what it got). Set for a user's scene under a
    preset that renders it at another size than its targets were written for, or with the preset's
    own targets (chosen for the preset's scenes); targets used at the size they were written for are
    never fitted.
    """
    target_px: dict[str, float] = field(default_factory=dict)  # blur level -> target median blur length (px)
    exposure_ms: dict[str, float] = field(default_factory=dict)   # levels of a fixed exposure (real-time ms)
    tolerance: float = 0.15  # a level's measured blur may miss its target by this fraction
    max_exposure_ms: float = 40.0  # longest exposure a blur level may take (real-time ms)
    sample_stride_px: int = 4  # pixel stride of the surface samples the blur is measured on
    fit: bool = False  # take the closest exposure however far it lands, instead of refusing a level out of reach

    def __post_init__(self):
        check_positive(self, "tolerance", "max_exposure_ms", "sample_stride_px")
        for level, px in self.target_px.items():
            if not px > 0:
                raise ConfigError(f"target_px.{level}: expected a positive blur length in pixels, got {px!r}")
        values = list(self.target_px.values())
        if len(set(values)) != len(values):
            raise ConfigError(f"target_px: two levels share a target ({self.target_px})")
        for level, ms in self.exposure_ms.items():
            if not ms > 0:
                raise ConfigError(f"exposure_ms.{level}: expected a positive exposure in milliseconds, got {ms!r}")
            if level in self.target_px:
                raise ConfigError(f"exposure_ms.{level}: level {level!r} is also declared in target_px")
        if not self.tolerance < 1:
            raise ConfigError(f"tolerance: expected a relative tolerance below 1, got {self.tolerance!r}")

    @property
    def levels(self) -> list[str]:
        """Level names: those declared in pixels from the weakest to the strongest blur, then those
        declared by a fixed exposure from the shortest to the longest."""
        return sorted(self.target_px, key=self.target_px.get) + sorted(self.exposure_ms, key=self.exposure_ms.get)


@dataclass(frozen=True)
class SpeedConfig:
    """Speed variants: the same render traversed `factors` times faster (datagen.speed).

    Variant s of scene NAME is the folder NAME_x<s>: the clip's timestamps divided by s, the events
    re-simulated from the same rendered frames at those timestamps with the scene's sensor, and
    blurred frames (level `shutter`) of a fixed real-time exposure `exposure_ms`, which integrate
    exposure_ms * fps * s rendered frames. A speed whose exposure exceeds the clip, or a render whose
    image moves more than `max_px_per_frame` (p90) between rendered frames, is refused.
    """
    factors: tuple[float, ...] = ()  # speed factors of the variants written beside the scene (<scene>_x<f>)
    exposure_ms: float = 2.0  # the variants' shutter (real-time ms) of their blurred frames
    max_px_per_frame: float = 2.0  # refuse a variant whose image moves more than this between rendered frames (p90)

    def __post_init__(self):
        check_positive(self, "exposure_ms", "max_px_per_frame")
        for s in self.factors:
            if not (isinstance(s, (int, float)) and s >= 1):
                raise ConfigError(f"factors: expected speed factors >= 1, got {s!r}")
        if len(set(self.factors)) != len(self.factors):
            raise ConfigError(f"factors: a speed appears twice ({list(self.factors)})")


SCENE_FILE_SUFFIXES = (".blend", ".glb", ".gltf", ".fbx", ".obj", ".usd", ".usda", ".usdc", ".usdz", ".abc")


@dataclass(frozen=True)
class SourceConfig:
    """Where the scene comes from: built in code (blender_scenes/<name>.py; `file` empty) or a file
    made elsewhere (.blend, or glTF / FBX / OBJ / USD / Alembic imported headless). A file's own
    animation, frames frame_start .. frame_end at `fps` (read from the file when not given), is the
    clip: it spans the normalised time [0, 1], played in duration_s seconds (the file's own length
    unless the scene YAML or the preset sets duration_s). rig `auto` places the camera rig from the
    animated bounding box (around it for kind object, inside it for kind room); `config` keeps camera:
    as written. `cameras` names camera objects of the file to film with instead of the rig."""
    file: str = ""  # a scene file (.blend, glTF, FBX, USD, Alembic) to render instead of a built-in scene
    # built in code: the built-in scene whose builder (blender_scenes/<builtin>.py) makes this one, for a
    # scene YAML copied under a new name (`name: my_cubes`, `source: {builtin: cubes}`); "" = its name
    builtin: str = ""
    frame_start: float | None = None  # first animation frame of the file to use (None: the file's start)
    frame_end: float | None = None  # last animation frame of the file to use (None: the file's end)
    fps: float | None = None  # the file's animation frame rate (None: the file's own)
    rig: Literal["auto", "config"] = "auto"  # auto: place the rig around the file's animation; config: the camera section as given
    # camera objects of the file to use instead of the rig (their animated poses and their common lens)
    cameras: tuple[str, ...] = ()

    def __post_init__(self):
        if self.file and self.builtin:
            raise ConfigError(f"builtin: {self.builtin!r} and file: {self.file!r}: a scene comes from one; keep one")
        if self.builtin and not self.builtin.replace("_", "").isalnum():
            raise ConfigError(f"builtin: expected a built-in scene's name, got {self.builtin!r}")
        if self.file and not self.file.lower().endswith(SCENE_FILE_SUFFIXES):
            raise ConfigError(f"file: {self.file!r} is not a format Blender imports headless here "
                              f"(expected {', '.join(SCENE_FILE_SUFFIXES)})")
        if self.fps is not None and not self.fps > 0:
            raise ConfigError(f"fps: expected a positive frame rate, got {self.fps!r}")
        if self.frame_start is not None and self.frame_end is not None and not self.frame_end > self.frame_start:
            raise ConfigError(f"frame_end: expected a frame after frame_start ({self.frame_start}), got {self.frame_end}")


SCENE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,127}")


GROUND_TRUTH_KINDS = ("depth", "flow", "normals", "ids")   # datagen.ground_truth, docs/reference/dataset_layout.md


@dataclass(frozen=True)
class SceneConfig:
    name: str  # the scene's name and folder name
    kind: Literal["object", "room"]  # object (cameras outside, looking in) or room (cameras inside)
    description: str = ""  # what the scene shows (free text)
    duration_s: float = 0.2  # scene time of the clip, seconds (before a speed variant's factor)
    motion_strength: float = 1.0  # scales every animated motion of the built-in scene (1: as written)
    seed: int = 0  # the scene's random seed (textures, noise of the renders, the events unless sensor_seed)
    render: RenderConfig = field(default_factory=RenderConfig)  # the renderer and the frame rate and size
    camera: CameraRigConfig = field(default_factory=CameraRigConfig)  # the camera rig
    lighting: LightingConfig = field(default_factory=LightingConfig)  # the lighting
    frames: FramesConfig = field(default_factory=FramesConfig)  # which frames are kept and held out
    blur: BlurConfig = field(default_factory=BlurConfig)  # no target_px: no blurred frames
    sensor: SimulatorConfig = field(default_factory=SimulatorConfig)  # the event sensor (the Sensor table)
    speed: float = 1.0     # this folder's time compression: the clip lasts duration_s / speed real seconds
    speeds: SpeedConfig = field(default_factory=SpeedConfig)   # speed variants written beside the scene
    source: SourceConfig = field(default_factory=SourceConfig)   # built in code, or a file's scene
    # extra event formats written beside the HDF5 (datagen.exports; eventio.formats.FORMATS but h5)
    formats: tuple[str, ...] = ()
    # per-pixel ground truth of every kept frame (datagen.ground_truth): any of GROUND_TRUTH_KINDS
    ground_truth: tuple[str, ...] = ()
    # seed of the event sensor's noise and threshold mismatch alone (None: the scene's seed): another
    # value is another realisation of the same scene's events, every frame and pose unchanged (the
    # benchmark's `noise` seed axis: dataset `<preset>@noise<k>`)
    sensor_seed: int | None = None
    # a named sensor (configs/sensors/<name>.yaml) in place of `sensor`, which it replaces whole, and the
    # optional effects of it this scene calls for (simulator.sensor_presets.EFFECTS: latency, readout,
    # bandwidth, on_off_mismatch); the dataset `<preset>@<sensor>` sets it for every scene
    sensor_preset: str = ""
    sensor_effects: tuple[str, ...] = ()  # the optional effects of sensor_preset this scene calls for

    def __post_init__(self):
        check_positive(self, "duration_s")
        if not (isinstance(self.name, str) and SCENE_NAME.fullmatch(self.name)):
            raise ConfigError(f"name: expected a folder name (letters, digits, and _ . + - after the first; no / "
                              f"or leading dot), got {self.name!r}: the scene is written to <out>/<name>")
        if not self.speed >= 1:
            raise ConfigError(f"speed: expected a time compression factor >= 1, got {self.speed!r}")
        from eventio.formats import FORMATS

        for fmt in self.formats:
            if fmt not in FORMATS or fmt == "h5":
                raise ConfigError(f"formats: {fmt!r} is not an extra event format (expected any of "
                                  f"{', '.join(f for f in FORMATS if f != 'h5')}; the HDF5 is always written)")
        if len(set(self.formats)) != len(self.formats):
            raise ConfigError(f"formats: a format is named twice ({list(self.formats)})")
        for kind in self.ground_truth:
            if kind not in GROUND_TRUTH_KINDS:
                raise ConfigError(f"ground_truth: {kind!r} is not a kind of ground truth (expected any of "
                                  f"{', '.join(GROUND_TRUTH_KINDS)})")
        from simulator.sensor_presets import EFFECTS

        for effect in self.sensor_effects:
            if effect not in EFFECTS:
                raise ConfigError(f"sensor_effects: {effect!r} is not an effect (expected any of {', '.join(EFFECTS)})")
        if len(set(self.ground_truth)) != len(self.ground_truth):
            raise ConfigError(f"ground_truth: a kind is named twice ({list(self.ground_truth)})")
        if not self.motion_strength >= 0:   # 0: a static scene (only the cameras move)
            raise ConfigError(f"motion_strength: expected a value >= 0, got {self.motion_strength!r}")
        if self.duration_s * self.render.fps > MAX_TIMESTAMPS:
            raise ConfigError(f"duration_s: {self.duration_s:g} s at render.fps {self.render.fps:g} is "
                              f"{self.duration_s * self.render.fps:.3g} rendered timestamps; at most {MAX_TIMESTAMPS:,} "
                              "(~2 days of rendering six cameras at the quick preset's pace); shorten the clip or lower the rate")

    @property
    def event_seed(self) -> int:
        """The seed of the event sensor's noise and mismatch: sensor_seed, else the scene's seed."""
        return self.seed if self.sensor_seed is None else self.sensor_seed

    @property
    def n_timestamps(self) -> int:
        """Rendered timestamps: the clip [0, duration] sampled at fps, both ends included."""
        return int(round(self.duration_s * self.render.fps)) + 1

    @property
    def real_duration_s(self) -> float:
        """How long the clip lasts for the sensor and the shutter: duration_s / speed."""
        return self.duration_s / self.speed

    @property
    def real_fps(self) -> float:
        """Rendered frames per real second: render.fps * speed."""
        return self.render.fps * self.speed


def deep_merge(base: Mapping, override: Mapping) -> dict:
    out = copy.deepcopy(dict(base))
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def read_scene_yaml(path: Path) -> dict:
    """A scene YAML as a mapping; a top-level `file: my_scene.blend` is short for `source: {file: ...}`."""
    data = read_yaml_mapping(path)
    if "file" in data:
        source = data.get("source") or {}
        if not isinstance(source, Mapping) or "file" in source:
            raise ConfigError(f"{path}: file: given twice (as file: and as source.file:); keep one")
        data["source"] = {**source, "file": data.pop("file")}
    return data


def expand_sensor_preset(data: Mapping, path: Path) -> dict:
    """A scene mapping whose `sensor_preset` (if any) has replaced its `sensor` mapping: that named
    sensor with the scene's `sensor_effects` on. Done once, when a scene is resolved from its YAML and
    a preset's overrides; a folder's scene.yaml records the result and is read as written."""
    if not data.get("sensor_preset"):
        return dict(data)
    from simulator.sensor_presets import sensor_dict

    effects = data.get("sensor_effects") or ()
    try:
        if not isinstance(effects, (list, tuple)):
            raise ConfigError(f"sensor_effects: expected a list of effect names, got {effects!r}")
        return {**data, "sensor": sensor_dict(str(data["sensor_preset"]), effects)}
    except ConfigError as exc:
        raise ConfigError(f"{path}: sensor_preset {data['sensor_preset']!r}: {exc}") from None


def parse_scene(data: Mapping, path: Path) -> SceneConfig:
    """A scene config from a mapping read from `path`, parsed strictly (ConfigError names the file)."""
    try:
        return from_dict(SceneConfig, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def read_scene_config(path: str | Path) -> SceneConfig:
    """A scene YAML file (a scene folder's scene.yaml, or a scene's own YAML), parsed strictly."""
    return parse_scene(read_scene_yaml(Path(path)), Path(path))


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
MAX_TIMESTAMPS = 1_000_000      # rendered timestamps of one scene (duration_s x render.fps)
RenderConfig.BOUNDS = {
    "samples": (0, 64, "Workbench anti-aliasing samples"), "fps": (1e-3, 1e6, "frames per second; times are whole us"),
    "width": (1, 8192, "pixels"), "height": (1, 8192, "pixels"), "adaptive_px": (0.0, 1000.0, "pixels of motion"),
    "max_stride": (1, 100_000, "timestamps"),
}
ShakeConfig.BOUNDS = {
    "rms_deg": (0.0, 90.0, "degrees"), "min_hz": (0.0, 1e4, "Hz"), "max_hz": (0.0, 1e4, "Hz"),
    "components": (0, 64, "sine components"), "roll_scale": (0.0, 100.0, "a multiple of the shake"),
}
CameraRigConfig.BOUNDS = {
    "n_cameras": (1, 64, "cameras"), "radius": (1e-6, 1e4, "scene units"), "height": (-1e4, 1e4, "scene units"),
    "azimuth0_deg": (-360.0, 360.0, "degrees"), "sweep_deg": (-36000.0, 36000.0, "degrees (100 turns)"),
    "radius_change": (-1e4, 1e4, "scene units"), "fov_x_deg": (1e-3, 179.0, "degrees"),
}
LightingConfig.BOUNDS = {
    "rotate_z_deg": (-360.0, 360.0, "degrees"), "shadow_intensity": (0.0, 1.0, "a fraction"),
    "exposure": (-100.0, 100.0, "Blender exposure (EV)"),
}
FramesConfig.BOUNDS = {"keep_every": (1, MAX_TIMESTAMPS, "timestamps"), "test_every": (1, MAX_TIMESTAMPS, "kept frames")}
BlurConfig.BOUNDS = {
    "tolerance": (0.0, 10.0, "a relative error"), "max_exposure_ms": (0.0, 1e4, "milliseconds"),
    "sample_stride_px": (1, 10_000, "pixels"),
}
SpeedConfig.BOUNDS = {"exposure_ms": (0.0, 1e4, "milliseconds"), "max_px_per_frame": (0.0, 1e4, "pixels")}
SourceConfig.BOUNDS = {"frame_start": (-1e7, 1e7, "frames"), "frame_end": (-1e7, 1e7, "frames"),
                       "fps": (1e-3, 1e6, "frames per second")}
SceneConfig.BOUNDS = {
    "duration_s": (1e-6, 3600.0, "seconds of clip"), "motion_strength": (0.0, 100.0, "a multiple of the scene's motion"),
    "seed": SEED_RANGE, "sensor_seed": SEED_RANGE, "speed": (1.0, 1e4, "a time compression factor"),
}
