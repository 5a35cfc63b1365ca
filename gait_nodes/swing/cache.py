"""Where default swing value tables live, and building one on first use.

A node asked for ``swing: value_table`` without a ``table`` file uses
``$XDG_CACHE_HOME/gait_nodes/`` (default ``~/.cache/gait_nodes/``), one file per robot (its
URDF, what its YAML says but the joint limits, and the limb IK's family numbering), family,
step height and joint velocity limit. A missing table is made from the same robot's table at
another limit when there is one (every time scales as ``1 / W``:
:func:`gait_nodes.swing.value_iteration.at_limit`, a fraction of a second), else built with
the default grid.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gait_nodes.robot.limb_ik import FAMILY_NUMBERING
from gait_nodes.swing.table import ValueTable, load_table


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/gait_nodes`` or ``~/.cache/gait_nodes``."""
    base = os.environ.get('XDG_CACHE_HOME') or str(Path.home() / '.cache')
    return Path(base) / 'gait_nodes'


#: Robot YAML keys a value table does not depend on: the joint limits (the file name carries
#: the velocity limit; a table times its moves at that limit only), the prose and the URDF's
#: path (its bytes are hashed).
TABLE_FREE_KEYS = ('joint_velocity_limit_rad_s', 'joint_velocity_limits_rad_s',
                   'joint_acceleration_limit_rad_s2', 'joint_acceleration_limits_rad_s2',
                   'description', 'urdf')


def robot_digest(robot) -> str:
    """12 hex digits naming what a robot's tables depend on.

    The URDF's bytes, the robot YAML's content but :data:`TABLE_FREE_KEYS` (comments and
    layout do not count), and the limb IK's family numbering: the same robot at another joint
    velocity limit (a copy of its YAML with another limit) has the same digest, and its table
    is scaled, not built again.
    """
    import yaml

    identity = hashlib.sha256(Path(robot.description.urdf_path).read_bytes())
    content = yaml.safe_load(Path(robot.description.path).read_text())
    if isinstance(content, dict):
        content = {key: value for key, value in content.items() if key not in TABLE_FREE_KEYS}
    identity.update(json.dumps(content, sort_keys=True, default=str).encode())
    identity.update(FAMILY_NUMBERING.encode())
    return identity.hexdigest()[:12]


def default_table_path(robot, family: int, step_height_m: float,
                       joint_velocity_limit_rad_s: float) -> Path:
    """The cache file of a table for these settings (the robot's hash is in the name).

    The hash covers the URDF, the robot YAML (ground height, stance; not its joint limits) and
    the limb IK's family numbering, so a table of another robot, stance or family is never taken
    for this one (:func:`robot_digest`).
    """
    digest = robot_digest(robot)
    return cache_dir() / (f'swing_{robot.name}_{digest}_f{family}_h{step_height_m:g}'
                          f'_w{joint_velocity_limit_rad_s:g}.npz')


def load_or_build(robot, family: int, step_height_m: float, joint_velocity_limit_rad_s: float,
                  path: str | os.PathLike | None = None,
                  log: Callable[[str], None] | None = None) -> tuple[ValueTable, Path]:
    """Load a table (checked against robot, limit and family) or make the default one.

    The default one is the same robot's table at another limit, scaled (see the module
    docstring), when the cache holds one; otherwise it is built.

    Args:
        robot: The RobotModel.
        family: IK family 0..7.
        step_height_m: Step height [m] (only used to name and build the default table).
        joint_velocity_limit_rad_s: Joint velocity limit [rad/s].
        path: A table file; None or '' for the cache file, built when missing.
        log: Called with a message when a table is being built or scaled.

    Raises:
        SwingTableError: A given file is missing or refused, or the build fails.
    """
    if path:
        path = Path(path).expanduser()
        return load_table(path, robot, joint_velocity_limit_rad_s, family), path
    path = default_table_path(robot, family, step_height_m, joint_velocity_limit_rad_s)
    if not path.is_file():
        scaled = _scaled_from_another_limit(robot, family, step_height_m,
                                            joint_velocity_limit_rad_s, path, log)
        if scaled is not None:
            return scaled, path
        from gait_nodes.swing.value_iteration import build_table

        if log is not None:
            log(f'building the swing value table {path} (default grid, family {family}, step '
                f'height {step_height_m:g} m, {joint_velocity_limit_rad_s:g} rad/s); this '
                f'happens once')
        table, _ = build_table(robot, family, step_height_m, joint_velocity_limit_rad_s)
        table.save(path)
    return load_table(path, robot, joint_velocity_limit_rad_s, family), path


def _scaled_from_another_limit(robot, family: int, step_height_m: float,
                               joint_velocity_limit_rad_s: float, path: Path,
                               log: Callable[[str], None] | None) -> ValueTable | None:
    """The same robot's cached table at another limit, scaled and saved at ``path``.

    Same family and step height; None when the cache holds no such table.
    """
    from gait_nodes.errors import SwingTableError
    from gait_nodes.swing.value_iteration import at_limit

    pattern = path.name.replace(f'_w{joint_velocity_limit_rad_s:g}.npz', '_w*.npz')
    for source in sorted(path.parent.glob(pattern)):
        try:
            table = load_table(source, robot, family=family)
        except SwingTableError:
            continue  # a corrupt or foreign file: another source, or a build
        if log is not None:
            log(f'swing value table {path}: the table at {table.joint_velocity_limit_rad_s:g} '
                f'rad/s ({source.name}) with every time scaled by '
                f'{table.joint_velocity_limit_rad_s:g} / {joint_velocity_limit_rad_s:g}')
        scaled = at_limit(table, joint_velocity_limit_rad_s)
        scaled.save(path)
        return load_table(path, robot, joint_velocity_limit_rad_s, family)
    return None


def cached_one_step_costs(robot, family: int, joint_velocity_limit_rad_s: float, grid,
                          displacements, log: Callable[[str], None] | None = None):
    """``(costs, feasible)`` of :func:`~gait_nodes.swing.value_iteration.one_step_costs`.

    Cached in ``$XDG_CACHE_HOME/gait_nodes/thesis/``, one file per robot, family, limit, grid
    and action set (a minute per family on the thesis' default grid).

    Args:
        robot: The RobotModel.
        family: IK family 0..7.
        joint_velocity_limit_rad_s: Joint velocity limit [rad/s].
        grid: The :class:`~gait_nodes.swing.grid.SwingGrid`.
        displacements: (A, 4) actions of :meth:`SwingActions.displacements`.
        log: Called with a message when the costs are being computed.
    """
    import numpy as np

    from gait_nodes.swing.kinematics import LimbTiming
    from gait_nodes.swing.value_iteration import one_step_costs

    key = hashlib.sha256(robot_digest(robot).encode())
    for array in (*grid.axes, displacements, np.array([family, joint_velocity_limit_rad_s])):
        key.update(np.ascontiguousarray(array, dtype=float).tobytes())
    path = cache_dir() / 'thesis' / f'costs_{robot.name}_f{family}_{key.hexdigest()[:16]}.npz'
    if path.is_file():
        with np.load(path, allow_pickle=False) as data:
            return data['costs'], data['feasible']
    if log is not None:
        log(f'one-step costs of family {family}: {grid.size} states x {len(displacements)} '
            f'actions (cached in {path.parent})')
    costs, feasible = one_step_costs(LimbTiming(robot, family, joint_velocity_limit_rad_s),
                                     grid, displacements)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix('.part.npz')
    np.savez(partial, costs=costs, feasible=feasible)
    partial.replace(path)
    return costs, feasible


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 of this package's Python source (node times follow from its code)."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(root.rglob('*.py')):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def node_times_path(timing, kind: str) -> Path | None:
    """The file of a swing timing model's node times (None: a model it cannot name).

    ``kind``: ``'still'`` for the static crawl's body-still times
    (:class:`gait_nodes.swing.still_body.StillBody`), ``'timing'`` for the model's own
    (:class:`gait_nodes.swing.timing.SwingTiming`: the swings and body moves of the gaits whose
    body compensates the swinging limb). Named by what the times follow from: the package's
    code, the time law's solver, the robot's files and limits, the model, its table and the
    time law of the gait it is for.
    """
    from importlib.metadata import version

    from gait_nodes.swing.policy import law_placements
    from gait_nodes.swing.still_body import GAIT
    from gait_nodes.swing.timing import PolynomialSwingTiming, TableSwingTiming

    robot = timing.robot
    description = robot.description
    digest = hashlib.sha256(source_digest().encode())
    digest.update(version('toppra').encode())  # the time law's solver
    digest.update(Path(description.urdf_path).read_bytes())
    digest.update(Path(description.path).read_bytes())
    # What the times follow from of a description that may differ from its file (a copy with
    # other limits, say).
    for values in (robot.velocity_limits_rad_s, robot.acceleration_limits_rad_s2,
                   description.nominal_stance_in_base(GAIT),
                   [foot.nominal_position_in_base for foot in description.feet],
                   [description.body_height_m]):
        digest.update(np.ascontiguousarray(values, dtype=float).tobytes())
    digest.update(repr((type(timing).__name__, timing.family, timing.factor)).encode())
    if isinstance(timing, TableSwingTiming):
        table = timing.policy.table
        digest.update(repr((table.joint_velocity_limit_rad_s, table.step_height_m,
                            table.ground_z_m, table.goal.tolist())).encode())
        digest.update(np.ascontiguousarray(table.values_s).tobytes())
        digest.update(np.ascontiguousarray(table.grid.points()).tobytes())
        digest.update(repr(law_placements(timing.gait)).encode())  # the swings' time law
    elif isinstance(timing, PolynomialSwingTiming):
        digest.update(repr(timing.step_height_m).encode())
    else:
        return None
    return cache_dir() / f'{kind}_{robot.name}_{digest.hexdigest()[:16]}.json'


def read_node_times(path: Path | None, names: tuple[str, ...]) -> dict[str, dict] | None:
    """The node times stored at ``path``: ``name -> {key tuple: time}``.

    None: none, or unreadable (they are computed again and stored anew).
    """
    if path is None:
        return None
    try:
        content = json.loads(path.read_text())
        return {name: {tuple(key): float(value) for key, value in content[name]}
                for name in names}
    except (OSError, ValueError, TypeError, KeyError):
        return None


def write_node_times(path: Path | None, times: dict[str, dict]) -> None:
    """Store node times (``name -> {key tuple: time}``) at ``path``.

    Atomically: planners of other processes may read them. A read-only cache keeps nothing.
    """
    if path is None:
        return
    content = {name: [[list(key), value] for key, value in values.items()]
               for name, values in times.items()}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(f'{path.name}.{os.getpid()}.tmp')
        partial.write_text(json.dumps(content))
        os.replace(partial, path)
    except OSError:
        pass
