"""Gait parameters: one frozen, validated set, checked once where it enters.

Timing is the same for every gait. A gait cycle lasts ``T = 2 * step_period_s`` and holds two
*steps*; each step begins with all feet down while the ZMP moves (the transfer phase), then the
step's swings follow:

=======  ==========================================  ===============================
gait     swings of one step                          ZMP reference (seed)
=======  ==========================================  ===============================
biped    one foot                                    Lucy: at the stance ankle in
                                                     single support, rear to front in
                                                     double support
trot     one diagonal pair, together                 Kurazume 2.1: on the diagonal of
                                                     the support pair
crawl    one lateral pair, hind then fore            thesis III.B.1: from the diagonal
                                                     pairs, moves twice a cycle
static_  as crawl, the body still while a foot       the cart-table ZMP of the body's
crawl    swings, moving only with every foot down    rest-to-rest moves and of the
         (thesis eq. (2) walked: value-table         swinging limbs (the COM of the
         swings at the limb's own speed)             full model, base placed)
=======  ==========================================  ===============================

Each foot swings ``(1 - duty_factor) * T`` (``timing: fixed``). With ``timing: joint_limit``
and a robot whose swings can be timed at its joint velocity limit (closed-form limb IK), the
rhythm comes from the limit instead (:mod:`gait_nodes.planning.rhythm`, thesis eq. (2)): each
swing lasts what the swing method needs for the stride the velocity asks for, each transfer
half the body's move, and ``step_period_s`` and ``duty_factor`` are not used; a velocity
faster than the joints allow at the longest stride is reduced to the fastest feasible one.
``step_length_m`` is the longest stride: how far a
foot moves in one swing in steady straight walking (the thesis' step size, Kurazume's L); the
walk itself follows /cmd_vel, so a foot moves ``v T`` per swing, at most ``step_length_m``. For
the biped, Lucy's step length (the distance between the ankles in double support) is half the
stride. ``step_width_m`` is the distance between the left and right foot tracks (the robot's
nominal stance width by default).

Admissible duty factors (open intervals):

* biped: Kurazume (25), ``(1 + alpha) / 2 < beta < 1``, where ``alpha D`` is the inner edge of
  the sole measured from the sway centre, ``D = step_width_m / 2`` the sway half-width and the
  edge moved in by the ZMP margin: ``alpha = 1 - 2 (foot_radius_m - zmp_margin_m) / step_width_m``.
  This keeps Kurazume's moving ZMP in the sole during single support; our Lucy ZMP, held at the
  ankle, is then inside it with room to spare.
* trot: (25) with the ZMP on the support diagonal the whole time, i.e. ``alpha = 0``:
  ``1/2 < beta < 1``.
* crawl, static_crawl: ``3/4 < beta < 1`` (one foot at a time, with a four-foot phase for each
  ZMP move). The static crawl needs closed-form limb IK (the body is placed, not balanced) and
  ``timing: joint_limit`` (its swings and moves are timed at the limbs' own speed).

``gait = 'auto'`` resolves, for a robot with closed-form limb IK and more than one gait, to the
gait whose walk, planned by the footstep planner at the robot's joint velocity limit, is the
fastest (thesis IV.C; :mod:`gait_nodes.planning.gait_choice`, computed once per robot and limit
and cached: :func:`auto_choice` says which and why); for any other robot to its first gait (its
YAML ``gaits`` list).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass

from gait_nodes.errors import GaitCommandError, GaitParameterError
from gait_nodes.robot.description import RobotDescription

GAITS = ('biped', 'crawl', 'static_crawl', 'trot', 'auto')
SWING_METHODS = ('polynomial', 'value_table')
COM_METHODS = ('preview', 'sway', 'polynomial')
TIMINGS = ('fixed', 'joint_limit')

#: Steps per gait cycle (every gait).
STEPS_PER_CYCLE = 2
#: Sequential swing slots in one step.
SWING_SLOTS = {'biped': 1, 'trot': 1, 'crawl': 2, 'static_crawl': 2}

#: Numeric fields: (lowest excluded, highest included, unit) before any robot check.
NUMERIC_RANGES: dict[str, tuple[float, float, str]] = {
    'step_length_m': (0.0, 5.0, 'm'),
    'step_width_m': (0.0, 5.0, 'm'),
    # Below a millimetre the joint-limit rhythm's swing takes no time and the duty factor
    # rounds to 1 (a 5e-324 m apex stopped the planner).
    'step_height_m': (0.001, 2.0, 'm'),
    # A step shorter than 0.05 s (20 steps a second) is no gait, and the planner's work grows
    # as 1 / step_period_s: a step of 1e-6 s would take it hours per second walked.
    'step_period_s': (0.05, 60.0, 's'),
    'duty_factor': (0.0, 1.0, ''),
    'com_height_m': (0.0, 5.0, 'm'),
    'body_height_m': (0.0, 5.0, 'm'),
    'zmp_margin_m': (0.0, 1.0, 'm'),
    'max_vx_m_s': (0.0, 10.0, 'm/s'),
    'max_vy_m_s': (0.0, 10.0, 'm/s'),
    'max_wz_rad_s': (0.0, 10.0, 'rad/s'),
}
CHOICE_FIELDS: dict[str, tuple[str, ...]] = {
    'gait': GAITS, 'swing': SWING_METHODS, 'com_method': COM_METHODS, 'timing': TIMINGS,
}


@dataclass(frozen=True, kw_only=True)
class GaitParameters:
    """Settings of the gait, validated on construction (robot checks: :meth:`check_robot`).

    Attributes:
        gait: biped | crawl | static_crawl | trot | auto.
        step_length_m: Longest stride, one foot's displacement per swing [m].
        step_width_m: Distance between the left and right foot tracks [m].
        step_height_m: Swing apex above the ground [m] (for the swing-leg policy).
        step_period_s: Duration of one step, half a gait cycle [s].
        duty_factor: Fraction of the cycle each foot is on the ground.
        com_height_m: COM height of the cart-table model [m] (for the COM controller).
        body_height_m: Base height above the ground [m] (for the whole-body IK).
        zmp_margin_m: Least distance of the ZMP reference inside the support polygon [m].
        swing: Swing-leg method: polynomial | value_table.
        com_method: COM method: preview | sway | polynomial.
        timing: fixed (``step_period_s`` and ``duty_factor`` as given) | joint_limit (the
            rhythm follows from the joint velocity limit, see :mod:`gait_nodes.planning.
            rhythm`; for a robot without a swing timing model the same as fixed).
        max_vx_m_s: Largest forward speed accepted from /cmd_vel [m/s].
        max_vy_m_s: Largest sideways speed accepted from /cmd_vel [m/s].
        max_wz_rad_s: Largest turn rate accepted from /cmd_vel [rad/s].
    """

    gait: str = 'auto'
    step_length_m: float = 0.3
    step_width_m: float
    step_height_m: float = 0.1
    step_period_s: float = 2.0
    duty_factor: float = 0.85
    com_height_m: float
    body_height_m: float
    zmp_margin_m: float = 0.01
    swing: str = 'polynomial'
    com_method: str = 'preview'
    timing: str = 'fixed'
    max_vx_m_s: float = 0.1
    max_vy_m_s: float = 0.05
    max_wz_rad_s: float = 0.1

    def __post_init__(self):
        for name, choices in CHOICE_FIELDS.items():
            value = getattr(self, name)
            if not isinstance(value, str) or value not in choices:
                raise GaitParameterError(f'{name} must be one of {list(choices)}, got {value!r}')
        for name, (low, high, unit) in NUMERIC_RANGES.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise GaitParameterError(f'{name} must be a number, got {value!r} '
                                         f'({type(value).__name__})')
            if not math.isfinite(value):
                raise GaitParameterError(f'{name} must be finite, got {value!r}')
            if not low < value <= high:
                raise GaitParameterError(
                    f'{name} = {value!r} is out of range: must be in ({low:g}, {high:g}]'
                    f'{" " + unit if unit else ""}')
            object.__setattr__(self, name, float(value))
        if self.duty_factor >= 1.0:
            raise GaitParameterError(f'duty_factor = {self.duty_factor!r} leaves no time to '
                                     f'swing: must be < 1')

    @classmethod
    def for_robot(cls, robot: RobotDescription, **values) -> GaitParameters:
        """Parameters with the robot's defaults, checked for it.

        The robot gives the stance width, the heights and the longest stride: the class default
        ``step_length_m``, or the longest step of the robot's gaits when that is shorter (a
        Go2 reaches 0.2 m), so that the defaults always suit the robot. A gait steps at most
        its own longest step (:meth:`RobotDescription.max_step_length_m`).
        """
        params = cls(**{**cls.robot_defaults(robot), **values})
        params.check_robot(robot)
        return params

    @classmethod
    def robot_defaults(cls, robot: RobotDescription) -> dict[str, float]:
        """The settings whose defaults come from the robot (see :meth:`for_robot`)."""
        return {'step_length_m': min(cls.__dataclass_fields__['step_length_m'].default,
                                     robot.longest_step_m),
                'step_width_m': nominal_stance_width_m(robot),
                'com_height_m': robot.com_height_m,
                'body_height_m': robot.body_height_m}

    def replace(self, **changes) -> GaitParameters:
        """A copy with ``changes`` applied (validated again)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, object]:
        """Field name -> value, in declaration order (the command status' ``params``)."""
        return {field.name: getattr(self, field.name) for field in dataclasses.fields(self)}

    @property
    def cycle_s(self) -> float:
        """Gait cycle T [s]."""
        return STEPS_PER_CYCLE * self.step_period_s

    @property
    def swing_s(self) -> float:
        """Swing duration of one foot, (1 - beta) T [s]."""
        return (1.0 - self.duty_factor) * self.cycle_s

    def transfer_s(self, gait: str) -> float:
        """All-feet-down time at the start of each step of ``gait`` (a resolved gait) [s]."""
        return self.step_period_s - SWING_SLOTS[gait] * self.swing_s

    def resolved_gait(self, robot: RobotDescription) -> str:
        """The gait to walk: ``gait``, or for 'auto' the fastest one at the joint limit."""
        return auto_gait(robot, self.timing) if self.gait == 'auto' else self.gait

    def check_robot(self, robot: RobotDescription) -> None:
        """Raise :class:`GaitParameterError` if the robot cannot walk with these parameters."""
        gait = self.resolved_gait(robot)
        if gait not in robot.gaits:
            raise GaitParameterError(f'gait {gait!r} is not possible for {robot.name} '
                                     f'({robot.kind}); its gaits: {list(robot.gaits)}')
        reach = robot.reach
        if self.step_length_m > robot.longest_step_m:
            raise GaitParameterError(
                f'step_length_m = {self.step_length_m:g} is beyond the reach of {robot.name}: '
                f'must be <= {robot.longest_step_m:g} m (reach.max_step_length_m, or a gait\'s '
                f'own in gait_stances)')
        nominal = nominal_stance_width_m(robot)
        low = max(2.0 * robot.foot_radius_m, nominal - 2.0 * reach.max_step_width_m)
        high = nominal + 2.0 * reach.max_step_width_m
        if not low < self.step_width_m <= high:
            raise GaitParameterError(
                f'step_width_m = {self.step_width_m:g} is beyond the reach of {robot.name}: '
                f'must be in ({low:g}, {high:g}] m (nominal {nominal:g} m, each foot at most '
                f'reach.max_step_width_m = {reach.max_step_width_m:g} m from nominal, feet of '
                f'radius {robot.foot_radius_m:g} m apart)')
        if gait in ('biped', 'trot') and self.zmp_margin_m >= robot.foot_radius_m:
            raise GaitParameterError(
                f'zmp_margin_m = {self.zmp_margin_m:g} cannot be kept in a {gait} gait: the '
                f'ZMP sits on the support line, {robot.foot_radius_m:g} m (foot radius) inside '
                f'the support polygon; must be < {robot.foot_radius_m:g} m')
        low, high = duty_factor_bounds(gait, robot, self)
        if not low < self.duty_factor < high:
            raise GaitParameterError(
                f'duty_factor = {self.duty_factor:g} is not admissible for the {gait} gait: '
                f'must be in ({low:.4g}, {high:g}) ({DUTY_FACTOR_RULES[gait]})')
        if gait == 'static_crawl' and robot.extra.get('limb_ik') is None:
            raise GaitParameterError(
                f'gait \'static_crawl\' needs closed-form limb IK (the body is held still under '
                f'each swing); {robot.name} has none: use crawl')
        if gait == 'static_crawl' and self.timing != 'joint_limit':
            raise GaitParameterError(
                f'gait \'static_crawl\' is timed at the joint velocity limit (its swings and '
                f'body moves at the limbs\' own speed, the body placed by the swing timing '
                f'model): it needs timing \'joint_limit\', got {self.timing!r}')
        if gait in ('crawl', 'static_crawl'):
            from gait_nodes.planning.zmp_reference import crawl_margin_feasible

            clearance = crawl_margin_feasible(robot, self)
            if clearance < self.zmp_margin_m:
                raise GaitParameterError(
                    f'zmp_margin_m = {self.zmp_margin_m:g} cannot be kept in a crawl with '
                    f'step_length_m = {self.step_length_m:g}: the support triangles leave at '
                    f'most {clearance:.4g} m; reduce the margin or the step')


DUTY_FACTOR_RULES = {
    'biped': 'Kurazume (25): (1 + alpha)/2 < beta < 1 with the sole edge at alpha D',
    'trot': 'Kurazume (25) with the ZMP on the support diagonal: 1/2 < beta < 1',
    'crawl': 'crawl: one foot at a time with a four-foot phase per ZMP move, 3/4 < beta < 1',
    'static_crawl': 'crawl: one foot at a time with a four-foot phase per body move, '
                    '3/4 < beta < 1',
}


def duty_factor_bounds(gait: str, robot: RobotDescription,
                       params: GaitParameters) -> tuple[float, float]:
    """Open interval of admissible duty factors for ``gait`` (resolved) on ``robot``."""
    if gait in ('crawl', 'static_crawl'):
        return 0.75, 1.0
    if gait == 'trot':
        return 0.5, 1.0
    # Kurazume (25): sway half-width D = w / 2, sole inner edge at alpha D.
    sway_m = 0.5 * params.step_width_m
    alpha = (sway_m - (robot.foot_radius_m - params.zmp_margin_m)) / sway_m
    return max(0.5, 0.5 * (1.0 + alpha)), 1.0


def nominal_stance_width_m(robot: RobotDescription) -> float:
    """Mean distance between the left and right feet of the robot's nominal stance [m]."""
    y = robot.nominal_stance_in_base()[:, 1]
    return float(y[y > 0].mean() - y[y < 0].mean())


def parameters_from_mapping(base: GaitParameters, values: Mapping[str, object],
                            robot: RobotDescription) -> GaitParameters:
    """``base`` with ``values`` applied and checked for ``robot``.

    Raises:
        GaitParameterError: An unknown key, a wrong type, a value out of range or beyond the
            robot; the message names the key, the value and the allowed values.
    """
    known = [field.name for field in dataclasses.fields(GaitParameters)]
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise GaitParameterError(f'unknown key(s) {unknown}; allowed: {known}')
    changes = {}
    for key, value in values.items():
        if key in NUMERIC_RANGES and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        changes[key] = value
    params = base.replace(**changes)
    params.check_robot(robot)
    return params


def command_schema() -> dict:
    """The JSON Schema of /gait/command (``msgs_schema/gait_command.schema.json``)."""
    global _SCHEMA
    if _SCHEMA is None:
        import json

        from gait_nodes.paths import data_dir

        _SCHEMA = json.loads((data_dir('msgs_schema') / 'gait_command.schema.json').read_text())
    return _SCHEMA


_SCHEMA: dict | None = None


def parse_command(text: str) -> dict[str, object]:
    """The changes asked by a /gait/command JSON text (see :func:`parse_gait_command`)."""
    return parse_gait_command(text)[1]


def parse_gait_command(text: str) -> tuple[str | None, dict[str, object]]:
    """``(id, changes)`` of a /gait/command JSON text, checked against the schema.

    ``id`` (a string, optional: None when absent) names the command, so that a retry of it is
    applied once; the changes are the other keys.

    Raises:
        GaitCommandError: Invalid JSON, a key given twice, not an object, a NaN or infinite
            number, an unknown key, a wrong type or a value outside the schema's range; the
            message says which.
    """
    import json

    import jsonschema

    def no_duplicates(pairs):
        keys = [key for key, _ in pairs]
        twice = sorted({key for key in keys if keys.count(key) > 1})
        if twice:
            raise GaitCommandError(f'key(s) {twice} given more than once; each at most once')
        return dict(pairs)

    try:
        values = json.loads(text, object_pairs_hook=no_duplicates)
    except GaitCommandError:
        raise
    except (ValueError, TypeError) as exc:  # JSONDecodeError, or an integer of > 4300 digits
        raise GaitCommandError(f'invalid JSON: {exc}') from exc
    except RecursionError as exc:
        raise GaitCommandError(f'invalid JSON: nested too deeply ({exc})') from exc
    if not isinstance(values, dict):
        raise GaitCommandError(f'a gait command is a JSON object, got {type(values).__name__}')
    for key, value in values.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise GaitCommandError(f'{key} must be finite, got {value!r}')
    allowed = list(command_schema()['properties'])
    unknown = sorted(set(values) - set(allowed))
    if unknown:
        raise GaitCommandError(f'unknown key(s) {unknown}; allowed: {allowed}')
    validator = jsonschema.Draft202012Validator(command_schema())
    error = jsonschema.exceptions.best_match(validator.iter_errors(values))
    if error is not None:
        where = '.'.join(str(p) for p in error.absolute_path)
        raise GaitCommandError(f'{where + ": " if where else ""}{error.message}')
    command_id = values.pop('id', None)
    return command_id, {key: float(value) if key in NUMERIC_RANGES else value
                        for key, value in values.items()}


def command_id_of(text: str) -> str | None:
    """The ``id`` of a /gait/command text if it has a usable one, however bad the rest is."""
    import json

    try:
        values = json.loads(text)
    except (ValueError, TypeError, RecursionError):
        return None
    command_id = values.get('id') if isinstance(values, dict) else None
    return command_id if isinstance(command_id, str) and 0 < len(command_id) <= 128 else None


@functools.lru_cache(maxsize=8)
def _auto_choice(robot_path: str, joint_velocity_limit_rad_s: float):
    from gait_nodes.errors import GaitNodesError
    from gait_nodes.planning.gait_choice import compare_gaits
    from gait_nodes.robot.model import load_robot_model

    try:
        return compare_gaits(load_robot_model(robot_path))
    except GaitNodesError:
        return None  # no model to plan with: the first gait


def auto_choice(robot: RobotDescription):
    """How ``auto`` chose on ``robot``: a :class:`gait_nodes.planning.gait_choice.GaitChoice`.

    None for a robot whose ``auto`` is its first gait without a comparison (no closed-form limb
    IK, one gait, or no model to plan with).
    """
    if robot.extra.get('limb_ik') is None or len(robot.gaits) < 2:
        return None
    return _auto_choice(str(robot.path), robot.joint_velocity_limit_rad_s)


#: Gaits only a timing from the joint velocity limit can walk.
JOINT_LIMIT_GAITS = ('static_crawl',)


def auto_gait(robot: RobotDescription, timing: str = 'joint_limit') -> str:
    """The gait ``auto`` walks on ``robot`` (see the module docstring).

    With ``timing: fixed`` the fastest of the gaits that fixed timing can walk (not
    :data:`JOINT_LIMIT_GAITS`).
    """
    allowed = [gait for gait in robot.gaits
               if timing == 'joint_limit' or gait not in JOINT_LIMIT_GAITS] or list(robot.gaits)
    choice = auto_choice(robot)
    if choice is not None:
        for candidate in choice.candidates:
            if candidate.feasible and candidate.gait in allowed:
                return candidate.gait
    return allowed[0]
