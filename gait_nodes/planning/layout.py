"""Which foot is which: sides, ends, diagonal pairs and the swing order of every gait.

Feet are told apart by their nominal position in the base frame (x forward, y left), not by name,
so that any robot YAML works: a quadruped needs one foot in each quadrant, a biped one foot on
each side.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from gait_nodes.errors import ConfigError
from gait_nodes.robot.description import RobotDescription


@dataclass(frozen=True)
class FootLayout:
    """Foot roles of one robot (indices into the robot's foot order).

    Attributes:
        names: Foot names in the robot YAML's order.
        nominal_xy: (F, 2) nominal foot positions in the base frame [m].
        left: (F,) True for the feet on the left (y > 0).
        roles: Foot index by role: quadruped "fl", "fr", "rl", "rr"; biped "l", "r".
        gait_xy: Gait -> (F, 2) its own stance, for the gaits the robot gives one
            (``gait_stances``); the others walk the nominal one.
        com_xy: (2,) the COM of the robot standing at the nominal stance, in the base frame
            (``com_xy_m``; None: not given, the stance's centre stands in for it).
    """

    names: tuple[str, ...]
    nominal_xy: np.ndarray
    left: np.ndarray
    roles: dict[str, int]
    gait_xy: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    com_xy: np.ndarray | None = None

    @classmethod
    def of(cls, robot: RobotDescription) -> FootLayout:
        """The layout of ``robot``; ConfigError if its feet are not one per side/quadrant."""
        xy = robot.nominal_stance_in_base()[:, :2].copy()
        centre = xy.mean(axis=0)
        left = xy[:, 1] > centre[1]
        roles: dict[str, int] = {}
        if robot.kind == 'biped':
            for index, is_left in enumerate(left):
                roles['l' if is_left else 'r'] = index
            expected = {'l', 'r'}
        else:
            for index, (x, y) in enumerate(xy - centre):
                roles[('f' if x > 0 else 'r') + ('l' if y > 0 else 'r')] = index
            expected = {'fl', 'fr', 'rl', 'rr'}
        if set(roles) != expected or len(roles) != len(xy):
            raise ConfigError(f'{robot.name}: the nominal feet must be one per '
                              f'{"side" if robot.kind == "biped" else "quadrant"} of the base '
                              f'frame, got {xy.tolist()}')
        xy.setflags(write=False)
        left.setflags(write=False)
        gait_xy = {}
        for gait in robot.gait_stances:
            gait_xy[gait] = robot.nominal_stance_in_base(gait)[:, :2]
            gait_xy[gait].setflags(write=False)
        return cls(robot.foot_names, xy, left, roles, gait_xy, robot.com_xy_m)

    @property
    def count(self) -> int:
        """Number of feet."""
        return len(self.names)

    def offsets(self, step_width_m: float, gait: str | None = None) -> np.ndarray:
        """(F, 2) foot positions in the base frame for a stance ``step_width_m`` wide [m].

        ``gait``'s own stance (:attr:`gait_xy`) if it has one, else the nominal one. A new
        array each call (the caller may edit it), copied from the one worked out for that width
        (the planner asks for the same width hundreds of times per velocity it times).
        """
        known = self.__dict__.setdefault('_offsets', {})
        stance = gait if gait in self.gait_xy else None
        key = (step_width_m, stance)
        if key not in known:
            if len(known) > 64:
                known.clear()
            y = self.nominal_xy[:, 1]
            nominal_width = y[self.left].mean() - y[~self.left].mean()
            shift = 0.5 * (step_width_m - nominal_width)
            result = (self.nominal_xy if stance is None else self.gait_xy[stance]).copy()
            result[:, 1] += np.where(self.left, shift, -shift)
            known[key] = result
        return known[key].copy()

    def swing_groups(self, gait: str) -> tuple[tuple[tuple[int, ...], ...], ...]:
        """The gait's steps in cycle order, each a sequence of swing slots (sets of feet).

        Index 0 leads with the left side: biped ``[[l]], [[r]]``; trot ``[[fl, rr]], [[fr, rl]]``;
        crawl ``[[rl], [fl]], [[rr], [fr]]`` (hind then fore, the thesis' diagonal pairs
        standing while a lateral pair steps).
        """
        r = self.roles
        if gait == 'biped':
            return (((r['l'],),), ((r['r'],),))
        if gait == 'trot':
            return (((r['fl'], r['rr']),), ((r['fr'], r['rl']),))
        if gait in ('crawl', 'static_crawl'):
            return (((r['rl'],), (r['fl'],)), ((r['rr'],), (r['fr'],)))
        raise ConfigError(f'no swing order for gait {gait!r}')

    def diagonals(self) -> tuple[tuple[int, int], tuple[int, int]]:
        """The two diagonal pairs of a quadruped: (fl, rr) and (fr, rl)."""
        r = self.roles
        return (r['fl'], r['rr']), (r['fr'], r['rl'])
