"""The one configuration object: CLI flags, YAML files and GUI sliders all read and write it.

Example:
    >>> cfg = Config.load("my.yaml", overrides=["consciousness.tracking_threshold_m=0.25"])
    >>> cfg.set("consciousness.presence_threshold", 0.7)   # validated, as a slider does
    >>> cfg.save("run/config.yaml")                        # atomic; `ocslam run --config` reads it back
"""

from __future__ import annotations

import copy
import dataclasses
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from app.ocslam.config import (
    ConfigError,
    ConsciousnessConfig,
    DetectorConfig,
    RobotConfig,
    SlamConfig,
    coerce_value,
    param,
    validate_section,
)

__all__ = ["Config", "ConfigError", "PROJECT_ROOT", "ASSETS", "resolve_path", "project_relative", "atomic_write_bytes",
           "atomic_write_text"]

#: The repository root (the package is installed editable by ``make setup``).
PROJECT_ROOT = Path(os.environ.get("OCSLAM_ROOT", Path(__file__).resolve().parents[1]))
ASSETS = PROJECT_ROOT / "assets"


def resolve_path(p: str | os.PathLike[str]) -> Path:
    """Relative paths in the config are relative to the project root if they exist there, else to the CWD."""
    path = Path(p).expanduser()
    if path.is_absolute():
        return path
    if (Path.cwd() / path).exists():
        return Path.cwd() / path
    return PROJECT_ROOT / path


def project_relative(p: str | os.PathLike[str]) -> str:
    """``p`` relative to the project when it lies inside it (what a model card or report writes down: no
    machine's folders), else ``p`` as given."""
    try:
        return str(Path(p).resolve().relative_to(PROJECT_ROOT.resolve()))
    except (ValueError, OSError):
        return str(p)


_UMASK = os.umask(0)
os.umask(_UMASK)


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


# ----------------------------------------------------------------------------------------------
# Simulator, sensor and UI sections
# ----------------------------------------------------------------------------------------------


@dataclass
class SimConfig:
    """The pybullet world and the loop's clock."""

    world: str = param("assets/worlds/apartment.yaml", help="world file (docs/world-format.md)")
    physics_dt_s: float = param(0.01, min=0.001, max=0.05, unit="s", help="fixed physics step")
    seed: int = param(0, min=0, max=2**31 - 1, help="random seed of sensor noise")
    speed: float = param(
        1.0, min=0.1, max=20.0, step=0.1, help="target sim speed in the live app (1 = real time)", live=True
    )
    route: str = param("tour", help="route followed by headless runs and 'Follow route'")
    motor_time_constant_s: float = param(
        0.05, min=0.0, max=2.0, unit="s", help="wheel rates follow the command with this first-order lag"
    )
    robot_height_m: float = param(0.192, min=0.05, max=2.0, unit="m", help="height of the robot's collision cylinder")
    light_direction: list = param([0.3, -0.4, 1.0], help="render light direction [x, y, z] (world frame)", items=float,
                                  length=3)
    light_ambient: float = param(0.6, min=0.0, max=1.0, help="render ambient light coefficient")
    light_diffuse: float = param(0.5, min=0.0, max=1.0, help="render diffuse light coefficient")
    renderer: str = param(
        "auto", choices=("auto", "egl", "tiny"),
        help="camera renderer: auto = pybullet's EGL plugin (Mesa llvmpipe) where it loads, else TinyRenderer",
    )
    egl_shadow_map: bool = param(
        False, help="EGL renderer: draw pybullet's shadow-map pass before each frame (two thirds of a frame on"
                    " llvmpipe); off: no cast shadows or specular highlights, as in TinyRenderer's shadow=0",
    )
    parallel_stages: bool = param(
        True, help="run the detector, SLAM and the consciousness on threads overlapping physics, LIDAR and rendering"
                   " (results tied to sensor stamps: the same run as without)",
    )


@dataclass
class EncoderConfig:
    """Wheel encoders (absolute angles) and the wheel–floor slip that makes odometry drift."""

    rate_hz: float = param(50.0, min=1.0, max=1000.0, unit="Hz", help="odometry update rate")
    noise_std_rad: float = param(0.002, min=0.0, max=0.5, unit="rad", help="σ of each angle reading")
    slip_std: float = param(0.02, min=0.0, max=0.5, help="σ of the relative wheel slip (per wheel, slowly varying)")
    slip_tau_s: float = param(0.05, min=0.001, max=100.0, unit="s", help="correlation time of the wheel slip")
    radius_error_std: float = param(
        0.0, min=0.0, max=0.05, help="σ of a per-run relative error of each wheel's effective radius (systematic drift)"
    )
    resolution_rad: float = param(0.0015, min=0.0, max=0.1, unit="rad", help="encoder quantisation (4096 ticks/rev)")


@dataclass
class LidarConfig:
    """LDS-01-like 2D LIDAR."""

    beams: int = param(360, min=8, max=4096, help="beams over 360°")
    range_min_m: float = param(0.12, min=0.0, max=5.0, unit="m", help="minimum range (closer: -inf, REP-117)")
    range_max_m: float = param(3.5, min=0.5, max=100.0, unit="m", help="maximum range (no return → inf)")
    rate_hz: float = param(5.0, min=0.5, max=100.0, unit="Hz", help="scan rate")
    noise_std_m: float = param(0.01, min=0.0, max=0.5, step=0.001, unit="m", help="Gaussian range noise σ")
    caster: str = param(
        "planar", choices=("planar", "pybullet"),
        help="planar: rays against the collision shapes' exact cross-section at the LIDAR height (fast);"
             " pybullet: rayTestBatch",
    )


@dataclass
class CameraConfig:
    """Forward RGB camera (Astra-like)."""

    width: int = param(640, min=32, max=1920, help="image width (px)")
    height: int = param(480, min=24, max=1080, help="image height (px)")
    hfov_rad: float = param(1.04, min=0.2, max=3.0, unit="rad", help="horizontal field of view")
    rate_hz: float = param(5.0, min=0.5, max=60.0, unit="Hz", help="frame rate")
    near_m: float = param(0.05, min=0.001, max=1.0, unit="m", help="render near plane")
    far_m: float = param(20.0, min=1.0, max=200.0, unit="m", help="render far plane")
    render_width: int = param(
        320, min=0, max=1920,
        help="render at this width and scale K (0: full width); 320 = the training renders; the detector reads 224",
    )
    async_render: bool = param(
        True, help="render in a separate process (overlaps with SLAM and the detector on the other core)"
    )
    latency_s: float = param(
        0.1, min=0.0, max=1.0, unit="s", help="camera latency: a frame is processed this long after its stamp"
    )
    noise_std: float = param(2.0, min=0.0, max=50.0, help="pixel noise σ (0-255)")


@dataclass
class UiConfig:
    """Web view."""

    update_hz: float = param(10.0, min=1.0, max=30.0, unit="Hz", help="scene update rate", live=True)
    map_hz: float = param(1.0, min=0.1, max=5.0, unit="Hz", help="occupancy grid update rate", live=True)
    camera_width: int = param(320, min=64, max=1280, help="width of the camera panel image")
    wall_height_m: float = param(0.6, min=0.05, max=5.0, unit="m", help="walls are drawn cut away at this height (0: full)")
    teleop_deadman_s: float = param(0.6, min=0.1, max=5.0, unit="s", help="keyboard teleop stops after this", live=True)
    teleop_linear_mps: float = param(0.15, min=0.0, max=2.0, step=0.01, unit="m/s", help="teleop speed", live=True)
    teleop_angular_rps: float = param(1.0, min=0.0, max=10.0, step=0.05, unit="rad/s", help="teleop turn rate", live=True)


@dataclass
class ServerConfig:
    """The viser server. Local only unless told otherwise."""

    host: str = param("127.0.0.1", help="bind address ('0.0.0.0' exposes the robot to the network)")
    port: int = param(8080, min=0, max=65535, help="port (0: any free port)")
    allow_origins: list = param([], help="extra allowed WebSocket Origins (besides the server's own)", items=str)
    require_token: bool = param(True, help="on a non-loopback host, require the random access token printed at start"
                                " (`ocslam run --no-token` turns it off)")
    runs_dir: str = param("runs", help="the only directory the web UI saves or loads sessions, maps and configs in"
                          " (relative: to the project root)")
    worlds_dirs: list = param(["worlds", "assets/worlds"], help="directories whose *.yaml worlds the web UI offers"
                              " (relative: to the project root)")


@dataclass
class ReplayConfig:
    """``ocslam replay`` and ``ocslam run --record`` (ROS 2 bags, docs/ros2.md)."""

    T_base_scan: list = param(
        [],
        help="LIDAR pose in base_footprint [x, y, z, roll, pitch, yaw] (m, rad) when the bag has no /tf_static for it"
             " ([]: the robot model's)",
    )
    scan_topic: str = param("/scan", help="sensor_msgs/LaserScan topic")
    odom_topic: str = param("/odom", help="nav_msgs/Odometry topic (else /tf odom → base)")
    image_topic: str = param("/camera/image_raw/compressed", help="sensor_msgs/CompressedImage topic")
    image_raw_topic: str = param("/camera/image_raw", help="sensor_msgs/Image topic (used when no compressed one)")
    camera_info_topic: str = param("/camera/camera_info", help="sensor_msgs/CameraInfo topic")
    yolo_boxes_topic: str = param("/yolo_boxes", help="recorded boxes (std_msgs/Float32MultiArray) for --reuse-detections")
    snapshot_period_s: float = param(10.0, min=0.5, max=3600.0, unit="s", help="core snapshots for seeking, every")
    record_image_format: str = param("jpeg", choices=("jpeg", "png"), help="recorded camera frames: jpeg or lossless png")
    record_jpeg_quality: int = param(95, min=10, max=100, help="JPEG quality of recorded camera frames")


SECTIONS: dict[str, type] = {
    "sim": SimConfig,
    "robot": RobotConfig,
    "encoders": EncoderConfig,
    "lidar": LidarConfig,
    "camera": CameraConfig,
    "slam": SlamConfig,
    "detector": DetectorConfig,
    "consciousness": ConsciousnessConfig,
    "ui": UiConfig,
    "server": ServerConfig,
    "replay": ReplayConfig,
}


@dataclass
class Config:
    """All sections. Field paths are ``section.field`` (e.g. ``consciousness.tracking_threshold_m``)."""

    sim: SimConfig = field(default_factory=SimConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    encoders: EncoderConfig = field(default_factory=EncoderConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    slam: SlamConfig = field(default_factory=SlamConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    consciousness: ConsciousnessConfig = field(default_factory=ConsciousnessConfig)
    ui: UiConfig = field(default_factory=UiConfig)
    server: ServerConfig = field(default_factory=ServerConfig)
    replay: ReplayConfig = field(default_factory=ReplayConfig)

    # -- field access ------------------------------------------------------------------------------
    def field_info(self, path: str) -> tuple[str, dataclasses.Field]:
        section, _, name = path.partition(".")
        if section not in SECTIONS:
            raise ConfigError(f"unknown config section {section!r} (known: {', '.join(SECTIONS)})")
        fields = {f.name: f for f in dataclasses.fields(SECTIONS[section])}
        if name not in fields:
            raise ConfigError(f"unknown config key {path!r} (section {section!r} has: {', '.join(fields)})")
        return section, fields[name]

    def get(self, path: str) -> Any:
        section, f = self.field_info(path)
        return getattr(getattr(self, section), f.name)

    def set(self, path: str, value: Any) -> Any:
        """Validate and set one value; returns the coerced value. Raises :class:`ConfigError`."""
        section, f = self.field_info(path)
        v = coerce_value(section, f, value)
        setattr(getattr(self, section), f.name, v)
        return v

    def iter_fields(self) -> Iterator[tuple[str, dataclasses.Field, Any]]:
        """Yield ``(path, field, value)`` for every field, in declaration order."""
        for section in SECTIONS:
            obj = getattr(self, section)
            for f in dataclasses.fields(obj):
                yield f"{section}.{f.name}", f, getattr(obj, f.name)

    def copy(self) -> Config:
        return copy.deepcopy(self)

    def validate(self) -> Config:
        for section in SECTIONS:
            validate_section(section, getattr(self, section))
        return self

    # -- dict / YAML -------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {s: dataclasses.asdict(getattr(self, s)) for s in SECTIONS}

    @classmethod
    def from_dict(cls, data: Any, *, source: str = "config") -> Config:
        cfg = cls()
        if data is None:
            return cfg
        if not isinstance(data, dict):
            raise ConfigError(f"{source}: expected a mapping of sections, got {type(data).__name__}")
        for section, values in data.items():
            if section not in SECTIONS:
                raise ConfigError(f"{source}: unknown section {section!r} (known: {', '.join(SECTIONS)})")
            if values is None:
                continue
            if not isinstance(values, dict):
                raise ConfigError(f"{source}: section {section!r} must be a mapping")
            for name, value in values.items():
                try:
                    cfg.set(f"{section}.{name}", value)
                except ConfigError as e:
                    raise ConfigError(f"{source}: {e}") from None
        return cfg

    @classmethod
    def load(cls, path: str | os.PathLike[str] | None = None, overrides: list[str] | None = None) -> Config:
        """Defaults, then the YAML file (if any), then ``section.key=value`` overrides."""
        if path is None:
            cfg = cls()
        else:
            p = Path(path)
            try:
                text = p.read_text(encoding="utf-8")
            except OSError as e:
                raise ConfigError(f"cannot read config file {p}: {e.strerror or e}") from None
            except UnicodeDecodeError:
                raise ConfigError(f"{p}: not a YAML config (binary data, not UTF-8 text)") from None
            try:
                data = yaml.safe_load(text)
            except yaml.YAMLError as e:
                raise ConfigError(f"{p}: malformed YAML: {e}") from None
            cfg = cls.from_dict(data, source=str(p))
        for ov in overrides or []:
            key, sep, raw = ov.partition("=")
            if not sep:
                raise ConfigError(f"override {ov!r}: expected section.key=value")
            try:
                value = yaml.safe_load(raw) if raw.strip() else ""
            except yaml.YAMLError:
                value = raw
            _, f = cfg.field_info(key.strip())
            if isinstance(f.default, str) and not isinstance(value, str):
                value = raw
            cfg.set(key.strip(), value)
        return cfg

    def to_yaml(self) -> str:
        header = "# OCSLAM config: `ocslam run --config THIS_FILE`. Keys: docs/config.md\n"
        return header + yaml.safe_dump(self.to_dict(), sort_keys=False)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Atomic write of the YAML."""
        return atomic_write_text(path, self.to_yaml())
