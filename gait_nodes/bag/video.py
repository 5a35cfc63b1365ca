"""A recorded walk as a video: the robot posed from the bag, rendered headless by MuJoCo.

``python -m gait_nodes.inspect BAG --video walk.mp4`` (or ``walk.gif``; ``run ... --record BAG
--video walk.mp4`` writes one after its summary). Any gait bag renders, kinematic or physics: it
is what the bag holds that is drawn, nothing is simulated. Each frame, at bag time ``t``:

- **the robot**: MuJoCo's model of it, the one the physics simulator runs
  (:func:`gait_nodes.sim.mujoco_model.load_physics_model`: the URDF's geometry, the feet's
  contact shapes in orange), posed with the last ``odom -> base_link`` of /tf and the last
  /joint_states at or before ``t``; every link is drawn as a grey capsule from its parent's origin
  too (a skeleton), since a URDF may give its links no geometry (RoboSimian's limbs);
- **the footholds** of /gait/footsteps, one colour per foot: those landed by ``t`` (each swing as
  the plan that was walked placed it, :func:`gait_nodes.bag.analysis.executed_swings`) solid, and
  those the plan in force at ``t`` still has ahead faint; each in the shape of the foot's
  contact (a disc of the robot's foot radius, or the sole's box turned by the step's yaw);
- **the support polygon** (/gait/support_polygon, blue outline at its plane's height), **the ZMP**
  (/gait/zmp, red), **the centre of pressure** (/gait/cop, magenta, recorded by the physics
  simulator) and **the COM** (/gait/com, green, with a thin line down to the ZMP's plane);
- **the camera** follows the base: it looks at the base's position averaged over a second
  around ``t`` (the body's sway does not shake the picture) from the front left, at a distance
  set by the robot's size.

Frames are ``speed / fps`` seconds of walk apart (``speed`` 2 plays twice as fast), from
``start_s`` to ``end_s``, in seconds from the walk's first base pose. Rendering is MuJoCo's
(``mujoco.Renderer``, offscreen OpenGL: on a machine without a display EGL, or OSMesa where
EGL's library is missing or with ``MUJOCO_GL=osmesa``); encoding is imageio's: ``.mp4`` through
its ffmpeg plugin (H.264, ``imageio-ffmpeg``), ``.gif`` through Pillow; a ``.png`` is a still,
the frame at ``start_s``.
MuJoCo and imageio are optional dependencies, imported when a video is asked for (``pip
install mujoco "imageio[ffmpeg]"``).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gait_nodes.errors import GaitNodesError
from gait_nodes.markers import FOOT_COLOURS

#: Video formats by file suffix -> what encodes them.
FORMATS = {'.mp4': 'imageio-ffmpeg', '.gif': 'pillow', '.png': 'pillow'}
#: How far around ``t`` the camera averages the base's position [s].
CAMERA_WINDOW_S = 1.0
#: Colours (RGBA) of what is drawn over the robot.
ZMP_RGBA = (0.9, 0.1, 0.1, 1.0)
COP_RGBA = (0.85, 0.1, 0.85, 1.0)
COM_RGBA = (0.1, 0.7, 0.1, 1.0)
POLYGON_RGBA = (0.15, 0.35, 1.0, 1.0)
SKELETON_RGBA = (0.35, 0.37, 0.42, 1.0)
#: Landed footholds solid, planned ones faint (one colour a foot: FOOT_COLOURS, as on
#: /gait/markers).
LANDED_ALPHA, PLANNED_ALPHA = 0.9, 0.3
#: Opacity of the feet's contact shapes (what is under a sole shows through).
FOOT_ALPHA = 0.45
#: Thickness of footholds drawn on the ground, and their lift above it (no z-fighting) [m].
FOOTHOLD_THICKNESS_M = 0.002
LIFT_M = 0.003


class VideoError(GaitNodesError):
    """A video that cannot be made as asked (bad settings, a bag without a walk)."""


class VideoUnavailableError(VideoError):
    """A dependency of the video (MuJoCo, imageio, its ffmpeg plugin) is not installed."""


def headless_gl_backend() -> str | None:
    """The ``MUJOCO_GL`` backend to render with on a machine without a display, or None.

    EGL where its library is installed, else OSMesa where its is; None with a display (MuJoCo's
    default, GLFW, works there) or without either library (MuJoCo fails at import when
    ``MUJOCO_GL`` names a backend whose library is missing).
    """
    if os.environ.get('DISPLAY') or os.environ.get('WAYLAND_DISPLAY'):
        return None
    from ctypes.util import find_library

    for backend, library in (('egl', 'EGL'), ('osmesa', 'OSMesa')):
        if find_library(library):
            return backend
    return None


def prefer_headless_gl() -> None:
    """Choose MuJoCo's offscreen backend on a machine without a display, unless told otherwise.

    MuJoCo reads ``MUJOCO_GL`` once, when it is first imported: call this before. A value the
    user set is kept (:func:`headless_gl_backend` otherwise).
    """
    backend = headless_gl_backend()
    if backend is not None:
        os.environ.setdefault('MUJOCO_GL', backend)


def import_encoder(path: str | Path):
    """``imageio.v2``, checked to encode ``path``'s format; VideoUnavailableError otherwise."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise VideoError(f'{path}: a video is .mp4 or .gif (or .png, a still), got '
                         f'{suffix or "no suffix"!r}')
    install = 'pip install "imageio[ffmpeg]" (or pip install "gait_nodes[physics]")'
    try:
        import imageio.v2 as imageio
    except ImportError as exc:
        raise VideoUnavailableError(f'the video needs imageio, which is not installed ({exc}): '
                                    f'{install}') from None
    try:
        if suffix == '.mp4':
            import imageio_ffmpeg  # noqa: F401
        else:
            import PIL  # noqa: F401
    except ImportError as exc:
        raise VideoUnavailableError(f'a {suffix} video needs {FORMATS[suffix]}, which is not '
                                    f'installed ({exc}): {install}') from None
    return imageio


def import_mujoco_for_video():
    """The ``mujoco`` module, or VideoUnavailableError telling how to install it."""
    from gait_nodes.sim.mujoco_model import PhysicsUnavailableError, import_mujoco

    try:
        return import_mujoco()
    except PhysicsUnavailableError as exc:
        raise VideoUnavailableError(str(exc).replace('the physics simulator', 'the video')) \
            from None


def check_dependencies(path: str | Path) -> None:
    """Raise VideoUnavailableError (how to install it) if a video ``path`` cannot be made."""
    import_encoder(path)
    import_mujoco_for_video()


@dataclass(frozen=True)
class VideoSettings:
    """What the video shows and how.

    Attributes:
        fps: Frames per second of the video [Hz].
        width, height: Frame size [px] (even: H.264 in yuv420p halves the chroma).
        start_s: First frame's time from the walk's first base pose [s].
        end_s: Last frame's time at most, from the same origin [s]; None: the walk's end.
        speed: Playback speed (2: the video lasts half the walk).
    """

    fps: float = 15.0
    width: int = 640
    height: int = 480
    start_s: float = 0.0
    end_s: float | None = None
    speed: float = 1.0

    def __post_init__(self):
        def number(name, low, high, integer=False):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                    not math.isfinite(value) or not low <= value <= high or \
                    (integer and int(value) != value):
                kind = 'an integer' if integer else 'a number'
                raise VideoError(f'video {name} must be {kind} in [{low:g}, {high:g}], '
                                 f'got {value!r}')

        number('fps', 0.1, 240.0)
        number('width', 16, 4096, integer=True)
        number('height', 16, 4096, integer=True)
        number('start_s', 0.0, 1e7)
        number('speed', 0.01, 100.0)
        if self.end_s is not None:
            number('end_s', 0.0, 1e7)
            if self.end_s < self.start_s:
                raise VideoError(f'video end ({self.end_s:g} s) before its start '
                                 f'({self.start_s:g} s)')
        if self.width % 2 or self.height % 2:
            raise VideoError(f'video size must be even (H.264, yuv420p), got '
                             f'{self.width}x{self.height}')

    @property
    def frame_step_s(self) -> float:
        """Walk time between two frames [s]."""
        return self.speed / self.fps


def parse_size(text: str) -> tuple[int, int]:
    """``'640x480'`` -> ``(640, 480)``; VideoError otherwise."""
    try:
        width, height = (int(v) for v in text.lower().split('x'))
    except ValueError:
        raise VideoError(f'video size is WIDTHxHEIGHT in pixels (640x480), got {text!r}') \
            from None
    return width, height


def _last_at_or_before(stamps_ns: np.ndarray, t_ns: int) -> int:
    """Index of the last stamp at or before ``t_ns`` (the first one before them all)."""
    return max(int(np.searchsorted(stamps_ns, t_ns, side='right')) - 1, 0)


@dataclass
class RecordedWalk:
    """What a video draws, read from a bag (stamps [ns], positions in odom [m]).

    Attributes:
        robot: The robot's name (the bag's diagnostics' hardware_id) or None.
        base: (N, 8) stamp, position, quaternion (x, y, z, w) of ``odom -> base_link``.
        joint_names: Joints of /joint_states.
        joint_stamps_ns: (M,) their stamps.
        joint_positions: (M, J) [rad or m].
        points: ``{'zmp' | 'cop' | 'com': (K, 4) stamp, x, y, z}``.
        polygon_stamps_ns: (P,) stamps of the support polygons.
        polygons: P (V, 2) support polygons.
        polygon_heights_m: (P,) their planes' heights (the ZMP's at the same stamp, else 0).
        swings: Every landed swing (dicts of :func:`gait_nodes.bag.analysis.executed_swings`).
        plans: The footstep plans, in order.
    """

    robot: str | None
    base: np.ndarray
    joint_names: list[str]
    joint_stamps_ns: np.ndarray
    joint_positions: np.ndarray
    points: dict[str, np.ndarray]
    polygon_stamps_ns: np.ndarray
    polygons: list[np.ndarray]
    polygon_heights_m: np.ndarray
    swings: list[dict]
    plans: list

    @property
    def start_ns(self) -> int:
        """Stamp of the first base pose [ns]."""
        return int(self.base[0, 0])

    @property
    def duration_s(self) -> float:
        """From the first base pose to the last [s]."""
        return (self.base[-1, 0] - self.base[0, 0]) * 1e-9


def read_walk(path: str | Path, namespace: str | None = None) -> RecordedWalk:
    """The walk a bag holds (its base poses and joint states at least).

    Raises:
        NotABagError: The path is not a bag.
        VideoError: The bag has no base poses (/tf odom -> base_link) or no /joint_states.
    """
    from gait_nodes.bag.analysis import executed_swings, hardware_id, read_gait_series

    series = read_gait_series(path, namespace, topics=(
        '/tf', '/joint_states', '/gait/footsteps', '/gait/zmp', '/gait/cop', '/gait/com',
        '/gait/support_polygon', '/diagnostics'))
    joints = series.joints.get('/joint_states')
    if not series.base_poses or joints is None or not joints.stamps_ns:
        raise VideoError(f'{path}: no walk to draw: the video needs /tf (odom -> base_link) and '
                         f'/joint_states')
    base = np.array(sorted(series.base_poses), dtype=float)
    order = np.argsort(joints.stamps_ns, kind='stable')
    points = {}
    for name, samples in (('zmp', [(s, x, y, series.zmp_plane_heights_m.get(s, 0.0))
                                   for s, x, y in series.zmp]),
                          ('cop', series.cop), ('com', series.com)):
        array = np.array(sorted(samples), dtype=float).reshape(-1, 4)
        points[name] = array
    polygons = sorted(series.polygons, key=lambda p: p[0])
    stamps = np.array([s for s, _ in polygons], dtype=np.int64)
    heights = np.array([series.zmp_plane_heights_m.get(s, 0.0) for s in stamps.tolist()])
    return RecordedWalk(
        robot=hardware_id(series), base=base, joint_names=list(joints.names),
        joint_stamps_ns=np.array(joints.stamps_ns, dtype=np.int64)[order],
        joint_positions=np.array(joints.positions, dtype=float)[order],
        points=points, polygon_stamps_ns=stamps, polygons=[p for _, p in polygons],
        polygon_heights_m=heights, swings=executed_swings(series.plans, None),
        plans=list(series.plans))


def frame_times_s(walk: RecordedWalk, settings: VideoSettings) -> np.ndarray:
    """The frames' times from the walk's first base pose [s].

    Raises:
        VideoError: The range asked for starts after the walk's end.
    """
    end = walk.duration_s if settings.end_s is None else min(settings.end_s, walk.duration_s)
    if settings.start_s > end:
        raise VideoError(f'video start {settings.start_s:g} s is after the walk\'s end '
                         f'({walk.duration_s:.3f} s)')
    count = int(math.floor((end - settings.start_s) / settings.frame_step_s + 1e-9)) + 1
    return settings.start_s + settings.frame_step_s * np.arange(count)


class _Scene:
    """Adds geoms to a ``mujoco.MjvScene`` after ``mjv_updateScene`` (MuJoCo's decor geoms)."""

    def __init__(self, mujoco, scene):
        self.mujoco = mujoco
        self.scene = scene
        self._identity = np.eye(3).ravel()
        self._zero = np.zeros(3)

    def _next(self):
        scene = self.scene
        if scene.ngeom >= scene.maxgeom:
            return None
        geom = scene.geoms[scene.ngeom]
        scene.ngeom += 1
        return geom

    def add(self, kind, size, position, rgba, rotation: np.ndarray | None = None) -> None:
        """One geom of ``kind`` (``mjtGeom``), ``size`` as MuJoCo takes it."""
        geom = self._next()
        if geom is not None:
            self.mujoco.mjv_initGeom(geom, kind, np.asarray(size, dtype=float),
                                     np.asarray(position, dtype=float),
                                     self._identity if rotation is None else rotation.ravel(),
                                     np.asarray(rgba, dtype=np.float32))

    def segment(self, start, end, radius_m: float, rgba) -> None:
        """A capsule from ``start`` to ``end`` (3,) [m]."""
        geom = self._next()
        if geom is not None:
            capsule = self.mujoco.mjtGeom.mjGEOM_CAPSULE
            self.mujoco.mjv_initGeom(geom, capsule, self._zero, self._zero, self._identity,
                                     np.asarray(rgba, dtype=np.float32))
            self.mujoco.mjv_connector(geom, capsule, radius_m, np.asarray(start, dtype=float),
                                      np.asarray(end, dtype=float))


def _yaw_rotation(yaw_rad: float) -> np.ndarray:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class WalkRenderer:
    """Renders frames of a :class:`RecordedWalk` (see the module docstring).

    Args:
        walk: The walk.
        robot: The robot's model (:func:`gait_nodes.robot.model.load_robot_model`).
        settings: Size (fps, range and speed are the caller's, see :func:`frame_times_s`).
        staircase: The terrain the walk was on (None: flat).

    Raises:
        VideoUnavailableError: MuJoCo is not installed.
        VideoError: No OpenGL context could be made for rendering.
    """

    def __init__(self, walk: RecordedWalk, robot, settings: VideoSettings, staircase=None):
        from gait_nodes.sim.mujoco_model import FOOT_GROUP, load_physics_model

        mujoco = self.mujoco = import_mujoco_for_video()
        self.walk = walk
        description = robot.description
        physics = load_physics_model(description, robot.joint_names, staircase)
        model = self.model = physics.model
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, settings.width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, settings.height)
        model.vis.quality.offsamples = 4
        self.data = mujoco.MjData(model)
        try:
            self.renderer = mujoco.Renderer(model, settings.height, settings.width)
        except Exception as exc:  # the GL backends raise their own (ImportError, GLError...)
            raise VideoError(
                f'MuJoCo cannot render here ({type(exc).__name__}: {exc}). Without a display, '
                f'MUJOCO_GL=egl (libegl1 and Mesa, apt-get install libegl1 libgl1-mesa-dri) or '
                f'MUJOCO_GL=osmesa (apt-get install libosmesa6), set before Python starts')\
                from None
        self.option = mujoco.MjvOption()
        self.option.geomgroup[FOOT_GROUP] = 1
        # The feet see-through (their contact shapes, and the geometry of the foot frames'
        # links and of the links they hang from): the support polygon and the ZMP under a sole.
        feet = [model.body(name).id for name in physics.foot_bodies]
        feet += [int(model.body_parentid[b]) for b in feet]
        model.geom_rgba[np.isin(model.geom_bodyid, feet), 3] = FOOT_ALPHA
        # The bag's joints -> the model's qpos addresses (joints the model has not: ignored).
        self._qpos = [(k, int(model.jnt_qposadr[model.joint(name).id]))
                      for k, name in enumerate(walk.joint_names)
                      if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) >= 0]
        base = model.body(physics.base_body).id
        free = int(np.flatnonzero(model.jnt_bodyid == base)[0])
        self._base_qpos = int(model.jnt_qposadr[free])
        self.size_m, self._centre_above_base_m = self._robot_size_m()
        self._foot_index = {name: k for k, name in enumerate(robot.foot_names)}
        self._foot = description.physics.foot if description.physics is not None else None
        self._foot_radius_m = max(description.foot_radius_m, 0.01)
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.distance = 1.7 * self.size_m
        self.camera.azimuth = 125.0  # from the front left of a robot walking along +x
        self.camera.elevation = -35.0
        self._bodies = [(b, int(model.body_parentid[b])) for b in range(1, model.nbody)
                        if model.body_parentid[b] > 0]

    def _robot_size_m(self) -> tuple[float, float]:
        """``(size, middle)`` of the robot as it stands at the walk's start [m].

        The size is its height or the diagonal of its footprint, whichever is larger (at least
        0.2 m); the middle is the height of its bounding box's middle above the base.
        """
        model, data = self.model, self.data
        self._pose(self.walk.start_ns)
        robot = model.geom_bodyid > 0  # not the ground, not the stairs
        centres, radii = data.geom_xpos[robot], model.geom_rbound[robot][:, None]
        points = np.concatenate([data.xpos[1:], centres - radii, centres + radii])
        middle = 0.5 * (points[:, 2].min() + points[:, 2].max())
        extent = np.ptp(points, axis=0)
        size = max(float(np.hypot(extent[0], extent[1])), float(extent[2]), 0.2)
        return size, float(middle - self.walk.base[0, 3])

    # -- the state at a time -------------------------------------------------------------------

    def _pose(self, t_ns: int) -> None:
        walk, data = self.walk, self.data
        base = walk.base[_last_at_or_before(walk.base[:, 0], t_ns)]
        b = self._base_qpos
        data.qpos[b:b + 3] = base[1:4]
        data.qpos[b + 3:b + 7] = (base[7], base[4], base[5], base[6])  # w, x, y, z
        row = walk.joint_positions[_last_at_or_before(walk.joint_stamps_ns, t_ns)]
        for k, address in self._qpos:
            if k < len(row):
                data.qpos[address] = row[k]
        self.mujoco.mj_kinematics(self.model, data)
        self.mujoco.mj_camlight(self.model, data)

    def _look_at(self, t_ns: int) -> None:
        base = self.walk.base
        half = int(CAMERA_WINDOW_S * 0.5e9)
        lo, hi = np.searchsorted(base[:, 0], [t_ns - half, t_ns + half])
        window = base[lo:max(hi, lo + 1), 1:4]
        centre = window.mean(0)
        self.camera.lookat[:] = (centre[0], centre[1], centre[2] + self._centre_above_base_m)

    # -- what is drawn over the robot ----------------------------------------------------------

    def _skeleton(self, scene: _Scene) -> None:
        xpos = self.data.xpos
        radius = 0.012 * self.size_m
        for body, parent in self._bodies:
            if np.linalg.norm(xpos[body] - xpos[parent]) > 1e-3:
                scene.segment(xpos[parent], xpos[body], radius, SKELETON_RGBA)

    def _foothold(self, scene: _Scene, foot: str, position, yaw_rad: float,
                  alpha: float) -> None:
        mujoco = self.mujoco
        colour = (*FOOT_COLOURS[self._foot_index.get(foot, 0) % len(FOOT_COLOURS)], alpha)
        rotation = _yaw_rotation(yaw_rad)
        shape = self._foot
        z = position[2] + LIFT_M
        if shape is not None and shape.shape == 'box':
            centre = np.asarray(position) + rotation @ shape.centre_in_foot
            scene.add(mujoco.mjtGeom.mjGEOM_BOX,
                      (0.5 * shape.size_m[0], 0.5 * shape.size_m[1], FOOTHOLD_THICKNESS_M),
                      (centre[0], centre[1], z), colour, rotation)
        else:
            scene.add(mujoco.mjtGeom.mjGEOM_CYLINDER,
                      (self._foot_radius_m, FOOTHOLD_THICKNESS_M, 0.0),
                      (position[0], position[1], z), colour)

    def _footholds(self, scene: _Scene, t_ns: int) -> None:
        walk = self.walk
        plans = [plan for plan in walk.plans if plan.start_ns <= t_ns] or walk.plans[:1]
        if not plans:
            return
        first = plans[0]
        for f, foot in enumerate(first.foot_names):  # where the feet stood at the start
            self._foothold(scene, foot, first.positions_in_world[0, f],
                           float(first.yaws_rad[0, f]), LANDED_ALPHA)
        for swing in walk.swings:
            if swing['touch_down_ns'] <= t_ns:
                self._foothold(scene, swing['foot'], swing['end'], swing['end_yaw_rad'],
                               LANDED_ALPHA)
        current = plans[-1]
        for swing in current.swings():
            if current.start_ns + swing.touch_down_s * 1e9 > t_ns:
                self._foothold(scene, swing.foot, swing.end_in_world, swing.end_yaw_rad,
                               PLANNED_ALPHA)

    def _balance(self, scene: _Scene, t_ns: int) -> None:
        mujoco, walk = self.mujoco, self.walk
        if len(walk.polygons):
            k = _last_at_or_before(walk.polygon_stamps_ns, t_ns)
            if walk.polygon_stamps_ns[k] <= t_ns:
                polygon = walk.polygons[k]
                z = walk.polygon_heights_m[k] + 2 * LIFT_M
                for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
                    scene.segment((a[0], a[1], z), (b[0], b[1], z), 0.004 * self.size_m,
                                  POLYGON_RGBA)
        radius = 0.02 * self.size_m
        sphere = mujoco.mjtGeom.mjGEOM_SPHERE
        for name, rgba in (('zmp', ZMP_RGBA), ('cop', COP_RGBA), ('com', COM_RGBA)):
            samples = walk.points[name]
            if not len(samples):
                continue
            k = _last_at_or_before(samples[:, 0], t_ns)
            if samples[k, 0] > t_ns or not np.isfinite(samples[k, 1:]).all():
                continue
            x, y, z = samples[k, 1:]
            if name == 'com':
                ground = walk.points['zmp'][_last_at_or_before(walk.points['zmp'][:, 0],
                                                               t_ns), 3] \
                    if len(walk.points['zmp']) else 0.0
                scene.segment((x, y, z), (x, y, ground + LIFT_M), 0.003 * self.size_m, rgba)
                scene.add(sphere, (radius, 0, 0), (x, y, z), rgba)
            else:
                scene.add(sphere, (radius, 0, 0), (x, y, z + LIFT_M), rgba)

    def frame(self, t_s: float) -> np.ndarray:
        """(height, width, 3) uint8 image of the walk at ``t_s`` from its first base pose."""
        t_ns = self.walk.start_ns + int(round(t_s * 1e9))
        self._pose(t_ns)
        self._look_at(t_ns)
        self.renderer.update_scene(self.data, self.camera, self.option)
        scene = _Scene(self.mujoco, self.renderer.scene)
        self._skeleton(scene)
        self._footholds(scene, t_ns)
        self._balance(scene, t_ns)
        return self.renderer.render()

    def close(self) -> None:
        """Free the renderer's OpenGL context."""
        self.renderer.close()


def render_frames(walk: RecordedWalk, robot, settings: VideoSettings, staircase=None
                  ) -> Iterator[np.ndarray]:
    """The video's frames, one image (height, width, 3) each (see :func:`frame_times_s`)."""
    times = frame_times_s(walk, settings)
    renderer = WalkRenderer(walk, robot, settings, staircase)
    try:
        for t_s in times.tolist():
            yield renderer.frame(t_s)
    finally:
        renderer.close()


@dataclass(frozen=True)
class VideoReport:
    """What :func:`write_video` wrote.

    Attributes:
        path: The video file.
        frames: Number of frames.
        width, height: Frame size [px].
        fps: Frames per second [Hz].
        start_s, end_s: Walk time of the first and last frames, from its first base pose [s].
        wall_s: Time taken [s].
    """

    path: str
    frames: int
    width: int
    height: int
    fps: float
    start_s: float
    end_s: float
    wall_s: float

    def describe(self) -> str:
        """One line for a person."""
        return (f'{self.path}: {self.frames} frames {self.width}x{self.height} at {self.fps:g} '
                f'fps, walk {self.start_s:.2f}-{self.end_s:.2f} s, rendered in '
                f'{self.wall_s:.1f} s')


def write_video(bag: str | Path, output: str | Path, settings: VideoSettings | None = None,
                robot: str | None = None, staircase=None, namespace: str | None = None,
                progress: Callable[[int], None] | None = None) -> VideoReport:
    """Render the walk of ``bag`` into ``output`` (``.mp4``, ``.gif``, or a ``.png`` still).

    Args:
        bag: Bag directory or ``.mcap`` file.
        output: The video file (its suffix chooses the format); overwritten.
        settings: Frame rate, size, range, speed.
        robot: Robot name or YAML (default: the bag's diagnostics' hardware_id).
        staircase: The terrain (:class:`gait_nodes.planning.terrain.Staircase`; None: flat).
        namespace: The graph's ROS namespace in the bag (default: found from its topics).
        progress: Called with 1 for every frame written.

    Raises:
        VideoUnavailableError: MuJoCo, imageio or the format's encoder is not installed.
        VideoError: Bad settings, a bag without a walk, no robot, no OpenGL.
        NotABagError: ``bag`` is not a bag.
        OSError: The video cannot be written.
    """
    import time

    from gait_nodes.robot.model import load_robot_model

    settings = settings or VideoSettings()
    started = time.perf_counter()
    imageio = import_encoder(output)
    import_mujoco_for_video()
    walk = read_walk(bag, namespace)
    name = robot or walk.robot
    if not name:
        raise VideoError(f'{bag}: the bag does not name its robot (no /diagnostics): give it '
                         f'(--robot NAME)')
    model = load_robot_model(name)
    output = Path(output)
    still = output.suffix.lower() == '.png'
    if still:  # the frame at start_s
        settings = dataclasses.replace(settings, end_s=settings.start_s)
    times = frame_times_s(walk, settings)
    if still:
        (image,) = render_frames(walk, model, settings, staircase)
        imageio.imwrite(output, image)
        return VideoReport(str(output), 1, settings.width, settings.height, settings.fps,
                           float(times[0]), float(times[0]), time.perf_counter() - started)
    if output.suffix.lower() == '.mp4':
        writer = imageio.get_writer(output, format='FFMPEG', mode='I', fps=settings.fps,
                                    codec='libx264', pixelformat='yuv420p', quality=7,
                                    macro_block_size=2)
    else:
        writer = imageio.get_writer(output, format='GIF', mode='I',
                                    duration=1000.0 / settings.fps, loop=0)
    frames = 0
    with writer:
        for image in render_frames(walk, model, settings, staircase):
            writer.append_data(image)
            frames += 1
            if progress is not None:
                progress(1)
    return VideoReport(str(output), frames, settings.width, settings.height, settings.fps,
                       float(times[0]), float(times[-1]), time.perf_counter() - started)
