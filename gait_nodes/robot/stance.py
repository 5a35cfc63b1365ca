"""A robot YAML at another stance: the ground's depth below the body, the rear feet's width.

For walking one robot at stances its YAML does not ship: the thesis' own (RoboSimian on ground
0.7 m below its body, :mod:`gait_nodes.thesis`) and the static crawl's stance search
(``bench/stance.py``). The copy's COM height is the full model's at that stance, so that the
first COM reference holds the body where it stands.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from gait_nodes.errors import ConfigError


def write_stance(name_or_path: str | os.PathLike, directory: str | os.PathLike,
                 body_height_m: float, rear_width_m: float | None = None,
                 front_x_m: float | None = None, rear_x_m: float | None = None,
                 gait: str | None = None) -> Path:
    """A copy of a quadruped's robot YAML with its feet ``body_height_m`` below the body.

    Args:
        name_or_path: The robot (a shipped name or a YAML path).
        directory: Where the copy goes
            (``<name>_h<height>[_r<width>][_f<front x>][_b<rear x>].yaml``).
        body_height_m: Depth of the ground below the base [m] (every foot's nominal z).
        rear_width_m: The rear feet's lateral distance from the centre line [m] (None: as
            they are).
        front_x_m: The front feet's distance ahead of the base [m] (None: as they are).
        rear_x_m: The rear feet's distance behind the base [m] (None: as they are).
        gait: Place the front and rear feet in ``gait``'s own stance (``gait_stances``) rather
            than the nominal one (None); a gait's stance the YAML gives is kept otherwise.

    Returns:
        The copy's path (a valid robot YAML: give it wherever a robot name goes).

    Raises:
        ConfigError: The robot YAML is not valid, a height or width is not positive, or the
            robot has no closed-form limb IK (its standing COM is placed with it).
    """
    from gait_nodes.robot.description import load_robot_description
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.robot.whole_body_ik import limb_ik_family
    from gait_nodes.swing.still_body import StillBody
    from gait_nodes.swing.timing import PolynomialSwingTiming

    description = load_robot_description(name_or_path)
    for name, value in (('body_height_m', body_height_m), ('rear_width_m', rear_width_m),
                        ('front_x_m', front_x_m), ('rear_x_m', rear_x_m)):
        if value is not None and not (isinstance(value, (int, float)) and 0.0 < value < 10.0):
            raise ConfigError(f'{name} must be in (0, 10) m, got {value!r}')
    data = yaml.safe_load(description.path.read_text())
    data['urdf'] = str(description.urdf_path.resolve())
    nominal = gait is None
    for foot in data['feet'].values():
        x, y, _ = foot['nominal_position_m']
        if rear_width_m is not None and x < 0.0:
            y = float(np.copysign(rear_width_m, y))
        if nominal and front_x_m is not None and x > 0.0:
            x = float(front_x_m)
        elif nominal and rear_x_m is not None and x < 0.0:
            x = -float(rear_x_m)
        foot['nominal_position_m'] = [x, y, -float(body_height_m)]
    if not nominal and (front_x_m is not None or rear_x_m is not None):
        shipped = description.gait_stances.get(gait)
        if shipped is None:
            stance = description.nominal_stance_in_base()[:, 0]
            shipped = (float(stance.max()), float(-stance.min()))
        else:
            shipped = (shipped.front_x_m, shipped.rear_x_m)
        stances = data.setdefault('gait_stances', {})
        own = stances.setdefault(gait, {})
        own['front_x_m'] = float(front_x_m if front_x_m is not None else shipped[0])
        own['rear_x_m'] = float(rear_x_m if rear_x_m is not None else shipped[1])
    data['body_height_m'] = float(body_height_m)
    suffix = (f'_h{body_height_m:g}' + ('' if rear_width_m is None else f'_r{rear_width_m:g}')
              + ('' if nominal else f'_{gait}')
              + ('' if front_x_m is None else f'_f{front_x_m:g}')
              + ('' if rear_x_m is None else f'_b{rear_x_m:g}'))
    data['description'] = (f'{description.name} at another stance ({suffix[1:]}), a copy of '
                           f'{description.path}')
    path = Path(directory) / f'{description.name}{suffix}.yaml'
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    robot = load_robot_model(path)
    family = limb_ik_family(robot)
    if family is None:
        raise ConfigError(f'{description.name} has no closed-form limb IK: its stance cannot be '
                          f'placed (extra.limb_ik in {description.path})')
    base = np.array([0.0, 0.0, float(body_height_m)])
    feet = robot.nominal_feet_in_world(base, 0.0)
    still = StillBody(PolynomialSwingTiming(robot, family, 1.0, 0.06))
    com = still.com(base[None], 0.0, feet[None], np.zeros((1, len(feet))))[0]
    data['com_height_m'] = round(float(com[2] - feet[:, 2].min()), 5)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
