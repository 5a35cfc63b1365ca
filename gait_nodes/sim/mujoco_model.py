"""The MuJoCo model of a robot, built from its URDF and its robot YAML at start (never by hand).

MuJoCo's own URDF compiler reads the URDF (:meth:`mujoco.MjSpec.from_string`); this module adds
what a URDF does not say, all of it from the robot YAML's ``physics`` section
(:class:`gait_nodes.robot.description.PhysicsDescription`) and the terrain:

- a free joint on the root link (the floating base);
- the feet's contact shapes on the foot frames (disc, sphere or sole box), with the YAML's
  friction; the URDF's own geometry, visual and collision, is kept for display only (it
  collides with nothing and weighs nothing; meshes MuJoCo cannot decode, such as COLLADA
  ``.dae``, are left out), and the feet collide with the ground only, not with each other;
- a floor plane at z = 0 (a checker texture, 0.5 m squares, so that a video shows the robot
  moving) and, with a staircase (:class:`gait_nodes.planning.terrain.Staircase`),
  one box per stair up to the stair's tread height, reaching ``STAIRS_LENGTH_M`` past its riser;
- per 1-DOF joint, a position-controlled actuator as a ros2_control position interface drives
  it: ``tau = kp (q_ref - q) + kd (qd_ref - qd)`` (one MuJoCo ``general`` actuator with an
  affine bias, fed ``ctrl = q_ref + kd / kp qd_ref``), its force clamped at the URDF's effort
  limit, the joint's armature (rotor inertia) from the YAML (the URDF's own joint damping and
  friction, where it gives any, are kept);
- one directional light from above (for rendering: :mod:`gait_nodes.bag.video`);
- 1 kHz steps by default, MuJoCo's ``implicitfast`` integrator (the actuators' damping is
  integrated implicitly, as stiff PD gains need) and elliptic friction cones.

The URDF's inertias are used as they are (``inertiafromgeom`` off: display geometry weighs
nothing); links joined by fixed joints stay bodies (``fusestatic`` off), so that every foot frame
is a body whose pose MuJoCo reports. ``package://`` mesh URIs are resolved under the share folders
of the installed packages (example-robot-data's, ``AMENT_PREFIX_PATH``'s); a mesh that cannot be
found or decoded is left out of the display geometry. Nothing added for display (geometry,
texture, light) changes the dynamics.

The compiled model is cached in ``$XDG_CACHE_HOME/gait_nodes/physics/`` (as the swing value
tables are), one ``.mjb`` (MuJoCo's exact binary model, what the simulator runs) and its ``.xml``
(the MJCF, to read or open: ``python -m mujoco.viewer --mjcf=FILE``) per URDF, robot YAML,
staircase, timestep, builder and MuJoCo version.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gait_nodes.errors import ConfigError, GaitNodesError
from gait_nodes.planning.terrain import Staircase
from gait_nodes.robot.description import RobotDescription

#: Changes whenever the model this module builds changes (part of the cache key).
BUILDER_VERSION = '2'
#: Default physics step [s] (1 kHz, a legged robot's joint servo rate).
DEFAULT_TIMESTEP_S = 0.001
#: How far each stair reaches past its riser [m]: the landing, to walk on for long.
STAIRS_LENGTH_M = 50.0
#: Width of the stairs along y [m] (they span every y the walks reach).
STAIRS_WIDTH_M = 50.0
#: Ratio of frictional to normal constraint impedance: 100 makes static friction hold (at 1
#: the soft friction lets a loaded foot creep a few mm per second, at 10 about 1 mm/s).
IMPRATIO = 100.0
#: Collision bits: the feet (contype) against the ground (conaffinity), nothing else.
FOOT_CONTYPE, GROUND_CONAFFINITY = 1, 1
#: MuJoCo geom group of the feet's contact shapes and of the URDF's display geometry.
FOOT_GROUP, DISPLAY_GROUP = 3, 1
#: MuJoCo's ``<mujoco>`` extension of the URDF: keep fixed links as bodies, full mesh paths,
#: the URDF's visual and collision geometry (display only here), the URDF's inertias.
COMPILER_EXTENSION = ('<mujoco><compiler fusestatic="false" strippath="false" '
                      'discardvisual="false" inertiafromgeom="false" balanceinertia="true" '
                      'autolimits="true" angle="radian"/></mujoco>')
#: Name prefixes of what the builder adds.
FOOT_GEOM_PREFIX = 'gait_foot_'
GROUND_GEOM = 'gait_ground'
GROUND_MATERIAL = 'gait_ground'
#: Mesh files MuJoCo decodes (others are left out of the display geometry).
MESH_SUFFIXES = ('.stl', '.obj', '.msh')
#: Colour of the URDF's display geometry where the URDF gives none (MuJoCo's default grey).
DISPLAY_RGBA = (0.72, 0.74, 0.8, 1.0)
#: Side of the floor's checker squares [m].
GROUND_SQUARE_M = 0.5
STAIR_GEOM_PREFIX = 'gait_stair_'
ACTUATOR_PREFIX = 'gait_servo_'


class PhysicsUnavailableError(GaitNodesError):
    """MuJoCo is not installed (the physics simulator's optional dependency)."""


def import_mujoco():
    """The ``mujoco`` module, or PhysicsUnavailableError telling how to install it."""
    try:
        import mujoco
    except ImportError as exc:
        raise PhysicsUnavailableError(
            f'the physics simulator needs MuJoCo, which is not installed ({exc}): pip install '
            f'mujoco (or pip install "gait_nodes[physics]"; on a ROS machine, into the venv '
            f'or with --break-system-packages: MuJoCo has no rosdep key)') from None
    except Exception as exc:  # noqa: BLE001 (PyOpenGL fails with AttributeError, among others)
        backend = os.environ.get('MUJOCO_GL')
        raise PhysicsUnavailableError(
            f'MuJoCo cannot be imported ({type(exc).__name__}: {exc})'
            + (f': MUJOCO_GL={backend} names an OpenGL backend whose library is missing (EGL: '
               f'apt-get install libegl1; OSMesa: apt-get install libosmesa6), or unset it'
               if backend else '')) from None
    return mujoco


@dataclass(frozen=True)
class PhysicsModel:
    """A compiled MuJoCo model of a robot and the names that tie it to the robot YAML.

    Attributes:
        model: The ``mujoco.MjModel``.
        mjcf_path: The cached MJCF of the model (beside the binary model it was loaded from).
        base_body: Name of the free-floating root body (the URDF's root link).
        joint_names: The actuated joints, one actuator each, in the order of ``actuators``.
        foot_bodies: Body of each foot frame, in the robot's foot order.
        foot_geoms: Contact geom of each foot, in the robot's foot order.
        effort_limits: (J,) force limit of each actuator [N m]; inf where the URDF gives none.
    """

    model: object
    mjcf_path: Path
    base_body: str
    joint_names: tuple[str, ...]
    foot_bodies: tuple[str, ...]
    foot_geoms: tuple[str, ...]
    effort_limits: np.ndarray


def urdf_effort_limits(urdf_text: str) -> dict[str, float]:
    """``{joint: effort}`` of the URDF's ``<limit effort=...>`` (joints without one left out)."""
    root = ET.fromstring(urdf_text)
    limits = {}
    for joint in root.iter('joint'):
        limit = joint.find('limit')
        if limit is not None and limit.get('effort') is not None:
            limits[joint.get('name')] = float(limit.get('effort'))
    return limits


def _share_dirs() -> list[Path]:
    """Folders that hold ROS packages' share trees (``package://NAME/...`` is ``DIR/NAME/...``)."""
    folders = []
    try:
        from gait_nodes.robot.description import example_robot_data_dir

        folders.append(example_robot_data_dir().parent.parent)
    except ConfigError:
        pass
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            folders.append(Path(prefix) / 'share')
    return folders


def _resolve_package_uris(urdf_text: str, urdf_dir: Path) -> str:
    """The URDF with ``package://`` URIs made absolute paths where the file exists."""
    folders = _share_dirs()

    def resolve(match: re.Match) -> str:
        relative = match.group(1)
        for folder in folders:
            if (folder / relative).is_file():
                return str(folder / relative)
        return match.group(0)

    text = re.sub(r'package://([^"\'\s]+)', resolve, urdf_text)
    # Relative mesh paths are relative to the URDF's folder.
    return re.sub(r'filename="(?!/|package:)([^"]+)"',
                  lambda m: f'filename="{urdf_dir / m.group(1)}"', text)


def model_digest(description: RobotDescription, staircase: Staircase, timestep_s: float) -> str:
    """16 hex digits naming the URDF, the robot YAML, the terrain, the step and the builder."""
    import mujoco

    identity = hashlib.sha256(Path(description.urdf_path).read_bytes())
    identity.update(Path(description.path).read_bytes())
    identity.update(repr((staircase.start_x_m, staircase.rise_m, staircase.tread_m,
                          staircase.count, float(timestep_s), BUILDER_VERSION,
                          mujoco.__version__)).encode())
    return identity.hexdigest()[:16]


def _physics_of(description: RobotDescription):
    if description.physics is None:
        raise ConfigError(f'{description.path}: no physics section: the physics simulator needs '
                          f'the joints\' gains (physics.joint_stiffness_nm_per_rad, '
                          f'joint_damping_nm_s_per_rad, joint_armature_kg_m2, foot_friction; '
                          f'see gait_nodes/robot/description.py)')
    return description.physics


def build_spec(description: RobotDescription, joint_names, staircase: Staircase | None = None,
               timestep_s: float = DEFAULT_TIMESTEP_S):
    """The ``mujoco.MjSpec`` of the robot on its terrain (see the module docstring).

    Args:
        description: The robot YAML, with its ``physics`` section.
        joint_names: The joints to actuate (the robot model's 1-DOF joints).
        staircase: The terrain; None or flat: the floor only.
        timestep_s: Physics step [s].

    Returns:
        ``(spec, base_body, foot_geoms, effort_limits)``.

    Raises:
        ConfigError: No physics section, or a foot frame or joint missing from the URDF.
        PhysicsUnavailableError: MuJoCo is not installed.
    """
    mujoco = import_mujoco()
    physics = _physics_of(description)
    urdf_path = Path(description.urdf_path)
    urdf_text = urdf_path.read_text()
    text = _resolve_package_uris(urdf_text, urdf_path.parent)
    # MuJoCo's URDF extension: its compiler settings, read with the URDF.
    text, found = re.subn(r'(<robot\b[^>]*>)', r'\1' + COMPILER_EXTENSION, text, count=1)
    if not found:
        raise ConfigError(f'{urdf_path}: no <robot> element')
    try:
        spec = mujoco.MjSpec.from_string(text)
    except ValueError as exc:
        raise ConfigError(f'{urdf_path}: MuJoCo cannot read the URDF: {exc}') from exc
    spec.modelname = description.name
    # At compile time discardvisual would drop every geom that collides with nothing: the display
    # geometry kept below.
    spec.compiler.discardvisual = False
    spec.option.timestep = float(timestep_s)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = IMPRATIO

    # The URDF's geometry: display only. A mesh that cannot be found or decoded is dropped with
    # its geoms.
    missing = {mesh.name for mesh in spec.meshes
               if not os.path.isabs(mesh.file) or not os.path.isfile(mesh.file)
               or not mesh.file.lower().endswith(MESH_SUFFIXES)}
    for geom in list(spec.geoms):
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH and geom.meshname in missing:
            spec.delete(geom)
            continue
        geom.contype = geom.conaffinity = 0
        geom.group = DISPLAY_GROUP
        if list(geom.rgba) == [0.5, 0.5, 0.5, 1.0]:
            geom.rgba = DISPLAY_RGBA
    for mesh in list(spec.meshes):
        if mesh.name in missing:
            spec.delete(mesh)

    base = spec.worldbody.first_body()
    if base is None or base.name != description.base_frame:
        raise ConfigError(f'{description.path}: base_frame {description.base_frame!r} is not the '
                          f'root link MuJoCo found in {urdf_path.name} '
                          f'({base.name if base else "none"})')
    base.add_freejoint()

    foot_geoms = []
    shapes = {'cylinder': mujoco.mjtGeom.mjGEOM_CYLINDER, 'sphere': mujoco.mjtGeom.mjGEOM_SPHERE,
              'box': mujoco.mjtGeom.mjGEOM_BOX}
    foot = physics.foot
    if foot.shape == 'cylinder':
        size = [foot.size_m[0], 0.5 * foot.size_m[1], 0.0]  # MuJoCo: radius, half-height
    elif foot.shape == 'sphere':
        size = [foot.size_m[0], 0.0, 0.0]
    else:
        size = [0.5 * s for s in foot.size_m]  # MuJoCo: half-lengths
    for foot_description in description.feet:
        body = spec.body(foot_description.frame)
        if body is None:
            raise ConfigError(f'{description.path}: feet.{foot_description.name}.frame: '
                              f'{foot_description.frame!r} is not a link of {urdf_path.name}')
        name = FOOT_GEOM_PREFIX + foot_description.name
        body.add_geom(name=name, type=shapes[foot.shape], size=size,
                      pos=foot.centre_in_foot.tolist(), contype=FOOT_CONTYPE, conaffinity=0,
                      group=FOOT_GROUP, friction=[physics.foot_friction, 0.005, 0.0001],
                      rgba=[0.9, 0.5, 0.1, 1.0])
        foot_geoms.append(name)

    ground = dict(contype=0, conaffinity=GROUND_CONAFFINITY,
                  friction=[physics.foot_friction, 0.005, 0.0001])
    # Display only: a checker floor and a light. A checker texture is 2 x 2 squares, repeated
    # per metre (texuniform).
    repeat = 1.0 / (2.0 * GROUND_SQUARE_M)
    spec.add_texture(name=GROUND_MATERIAL, type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=[0.82, 0.82, 0.82],
                     rgb2=[0.68, 0.69, 0.72], width=256, height=256)
    material = spec.add_material(name=GROUND_MATERIAL, texuniform=True,
                                 texrepeat=[repeat, repeat])
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = GROUND_MATERIAL
    spec.worldbody.add_light(type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, pos=[0.0, 0.0, 10.0],
                             dir=[0.3, 0.2, -1.0], diffuse=[0.6, 0.6, 0.6],
                             specular=[0.1, 0.1, 0.1], castshadow=False)
    spec.worldbody.add_geom(name=GROUND_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE,
                            size=[0.0, 0.0, 1.0], material=GROUND_MATERIAL, **ground)
    staircase = staircase or Staircase()
    for k in range(staircase.count):
        top = (k + 1) * staircase.rise_m
        if top <= 0:
            continue  # a staircase down is not modelled: its treads are below the floor
        x0 = staircase.start_x_m + k * staircase.tread_m
        spec.worldbody.add_geom(
            name=f'{STAIR_GEOM_PREFIX}{k}', type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.5 * STAIRS_LENGTH_M, 0.5 * STAIRS_WIDTH_M, 0.5 * top],
            pos=[x0 + 0.5 * STAIRS_LENGTH_M, 0.0, 0.5 * top], rgba=[0.6, 0.6, 0.7, 1.0],
            **ground)

    efforts = urdf_effort_limits(urdf_text)
    limits = []
    kp = physics.joint_stiffness_nm_per_rad
    kd = physics.joint_damping_nm_s_per_rad
    for name in joint_names:
        joint = spec.joint(name)
        if joint is None:
            raise ConfigError(f'{urdf_path}: MuJoCo has no joint {name!r}')
        joint.armature = physics.joint_armature_kg_m2
        effort = efforts.get(name, 0.0)
        limit = effort if effort > 0 else math.inf
        limits.append(limit)
        actuator = spec.add_actuator(name=ACTUATOR_PREFIX + name, target=name,
                                     trntype=mujoco.mjtTrn.mjTRN_JOINT)
        actuator.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        actuator.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        actuator.gainprm[0] = kp
        actuator.biasprm[:3] = [0.0, -kp, -kd]
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        if math.isfinite(limit):
            actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            actuator.forcerange = [-limit, limit]
        else:
            actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
    return spec, base.name, tuple(foot_geoms), np.array(limits)


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/gait_nodes/physics`` (beside the swing value tables)."""
    from gait_nodes.swing.cache import cache_dir as gait_cache_dir

    return gait_cache_dir() / 'physics'


def load_physics_model(description: RobotDescription, joint_names,
                       staircase: Staircase | None = None,
                       timestep_s: float = DEFAULT_TIMESTEP_S) -> PhysicsModel:
    """The compiled model, from the cached MJCF when there is one (built and cached otherwise).

    Args:
        description: The robot YAML, with its ``physics`` section.
        joint_names: The joints to actuate (the robot model's 1-DOF joints).
        staircase: The terrain; None: flat.
        timestep_s: Physics step [s].

    Raises:
        ConfigError: See :func:`build_spec`; also a model MuJoCo refuses to compile.
        PhysicsUnavailableError: MuJoCo is not installed.
    """
    mujoco = import_mujoco()
    staircase = staircase or Staircase()
    joint_names = tuple(joint_names)
    stem = cache_dir() / f'{description.name}_{model_digest(description, staircase, timestep_s)}'
    binary, mjcf = stem.with_suffix('.mjb'), stem.with_suffix('.xml')
    if not binary.is_file():
        spec, _, _, _ = build_spec(description, joint_names, staircase, timestep_s)
        try:
            compiled = spec.compile()
        except ValueError as exc:
            raise ConfigError(f'{description.path}: MuJoCo cannot compile the model: '
                              f'{exc}') from exc
        stem.parent.mkdir(parents=True, exist_ok=True)
        partial = stem.with_suffix(f'.{os.getpid()}.part')
        partial.write_text(spec.to_xml())
        partial.replace(mjcf)
        mujoco.mj_saveModel(compiled, str(partial), None)
        partial.replace(binary)
    # Always the model of the file (MuJoCo's binary model is exact; the MJCF rounds numbers to
    # six digits): a run with a fresh cache and one with a warm cache simulate the same robot,
    # to the bit.
    model = mujoco.MjModel.from_binary_path(str(binary))
    path = mjcf
    return _physics_model(mujoco, model, path, description, joint_names)


def _physics_model(mujoco, model, path: Path, description: RobotDescription,
                   joint_names: tuple[str, ...]) -> PhysicsModel:
    """The :class:`PhysicsModel` of a compiled model, its names checked."""
    free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise ConfigError(f'{path}: expected one free joint, found {len(free)}')
    base_body = model.body(model.jnt_bodyid[free[0]]).name
    limits = []
    for k, name in enumerate(joint_names):
        actuator = model.actuator(ACTUATOR_PREFIX + name)
        if model.actuator_trnid[actuator.id, 0] != model.joint(name).id or actuator.id != k:
            raise ConfigError(f'{path}: actuator {k} does not drive joint {name!r}')
        limited = bool(model.actuator_forcelimited[actuator.id])
        limits.append(float(model.actuator_forcerange[actuator.id, 1]) if limited else math.inf)
    foot_geoms = tuple(FOOT_GEOM_PREFIX + foot.name for foot in description.feet)
    for name in foot_geoms:
        model.geom(name)  # KeyError if missing
    limits = np.array(limits)
    limits.flags.writeable = False
    return PhysicsModel(model=model, mjcf_path=path, base_body=base_body,
                        joint_names=joint_names,
                        foot_bodies=tuple(f.frame for f in description.feet),
                        foot_geoms=foot_geoms, effort_limits=limits)
