"""Robot YAML: what the gait needs to know about a robot beyond its URDF.

A robot is ``config/robots/<name>.yaml`` plus the URDF it names. The YAML is read here, without
Pinocchio, into a frozen :class:`RobotDescription` that the planner and every node can trust;
:mod:`gait_nodes.robot.model` loads the URDF into Pinocchio and checks the names against it.

Format (lengths in metres, angles in radians, in the base frame: x forward, y left, z up)::

    name: robosimian
    description: free text (say where the numbers come from)
    urdf: robosimian.urdf        # relative to the YAML, absolute, or
                                 # example-robot-data:go2_description/urdf/go2.urdf
    kind: quadruped              # quadruped | biped
    gaits: [crawl, trot]         # gaits the robot can do (biped: [biped])
    base_frame: base_link
    feet:                        # ordered; quadrupeds: front_left, front_right,
                                 # rear_left, rear_right
      front_left:
        frame: fl_foot           # URDF frame at the sole contact point
        joints: [fl_joint_1, ...]  # the limb's joints, base to foot
        nominal_position_m: [0.45, 0.55, -0.65]  # foot at standstill, in the base frame
      ...
    foot_radius_m: 0.055         # each foot is a disc of this radius on the ground
    body_height_m: 0.65          # base origin above the ground at standstill
    com_height_m: 0.60           # COM above the ground at standstill (preview control's zc)
    com_xy_m: [0.0, 0.0]         # optional: the COM at standstill, in the base frame (where a
                                 # standing robot's ZMP is; default: the stance's centre)
    joint_velocity_limit_rad_s: 1.0      # every joint unless listed below
    joint_velocity_limits_rad_s: {}      # joint -> limit, overrides
    joint_acceleration_limit_rad_s2: 20.0   # every joint unless listed below (required)
    joint_acceleration_limits_rad_s2: {}    # joint -> limit, overrides
    reach:
      max_step_length_m: 0.5     # longest step along x a foot can make
      max_step_width_m: 0.2      # largest sideways displacement of a foot in one step
      max_turn_rad: 0.35         # largest yaw change of the body per gait cycle
    gait_stances:                # optional, quadrupeds: a gait's own stance, walked instead
      static_crawl:              # of the nominal one and reach.max_step_length_m
        front_x_m: 0.58          # front feet ahead of the base, rear feet behind it (y and z
        rear_x_m: 0.54           # stay the nominal ones); the robot stands at the nominal
                                 # stance and its first steps go there
        max_step_length_m: 0.3   # the gait's longest step (optional: reach's)
    extra: {}                    # robot-specific settings (e.g. ik families), free form
    physics:                     # the physics simulator's model (optional; see below)
      joint_stiffness_nm_per_rad: 3000.0   # every joint's position gain kp [N m/rad]
      joint_damping_nm_s_per_rad: 100.0    # its velocity gain kd [N m s/rad]
      joint_armature_kg_m2: 0.1            # rotor inertia seen at the joint [kg m^2]
      foot_friction: 1.0                   # sliding friction of the feet on the ground
      foot:                                # the feet's contact geometry, in the foot frame
        shape: cylinder                    # cylinder (a disc) | sphere | box
        size_m: [0.055, 0.02]              # cylinder: radius, height; sphere: radius;
                                           # box: length x, width y, height z
        centre_m: [0.0, 0.0, 0.01]         # centre of the shape in the foot frame

Without ``physics.foot`` a foot is what the rest of the YAML says it is: a sphere of radius
``extra.foot_frame_height_m`` centred on the foot frame when that is given (the frame at the
centre of a point foot), else a disc of ``foot_radius_m`` whose bottom face is the foot frame's
xy plane (the frame at the sole). The gains have no default: a robot that walks in physics says
which gains its joints have, and why, in its YAML.

Every error names the file and the offending key with the allowed values.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from gait_nodes.errors import ConfigError
from gait_nodes.geometry import disc_support_margin
from gait_nodes.paths import data_dir

KINDS = ('quadruped', 'biped')
GAITS_BY_KIND = {'quadruped': ('crawl', 'static_crawl', 'trot'), 'biped': ('biped',)}
EXAMPLE_ROBOT_DATA_PREFIX = 'example-robot-data:'
#: Largest joint velocity limit a robot YAML may give [rad/s or m/s].
MAX_VELOCITY_RAD_S = 100.0
#: Largest joint acceleration limit a robot YAML may give [rad/s^2 or m/s^2].
MAX_ACCELERATION_RAD_S2 = 10000.0
#: Foot shapes of the physics model -> the number of ``size_m`` values each takes.
FOOT_SHAPES = {'cylinder': 2, 'sphere': 1, 'box': 3}
#: Thickness of a foot disc when the YAML gives its radius only [m].
DEFAULT_DISC_HEIGHT_M = 0.02


@dataclass(frozen=True)
class Foot:
    """One foot (end of a limb) of the robot.

    Attributes:
        name: Foot name used on the topics (``joint_names`` of /gait/footsteps).
        frame: URDF frame at the contact point.
        joints: The limb's joint names, base to foot.
        nominal_position_in_base: (3,) foot position at standstill, in the base frame [m].
    """

    name: str
    frame: str
    joints: tuple[str, ...]
    nominal_position_in_base: np.ndarray


@dataclass(frozen=True)
class Reach:
    """How far the feet can go per step (checked by the footstep planner).

    Attributes:
        max_step_length_m: Longest foot displacement along x in one step [m].
        max_step_width_m: Largest foot displacement along y in one step [m].
        max_turn_rad: Largest body yaw change per gait cycle [rad].
    """

    max_step_length_m: float
    max_step_width_m: float
    max_turn_rad: float


@dataclass(frozen=True)
class GaitStance:
    """A gait's own stance (``gait_stances`` in the robot YAML).

    Attributes:
        front_x_m: The front feet's place ahead of the base [m].
        rear_x_m: The rear feet's place behind the base [m].
        max_step_length_m: The gait's longest step along x [m] (None: the reach's).
    """

    front_x_m: float
    rear_x_m: float
    max_step_length_m: float | None = None


@dataclass(frozen=True)
class FootShape:
    """The contact geometry of every foot in the physics model, in the foot frame.

    Attributes:
        shape: ``cylinder`` (a disc, axis along the frame's z), ``sphere`` or ``box``.
        size_m: cylinder: (radius, height); sphere: (radius,); box: (x, y, z) edge lengths [m].
        centre_in_foot: (3,) centre of the shape in the foot frame [m].
    """

    shape: str
    size_m: tuple[float, ...]
    centre_in_foot: np.ndarray


@dataclass(frozen=True)
class PhysicsDescription:
    """How the physics simulator models the robot beyond its URDF (``physics`` in the YAML).

    The joints are position-controlled as a ros2_control position interface drives them: a
    PD law ``tau = kp (q_ref - q) + kd (qd_ref - qd)``, clamped at the URDF's effort limit.

    Attributes:
        joint_stiffness_nm_per_rad: kp of every joint [N m/rad] (N/m for a prismatic joint).
        joint_damping_nm_s_per_rad: kd of every joint [N m s/rad].
        joint_armature_kg_m2: Rotor inertia reflected through the gearbox [kg m^2].
        foot_friction: Coulomb friction coefficient of the feet on the ground.
        foot: Every foot's contact shape.
    """

    joint_stiffness_nm_per_rad: float
    joint_damping_nm_s_per_rad: float
    joint_armature_kg_m2: float
    foot_friction: float
    foot: FootShape


@dataclass(frozen=True)
class RobotDescription:
    """A robot YAML, validated. See the module docstring for the meaning of each field."""

    name: str
    path: Path
    urdf_path: Path
    kind: str
    gaits: tuple[str, ...]
    base_frame: str
    feet: tuple[Foot, ...]
    foot_radius_m: float
    body_height_m: float
    com_height_m: float
    joint_velocity_limit_rad_s: float
    joint_velocity_limits_rad_s: Mapping[str, float]
    joint_acceleration_limit_rad_s2: float
    joint_acceleration_limits_rad_s2: Mapping[str, float]
    reach: Reach
    description: str = ''
    extra: Mapping[str, object] = field(default_factory=dict)
    physics: PhysicsDescription | None = None
    gait_stances: Mapping[str, GaitStance] = field(default_factory=dict)
    com_xy_m: np.ndarray | None = None

    @property
    def foot_names(self) -> tuple[str, ...]:
        """Foot names in YAML order."""
        return tuple(foot.name for foot in self.feet)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Every limb joint, foot by foot, in YAML order."""
        return tuple(joint for foot in self.feet for joint in foot.joints)

    def foot(self, name: str) -> Foot:
        """The foot called ``name``; ConfigError listing the valid names otherwise."""
        for foot in self.feet:
            if foot.name == name:
                return foot
        raise ConfigError(f'{self.name} has no foot {name!r}; feet: {list(self.foot_names)}')

    def velocity_limit_rad_s(self, joint: str) -> float:
        """Velocity limit of ``joint`` [rad/s]."""
        return float(self.joint_velocity_limits_rad_s.get(joint, self.joint_velocity_limit_rad_s))

    def acceleration_limit_rad_s2(self, joint: str) -> float:
        """Acceleration limit of ``joint`` [rad/s^2] (what its actuator can do, both ways)."""
        return float(self.joint_acceleration_limits_rad_s2.get(
            joint, self.joint_acceleration_limit_rad_s2))

    @property
    def sole_extent_x_m(self) -> tuple[float, float]:
        """How far a foot reaches behind and ahead of its foot frame along the foot's x [m].

        The larger of the planner's disc (``foot_radius_m``) and the contact shape the YAML gives
        the foot (``physics.foot``): the biped's sole box reaches 0.12 m ahead of its sole frame
        and 0.08 m behind, where its 0.05 m disc says 0.05 m both ways. The footholds keep their
        distance from stair edges with it (:mod:`gait_nodes.planning.terrain`).
        """
        behind = ahead = self.foot_radius_m
        if self.physics is not None:
            foot = self.physics.foot
            half = foot.size_m[0] if foot.shape != 'box' else 0.5 * foot.size_m[0]
            centre = float(foot.centre_in_foot[0])
            behind, ahead = max(behind, half - centre), max(ahead, half + centre)
        return float(behind), float(ahead)

    def nominal_stance_in_base(self, gait: str | None = None) -> np.ndarray:
        """(F, 3) nominal foot positions in the base frame [m]: ``gait``'s own, if it has one.

        A gait of ``gait_stances`` puts the front feet (x above the feet's mean) its
        ``front_x_m`` ahead of the base and the rear ones ``rear_x_m`` behind.
        """
        stance = np.array([foot.nominal_position_in_base for foot in self.feet])
        if gait in self.gait_stances:
            own = self.gait_stances[gait]
            front = stance[:, 0] > stance[:, 0].mean()
            stance[:, 0] = np.where(front, own.front_x_m, -own.rear_x_m)
        return stance

    def max_step_length_m(self, gait: str | None = None) -> float:
        """Longest step along x [m]: ``gait``'s own (``gait_stances``), else the reach's."""
        own = self.gait_stances.get(gait)
        if own is not None and own.max_step_length_m is not None:
            return own.max_step_length_m
        return self.reach.max_step_length_m

    @property
    def longest_step_m(self) -> float:
        """Longest step along x of any of the robot's gaits [m]."""
        return max(self.max_step_length_m(gait) for gait in (None, *self.gaits))


def robots_dir() -> Path:
    """The shipped robot folder (``config/robots``)."""
    return Path(data_dir('config')) / 'robots'


def available_robots() -> list[str]:
    """Names of the shipped robots."""
    folder = robots_dir()
    return sorted(p.stem for p in folder.glob('*.yaml')) if folder.is_dir() else []


def robot_yaml_path(name_or_path: str | os.PathLike) -> Path:
    """Path of a robot YAML given a shipped robot name or a file path."""
    text = os.fspath(name_or_path)
    if text.endswith(('.yaml', '.yml')) or os.sep in text:
        path = Path(text)
        if not path.is_file():
            raise ConfigError(f'{path}: robot YAML not found')
        return path
    path = robots_dir() / f'{text}.yaml'
    if not path.is_file():
        raise ConfigError(f'unknown robot {text!r}; shipped robots: {available_robots()} '
                          f'(or give the path of a robot YAML)')
    return path


def example_robot_data_dir() -> Path:
    """The ``robots`` folder of the example-robot-data package (an optional extra).

    ``EXAMPLE_ROBOT_DATA_MODEL_DIR`` (the variable example-robot-data itself honours) wins;
    otherwise the folder its cmeel wheel installs under ``<site-packages>/cmeel.prefix/share``.
    """
    import sysconfig

    override = os.environ.get('EXAMPLE_ROBOT_DATA_MODEL_DIR')
    candidates = [Path(override)] if override else []
    for key in ('purelib', 'platlib'):
        candidates.append(Path(sysconfig.get_paths()[key]) / 'cmeel.prefix' / 'share'
                          / 'example-robot-data' / 'robots')
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    raise ConfigError('this robot needs the example-robot-data package: pip install '
                      '"gait_nodes[robots]" (or GAIT_NODES_ROBOTS=1 sh tools/venv.sh)')


def _resolve_urdf(yaml_path: Path, text: str) -> Path:
    if text.startswith(EXAMPLE_ROBOT_DATA_PREFIX):
        path = example_robot_data_dir() / text[len(EXAMPLE_ROBOT_DATA_PREFIX):]
    else:
        path = Path(text) if os.path.isabs(text) else yaml_path.parent / text
    if not path.is_file():
        raise ConfigError(f'{yaml_path}: urdf {text!r} not found (looked at {path})')
    return path


def write_at_joint_velocity_limit(name_or_path: str | os.PathLike,
                                  joint_velocity_limit_rad_s: float,
                                  directory: str | os.PathLike) -> Path:
    """A copy of a robot YAML whose joints are limited to ``joint_velocity_limit_rad_s``.

    For walking the same robot at another limit (the walked crossover, thesis Fig. 21): the
    copy is written into ``directory`` as ``<name>_w<limit>.yaml``, its URDF named by absolute
    path (or example-robot-data's, as it was) and any per-joint limits scaled in proportion. A
    value table does not depend on the limits but through its time scale, so the copy shares
    the original's cached tables (:func:`gait_nodes.swing.cache.robot_digest`).

    Returns:
        The path of the copy (a valid robot YAML; give it wherever a robot name goes).

    Raises:
        ConfigError: The robot YAML is not valid, or the limit is not in (0, 100] rad/s.
    """
    description = load_robot_description(name_or_path)
    limit = joint_velocity_limit_rad_s
    if isinstance(limit, bool) or not isinstance(limit, (int, float)) or \
            not 0.0 < limit <= MAX_VELOCITY_RAD_S:
        raise ConfigError(f'joint velocity limit must be in (0, {MAX_VELOCITY_RAD_S:g}] rad/s, '
                          f'got {limit!r}')
    data = yaml.safe_load(description.path.read_text())
    factor = float(limit) / description.joint_velocity_limit_rad_s
    data['description'] = (f'{description.name} with its joints limited to {float(limit):g} '
                           f'rad/s, a copy of {description.path}: {data.get("description", "")}')
    data['joint_velocity_limit_rad_s'] = float(limit)
    if data.get('joint_velocity_limits_rad_s'):
        data['joint_velocity_limits_rad_s'] = {
            joint: float(value) * factor
            for joint, value in data['joint_velocity_limits_rad_s'].items()}
    if not str(data['urdf']).startswith(EXAMPLE_ROBOT_DATA_PREFIX):
        data['urdf'] = str(description.urdf_path.resolve())
    path = Path(directory) / f'{description.name}_w{float(limit):g}.yaml'
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    load_robot_description(path)  # the copy is checked as any robot YAML
    return path


class _Reader:
    """Typed access to a YAML mapping whose errors name the file and the key."""

    def __init__(self, path: Path, data: Mapping, where: str = ''):
        self.path, self.data, self.where = path, data, where

    def _name(self, key: str) -> str:
        return f'{self.where}{key}'

    def fail(self, key: str, problem: str):
        raise ConfigError(f'{self.path}: {self._name(key)}: {problem}')

    def get(self, key: str, default=None, required: bool = True):
        if key not in self.data:
            if required and default is None:
                self.fail(key, 'missing')
            return default
        return self.data[key]

    def string(self, key: str, default: str | None = None) -> str:
        value = self.get(key, default)
        if not isinstance(value, str) or not value:
            self.fail(key, f'must be a non-empty string, got {value!r}')
        return value

    def number(self, key: str, low: float, high: float, default: float | None = None) -> float:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value) or not low < value <= high:
            self.fail(key, f'must be a number in ({low}, {high}], got {value!r}')
        return float(value)

    def mapping(self, key: str, default: Mapping | None = None) -> _Reader:
        value = self.get(key, default)
        if not isinstance(value, Mapping):
            self.fail(key, f'must be a mapping, got {type(value).__name__}')
        return _Reader(self.path, value, f'{self._name(key)}.')

    def names(self, key: str) -> tuple[str, ...]:
        value = self.get(key)
        if not isinstance(value, list) or not value \
                or not all(isinstance(v, str) and v for v in value):
            self.fail(key, f'must be a non-empty list of names, got {value!r}')
        if len(set(value)) != len(value):
            self.fail(key, f'names repeat: {value}')
        return tuple(value)

    def vector(self, key: str, size: int) -> np.ndarray:
        value = self.get(key)
        if not isinstance(value, list) or len(value) != size or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value):
            self.fail(key, f'must be a list of {size} finite numbers, got {value!r}')
        array = np.array(value, dtype=float)
        array.setflags(write=False)
        return array


def _per_joint(top: _Reader, key: str, all_joints: list[str], high: float) -> dict[str, float]:
    """The optional ``joint -> limit`` overrides under ``key``, each in (0, ``high``]."""
    reader = top.mapping(key, default={})
    limits = {}
    for joint in reader.data:
        if joint not in all_joints:
            reader.fail(str(joint), f'not a limb joint; limb joints: {all_joints}')
        limits[str(joint)] = reader.number(joint, 0.0, high)
    return limits


def load_robot_description(name_or_path: str | os.PathLike) -> RobotDescription:
    """Read and validate a robot YAML (a shipped name such as ``robosimian``, or a path).

    Raises:
        ConfigError: The file is missing or unreadable, or a key is missing or out of range;
            the message names the file, the key and the allowed values.
    """
    path = robot_yaml_path(name_or_path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f'{path}: cannot read robot YAML: {exc}'.splitlines()[0]) from exc
    if not isinstance(data, Mapping):
        raise ConfigError(f'{path}: a robot YAML must be a mapping at the top level')
    top = _Reader(path, data)
    known = {'name', 'description', 'urdf', 'kind', 'gaits', 'base_frame', 'feet',
             'foot_radius_m', 'body_height_m', 'com_height_m', 'com_xy_m',
             'joint_velocity_limit_rad_s',
             'joint_velocity_limits_rad_s', 'joint_acceleration_limit_rad_s2',
             'joint_acceleration_limits_rad_s2', 'reach', 'gait_stances', 'extra', 'physics'}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f'{path}: unknown keys {unknown}; allowed: {sorted(known)}')

    kind = top.string('kind')
    if kind not in KINDS:
        top.fail('kind', f'must be one of {list(KINDS)}, got {kind!r}')
    gaits = top.names('gaits')
    bad_gaits = [g for g in gaits if g not in GAITS_BY_KIND[kind]]
    if bad_gaits:
        top.fail('gaits', f'{bad_gaits} not possible for a {kind}; allowed: '
                          f'{list(GAITS_BY_KIND[kind])}')

    feet_reader = top.mapping('feet')
    expected_feet = 4 if kind == 'quadruped' else 2
    if len(feet_reader.data) != expected_feet:
        top.fail('feet', f'a {kind} has {expected_feet} feet, got {len(feet_reader.data)}')
    feet = []
    for foot_name in feet_reader.data:
        foot = feet_reader.mapping(foot_name)
        feet.append(Foot(name=str(foot_name), frame=foot.string('frame'),
                         joints=foot.names('joints'),
                         nominal_position_in_base=foot.vector('nominal_position_m', 3)))
    all_joints = [j for foot in feet for j in foot.joints]
    if len(set(all_joints)) != len(all_joints):
        top.fail('feet', 'a joint belongs to more than one limb')

    limits = _per_joint(top, 'joint_velocity_limits_rad_s', all_joints, MAX_VELOCITY_RAD_S)
    acceleration_limits = _per_joint(top, 'joint_acceleration_limits_rad_s2', all_joints,
                                     MAX_ACCELERATION_RAD_S2)

    reach_reader = top.mapping('reach')
    reach = Reach(max_step_length_m=reach_reader.number('max_step_length_m', 0.0, 5.0),
                  max_step_width_m=reach_reader.number('max_step_width_m', 0.0, 5.0),
                  max_turn_rad=reach_reader.number('max_turn_rad', 0.0, math.pi))
    extra = top.get('extra', {}, required=False)
    if not isinstance(extra, Mapping):
        top.fail('extra', 'must be a mapping')

    description = RobotDescription(
        name=top.string('name'),
        path=path,
        urdf_path=_resolve_urdf(path, top.string('urdf')),
        kind=kind,
        gaits=gaits,
        base_frame=top.string('base_frame'),
        feet=tuple(feet),
        foot_radius_m=top.number('foot_radius_m', 0.0, 0.5),
        body_height_m=top.number('body_height_m', 0.0, 5.0),
        com_height_m=top.number('com_height_m', 0.0, 5.0),
        joint_velocity_limit_rad_s=top.number('joint_velocity_limit_rad_s', 0.0,
                                              MAX_VELOCITY_RAD_S),
        joint_velocity_limits_rad_s=limits,
        joint_acceleration_limit_rad_s2=top.number('joint_acceleration_limit_rad_s2', 0.0,
                                                   MAX_ACCELERATION_RAD_S2),
        joint_acceleration_limits_rad_s2=acceleration_limits,
        reach=reach,
        description=str(top.get('description', '', required=False)),
        extra=dict(extra),
        physics=_physics(top, extra, top.number('foot_radius_m', 0.0, 0.5))
        if 'physics' in data else None,
        gait_stances=_gait_stances(top, kind, gaits),
        com_xy_m=top.vector('com_xy_m', 2) if 'com_xy_m' in data else None,
    )
    if description.com_xy_m is not None and kind == 'quadruped':
        feet_xy = description.nominal_stance_in_base()[:, :2]
        if disc_support_margin(description.com_xy_m.reshape(1, 2), feet_xy, 0.0)[0] <= 0.0:
            top.fail('com_xy_m', f'the COM at standstill must lie between the nominal feet '
                                 f'{feet_xy.tolist()}, got {description.com_xy_m.tolist()}')
    for foot in description.feet:
        if foot.nominal_position_in_base[2] >= 0:
            z = foot.nominal_position_in_base[2]
            raise ConfigError(f'{path}: feet.{foot.name}.nominal_position_m: the foot must be '
                              f'below the base (z < 0), got z = {z}')
    return description


def _gait_stances(top: _Reader, kind: str, gaits: tuple[str, ...]
                  ) -> dict[str, GaitStance]:
    """``gait_stances``, validated."""
    if 'gait_stances' not in top.data:
        return {}
    stances = top.mapping('gait_stances')
    if kind != 'quadruped':
        top.fail('gait_stances', f'a {kind} has no front and rear feet to place')
    result = {}
    for gait in stances.data:
        if gait not in gaits:
            stances.fail(str(gait), f'is not one of the robot\'s gaits {list(gaits)}')
        stance = stances.mapping(str(gait))
        keys = ['front_x_m', 'max_step_length_m', 'rear_x_m']
        unknown = sorted(set(stance.data) - set(keys))
        if unknown:
            stances.fail(str(gait), f'unknown keys {unknown}; allowed: {keys}')
        longest = (stance.number('max_step_length_m', 0.0, 5.0)
                   if 'max_step_length_m' in stance.data else None)
        result[str(gait)] = GaitStance(stance.number('front_x_m', 0.0, 5.0),
                                       stance.number('rear_x_m', 0.0, 5.0), longest)
    return result


def _foot_shape(physics: _Reader, extra: Mapping, foot_radius_m: float) -> FootShape:
    """``physics.foot``, or the foot the rest of the YAML describes (module docstring)."""
    if 'foot' not in physics.data:
        sphere_radius = extra.get('foot_frame_height_m')
        if isinstance(sphere_radius, (int, float)) and not isinstance(sphere_radius, bool) \
                and 0 < sphere_radius <= 0.5:
            return FootShape('sphere', (float(sphere_radius),), np.zeros(3))
        return FootShape('cylinder', (foot_radius_m, DEFAULT_DISC_HEIGHT_M),
                         np.array([0.0, 0.0, 0.5 * DEFAULT_DISC_HEIGHT_M]))
    foot = physics.mapping('foot')
    shape = foot.string('shape')
    if shape not in FOOT_SHAPES:
        foot.fail('shape', f'must be one of {list(FOOT_SHAPES)}, got {shape!r}')
    size = foot.vector('size_m', FOOT_SHAPES[shape])
    if not np.all(size > 0):
        foot.fail('size_m', f'every size must be > 0 m, got {size.tolist()}')
    return FootShape(shape, tuple(size.tolist()), foot.vector('centre_m', 3))


def _physics(top: _Reader, extra: Mapping, foot_radius_m: float) -> PhysicsDescription:
    """The ``physics`` section, validated."""
    physics = top.mapping('physics')
    known = {'joint_stiffness_nm_per_rad', 'joint_damping_nm_s_per_rad',
             'joint_armature_kg_m2', 'foot_friction', 'foot'}
    unknown = sorted(set(physics.data) - known)
    if unknown:
        top.fail('physics', f'unknown keys {unknown}; allowed: {sorted(known)}')
    return PhysicsDescription(
        joint_stiffness_nm_per_rad=physics.number('joint_stiffness_nm_per_rad', 0.0, 1e7),
        joint_damping_nm_s_per_rad=physics.number('joint_damping_nm_s_per_rad', 0.0, 1e6),
        joint_armature_kg_m2=physics.number('joint_armature_kg_m2', 0.0, 1e3),
        foot_friction=physics.number('foot_friction', 0.0, 10.0),
        foot=_foot_shape(physics, extra, foot_radius_m))
