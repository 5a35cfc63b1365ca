"""The swing-leg value table: converged values on the state grid, with what they were made for.

A table file is a NumPy ``.npz`` (read with ``allow_pickle=False``) holding the arrays
``values_s`` (cost-to-go to the goal), ``lift_s`` (time to lift the foot from the ground to each
state), the grid axes, the goal and the action set, and ``metadata``: a JSON string with the
format version, the robot name and the SHA-256 of its URDF, the IK family, the joint velocity
limit, the step height, the ground height, the lowering time at the goal and the convergence
figures. :func:`load_table` refuses a file that is corrupt or was made for another robot, limit
or family, naming the file and what differs.
"""

from __future__ import annotations

import io
import json
import math
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gait_nodes.errors import SwingTableError
from gait_nodes.swing.grid import SwingActions, SwingGrid
from gait_nodes.swing.kinematics import FEASIBLE_BELOW_S, urdf_sha256

#: Table file format version; a file with another version is refused.
TABLE_VERSION = 1
_ARRAYS = ('values_s', 'lift_s', 'x_m', 'y_m', 'z_m', 'yaw_rad', 'goal',
           'action_radii_m', 'action_elevations_rad', 'action_yaw_steps_rad', 'metadata')
#: Relative tolerance when comparing a table's joint velocity limit with the requested one.
LIMIT_TOLERANCE = 1e-9


def _frozen(array) -> np.ndarray:
    result = np.array(array, dtype=float)
    result.setflags(write=False)
    return result


@dataclass(frozen=True)
class ValueTable:
    """A converged swing-leg value function and its provenance.

    Attributes:
        robot_name: Robot name.
        urdf_sha256: SHA-256 of the robot's URDF bytes.
        family: IK family 0..7.
        joint_velocity_limit_rad_s: Joint velocity limit the times are for [rad/s].
        step_height_m: Swing height above the ground (lowest z level) [m].
        ground_z_m: Ground height in the base frame [m].
        grid: The state mesh.
        actions: The action set.
        goal: (4,) goal state (a node of the grid).
        values_s: Cost-to-go to the goal [s], grid-shaped.
        lift_s: Time to lift the foot from the ground to each state [s], grid-shaped.
        lower_s: Time to lower the foot from the goal to the ground [s].
        iterations: Value-iteration sweeps run.
        max_change_s: Largest value change of the last sweep [s].
        version: File format version.
    """

    robot_name: str
    urdf_sha256: str
    family: int
    joint_velocity_limit_rad_s: float
    step_height_m: float
    ground_z_m: float
    grid: SwingGrid
    actions: SwingActions
    goal: np.ndarray
    values_s: np.ndarray
    lift_s: np.ndarray
    lower_s: float
    iterations: int = 0
    max_change_s: float = 0.0
    version: int = TABLE_VERSION
    _total: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        object.__setattr__(self, 'goal', _frozen(self.goal))
        object.__setattr__(self, 'values_s', _frozen(self.values_s))
        object.__setattr__(self, 'lift_s', _frozen(self.lift_s))
        if self.values_s.shape != self.grid.shape or self.lift_s.shape != self.grid.shape:
            raise SwingTableError(f'table arrays {self.values_s.shape}, {self.lift_s.shape} do '
                                  f'not match the grid {self.grid.shape}')
        if self.goal.shape != (4,):
            raise SwingTableError(f'table goal must be (x, y, z, yaw), got {self.goal.shape}')
        # Times [s] and sizes: a swing takes no negative time, a limit and a height are > 0.
        for name, value, low in (('joint_velocity_limit_rad_s', self.joint_velocity_limit_rad_s,
                                  None), ('step_height_m', self.step_height_m, None),
                                 ('lower_s', self.lower_s, 0.0),
                                 ('ground_z_m', self.ground_z_m, -math.inf)):
            if not (math.isfinite(value) and (value > 0.0 if low is None else value >= low)):
                raise SwingTableError(f'table {name} must be finite and '
                                      f'{"> 0" if low is None else f">= {low:g}"}, got {value!r}')
        for name in ('values_s', 'lift_s'):
            if not np.all(getattr(self, name) >= 0.0):
                raise SwingTableError(f'table {name} must be times >= 0 s, got '
                                      f'{float(np.min(getattr(self, name)))!r}')

    @property
    def total_s(self) -> np.ndarray:
        """Whole swing time from each state: lift + cost-to-go + lowering [s] (grid-shaped)."""
        if self._total is None:
            object.__setattr__(self, '_total',
                               _frozen(self.values_s + self.lift_s + self.lower_s))
        return self._total

    @property
    def converged(self) -> bool:
        """The last sweep changed no value by more than 1e-4 s."""
        return self.max_change_s < 1e-4

    def feasible_fraction(self) -> float:
        """Share of the states with a finite swing to the goal."""
        return float(np.mean(self.values_s < FEASIBLE_BELOW_S))

    def metadata(self) -> dict:
        """The JSON metadata stored with the arrays."""
        return {
            'version': self.version,
            'robot': self.robot_name,
            'urdf_sha256': self.urdf_sha256,
            'family': self.family,
            'joint_velocity_limit_rad_s': self.joint_velocity_limit_rad_s,
            'step_height_m': self.step_height_m,
            'ground_z_m': self.ground_z_m,
            'lower_s': self.lower_s,
            'azimuth_count': self.actions.azimuth_count,
            'iterations': self.iterations,
            'max_change_s': self.max_change_s,
            'goal': [float(v) for v in self.goal],
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write the table to ``path`` (``.npz``), atomically (write then rename)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer, values_s=self.values_s, lift_s=self.lift_s, x_m=self.grid.x_m,
            y_m=self.grid.y_m, z_m=self.grid.z_m, yaw_rad=self.grid.yaw_rad, goal=self.goal,
            action_radii_m=np.array(self.actions.radii_m),
            action_elevations_rad=np.array(self.actions.elevations_rad),
            action_yaw_steps_rad=np.array(self.actions.yaw_steps_rad),
            metadata=np.array(json.dumps(self.metadata(), sort_keys=True)))
        partial = path.with_name(path.name + '.partial')
        partial.write_bytes(buffer.getvalue())
        os.replace(partial, path)
        return path

    def check_for(self, robot, joint_velocity_limit_rad_s: float | None = None,
                  family: int | None = None, where: str = 'table') -> None:
        """Refuse a table made for another robot (URDF hash), limit or family.

        Args:
            robot: The :class:`gait_nodes.robot.model.RobotModel` it will be used with.
            joint_velocity_limit_rad_s: Required limit [rad/s], or None to accept any.
            family: Required IK family, or None to accept any.
            where: Name of the table (its file) for the message.

        Raises:
            SwingTableError: Naming ``where`` and what differs.
        """
        differences = []
        digest = urdf_sha256(robot.description.urdf_path)
        if digest != self.urdf_sha256 or robot.name != self.robot_name:
            differences.append(f'it was built for robot {self.robot_name!r} (URDF sha256 '
                               f'{self.urdf_sha256[:12]}...), not {robot.name!r} (URDF '
                               f'{robot.description.urdf_path}, sha256 {digest[:12]}...)')
        if joint_velocity_limit_rad_s is not None and not math.isclose(
                self.joint_velocity_limit_rad_s, joint_velocity_limit_rad_s,
                rel_tol=LIMIT_TOLERANCE):
            differences.append(f'its joint velocity limit is '
                               f'{self.joint_velocity_limit_rad_s} rad/s, not '
                               f'{joint_velocity_limit_rad_s} rad/s')
        if family is not None and family != self.family:
            differences.append(f'its IK family is {self.family}, not {family}')
        if differences:
            raise SwingTableError(f'{where}: refused: ' + '; '.join(differences))


def load_table(path: str | os.PathLike, robot=None,
               joint_velocity_limit_rad_s: float | None = None,
               family: int | None = None) -> ValueTable:
    """Read a table file; refuse it when corrupt or made for another robot, limit or family.

    Args:
        path: The ``.npz`` file.
        robot: When given, the table's URDF hash and name must match this RobotModel.
        joint_velocity_limit_rad_s: When given, the table's limit must equal it [rad/s].
        family: When given, the table's IK family must equal it.

    Raises:
        SwingTableError: Naming the file and what is wrong or differs.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [name for name in _ARRAYS if name not in data.files]
            if missing:
                raise SwingTableError(f'{path}: not a swing value table: missing {missing}')
            arrays = {name: data[name] for name in _ARRAYS}
        meta = json.loads(str(arrays['metadata']))
    except FileNotFoundError:
        raise SwingTableError(f'{path}: no such table file') from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as exc:
        raise SwingTableError(f'{path}: corrupt swing value table: {exc}') from None
    if not isinstance(meta, dict) or meta.get('version') != TABLE_VERSION:
        version = meta.get('version') if isinstance(meta, dict) else None
        raise SwingTableError(f'{path}: table format version {version!r}, this gait_nodes reads '
                              f'version {TABLE_VERSION}; rebuild it with python -m '
                              f'gait_nodes.swing_table build')
    try:
        for name in _ARRAYS[:-1]:
            if not np.all(np.isfinite(np.asarray(arrays[name], dtype=float))):
                raise SwingTableError(f'{path}: corrupt swing value table: {name} holds a NaN or '
                                      f'infinite value')
        table = ValueTable(
            robot_name=str(meta['robot']), urdf_sha256=str(meta['urdf_sha256']),
            family=int(meta['family']),
            joint_velocity_limit_rad_s=float(meta['joint_velocity_limit_rad_s']),
            step_height_m=float(meta['step_height_m']), ground_z_m=float(meta['ground_z_m']),
            grid=SwingGrid(arrays['x_m'], arrays['y_m'], arrays['z_m'], arrays['yaw_rad']),
            actions=SwingActions(tuple(arrays['action_radii_m']), int(meta['azimuth_count']),
                                 tuple(arrays['action_elevations_rad']),
                                 tuple(arrays['action_yaw_steps_rad'])),
            goal=arrays['goal'], values_s=arrays['values_s'], lift_s=arrays['lift_s'],
            lower_s=float(meta['lower_s']), iterations=int(meta['iterations']),
            max_change_s=float(meta['max_change_s']), version=int(meta['version']))
    except (KeyError, TypeError, ValueError) as exc:
        raise SwingTableError(f'{path}: corrupt swing value table: {exc!r}') from None
    except SwingTableError as exc:
        message = str(exc)
        raise SwingTableError(message if message.startswith(str(path))
                              else f'{path}: corrupt swing value table: {message}') from None
    if robot is not None or joint_velocity_limit_rad_s is not None or family is not None:
        if robot is not None:
            table.check_for(robot, joint_velocity_limit_rad_s, family, where=str(path))
        elif joint_velocity_limit_rad_s is not None and not math.isclose(
                table.joint_velocity_limit_rad_s, joint_velocity_limit_rad_s,
                rel_tol=LIMIT_TOLERANCE):
            raise SwingTableError(f'{path}: refused: its joint velocity limit is '
                                  f'{table.joint_velocity_limit_rad_s} rad/s, not '
                                  f'{joint_velocity_limit_rad_s} rad/s')
    return table
