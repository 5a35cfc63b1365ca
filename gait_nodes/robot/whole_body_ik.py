"""Whole-body IK: feet on their targets and the full-model COM on its reference.

The body stays level with the commanded yaw; its position is a free variable, so that the real
(multi-body) COM lands where the preview controller wants it: the thesis moves the body so that
the COM of the full model follows the cart-table COM (thesis III.B.1, Figure 7). Each foot's
contact point must reach its target; with ``foot_orientation: yaw`` the sole is also level with
the target yaw (thesis III.A). Unknowns: base position (3) and the IK joints of every limb;
equations: 3 or 6 per foot and 3 for the COM, a square system for every shipped robot.

The solver is Gauss-Newton with Levenberg-Marquardt damping ``lambda = |e|^2 + w`` (Sugihara
2011, "Solvability-unconcerned inverse kinematics by the Levenberg-Marquardt method"), which
converges quadratically to a reachable target and to the least-squares best effort otherwise;
joints are projected onto their URDF limits after every step. Warm-started from the previous
tick it needs one to three iterations.

Joint velocity limits are applied afterwards by :func:`limit_joint_velocity`: when the step
demands more than a joint's limit (or a share of it, ``share``), the whole step is scaled down
(the fastest joint saturated, as the thesis times its swing motions), which keeps every joint on
the straight line to the solution and reports which joints asked for more than their limit and
by how much.

The module also turns the public references into targets at one instant: COM state
(:func:`com_state_at`), swing waypoints (:func:`swing_pose_at`) and the fallback swing used when
no swing trajectory is there for a foot in swing (:func:`fallback_swing_pose`).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from gait_nodes.contract import ComState, FootstepPlan, Swing, SwingTrajectory
from gait_nodes.errors import ConfigError, ParameterError
from gait_nodes.robot.model import RobotModel, yaw_rotation

#: Sugihara's bias weight: keeps the damped system regular at singular configurations.
DAMPING_BIAS = 1e-9
#: Largest joint change in one Newton step [rad]; keeps a far target from jumping branches.
MAX_NEWTON_STEP_RAD = 0.4


@dataclass(frozen=True)
class IkSettings:
    """Tolerances and limits of the whole-body IK.

    Attributes:
        max_iterations: Newton iterations per solve.
        position_tolerance_m: Foot position error below which a foot is on target [m].
        orientation_tolerance_rad: Sole orientation error below which it is on target [rad].
        com_tolerance_m: COM error below which the COM is on target [m].
        vertical: What the COM target's height sets: ``'com'`` (default) the full-model COM's
            height itself; ``'base'`` the body's height, ``com_z + body_height_m -
            com_height_m`` (the robot YAML's heights: the base where it is at the nominal
            stance when the COM is there), the horizontal COM still on its target. The walk
            uses :func:`walking_vertical`'s choice for the robot.
    """

    max_iterations: int = 20
    position_tolerance_m: float = 1e-6
    orientation_tolerance_rad: float = 1e-6
    com_tolerance_m: float = 1e-6
    vertical: str = 'com'

    def __post_init__(self):
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) \
                or not 1 <= self.max_iterations <= 1000:
            raise ParameterError(f'max_iterations must be an integer in [1, 1000], got '
                                 f'{self.max_iterations!r}')
        for name in ('position_tolerance_m', 'orientation_tolerance_rad', 'com_tolerance_m'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 1e-12 <= value <= 1e-2):
                raise ParameterError(f'{name} must be in [1e-12, 1e-2], got {value!r}')
        if self.vertical not in ('base', 'com'):
            raise ParameterError(f"vertical must be 'base' or 'com', got {self.vertical!r}")


def walking_vertical(robot: RobotModel) -> str:
    """The vertical task of every solver of ``robot``'s walk (:attr:`IkSettings.vertical`).

    The IK node, the planner's timing probes and the multi-mass correction use it, so that they
    agree. A quadruped carries its body at a constant height (``'base'``; thesis III.B: the
    COB's trajectory is planned, the cart-table COM at a constant height): holding the COM's
    own height instead bobs the body against every lifted limb (a centimetre for RoboSimian's
    15 % limbs), and its swinging limb's joints run faster by as much. A biped keeps its COM at
    the linear inverted pendulum's height (``'com'``), as humanoid walkers do.
    """
    return 'base' if robot.description.kind == 'quadruped' else 'com'


@dataclass(frozen=True)
class IkTargets:
    """What the whole body must do at one instant (world frame ``odom``).

    Attributes:
        feet_in_world: (F, 3) contact point targets, in the robot's foot order [m].
        foot_yaws_rad: (F,) sole yaw targets [rad] (ignored for point feet).
        base_yaw_rad: Body yaw [rad]; roll and pitch are zero.
        com_in_world: (3,) COM target [m], or None to hold the base at ``base_position_in_world``.
        base_position_in_world: (3,) base position when ``com_in_world`` is None [m].
    """

    feet_in_world: np.ndarray
    foot_yaws_rad: np.ndarray
    base_yaw_rad: float = 0.0
    com_in_world: np.ndarray | None = None
    base_position_in_world: np.ndarray | None = None

    def __post_init__(self):
        feet = np.asarray(self.feet_in_world, dtype=float)
        yaws = np.asarray(self.foot_yaws_rad, dtype=float)
        if feet.ndim != 2 or feet.shape[1] != 3 or yaws.shape != (len(feet),):
            raise ValueError(f'targets: feet must be (F, 3) with (F,) yaws, got {feet.shape} '
                             f'and {yaws.shape}')
        if (self.com_in_world is None) == (self.base_position_in_world is None):
            raise ValueError('targets: give exactly one of com_in_world and '
                             'base_position_in_world')
        point = self.com_in_world if self.com_in_world is not None \
            else self.base_position_in_world
        if not (np.isfinite(feet).all() and np.isfinite(yaws).all()
                and math.isfinite(self.base_yaw_rad)
                and np.isfinite(np.asarray(point, dtype=float)).all()):
            raise ValueError('targets hold a NaN or infinite value')
        object.__setattr__(self, 'feet_in_world', feet)
        object.__setattr__(self, 'foot_yaws_rad', yaws)


@dataclass(frozen=True)
class IkResult:
    """A whole-body IK solution and how well it reaches the targets.

    Attributes:
        q: Pinocchio configuration (base pose, then the joints).
        converged: Every foot and the COM within the tolerances.
        iterations: Newton iterations used.
        foot_position_errors_m: (F,) distance of each contact point from its target [m].
        foot_orientation_errors_rad: (F,) sole orientation error (0 for point feet) [rad].
        com_error_m: Distance of the full-model COM from its target (0 without target) [m].
        joints_at_limit: IK joints sitting on a URDF position limit.
    """

    q: np.ndarray
    converged: bool
    iterations: int
    foot_position_errors_m: np.ndarray
    foot_orientation_errors_rad: np.ndarray
    com_error_m: float
    joints_at_limit: tuple[str, ...] = field(default=())


class WholeBodyIkSolver:
    """Solves :class:`IkTargets` for one robot; keeps its own Pinocchio data (not thread-safe).

    A 200 Hz tick is a handful of small Pinocchio calls (forward kinematics, one placement per
    foot, the COM; the joint Jacobians only when a step is taken) glued by numpy operations
    over arrays allocated once here, every foot at once: the Python around Pinocchio, not
    Pinocchio, is what a solve costs. Warm-started by :meth:`warm_start`, a walking tick
    usually converges to 1e-9 in one Newton step.

    Args:
        robot: The robot model.
        settings: Tolerances and iteration limit.
    """

    def __init__(self, robot: RobotModel, settings: IkSettings | None = None):
        self.robot = robot
        self.settings = settings or IkSettings()
        self.model = robot.model
        self.data = robot.new_data()
        self.joint_names = robot.ik_joint_names
        self._q_idx = robot.q_indices(self.joint_names)
        self._v_idx = robot.v_indices(self.joint_names)
        vector_idx = robot.indices(self.joint_names)
        self._lower = np.array(robot.lower_limits[vector_idx])
        self._upper = np.array(robot.upper_limits[vector_idx])
        self._orient = robot.foot_orientation == 'yaw'
        self._rows_per_foot = 6 if self._orient else 3
        self._frames = tuple(int(f) for f in robot.foot_frame_ids)
        self._frame_offset = np.array([0.0, 0.0, robot.foot_frame_height_m])
        self._offsets = np.array(robot.foot_rotation_offsets)
        # The IK joints' limits over the whole configuration (infinite elsewhere): one clip of
        # q is the clip of q[q_idx] (max/min with an infinite bound return the value itself).
        self._q_lower = np.full(self.model.nq, -np.inf)
        self._q_upper = np.full(self.model.nq, np.inf)
        self._q_lower[self._q_idx] = self._lower
        self._q_upper[self._q_idx] = self._upper
        self._work: dict[bool, _Workspace] = {}
        #: Base height minus the COM target's height with ``vertical: base`` (else None).
        self._base_above_com = (float(robot.description.body_height_m
                                      - robot.description.com_height_m)
                                if self.settings.vertical == 'base' else None)

    def _workspace(self, free_base: bool) -> _Workspace:
        work = self._work.get(free_base)
        if work is None:
            work = self._work[free_base] = _Workspace(
                self._frames, self._rows_per_foot, self.model.nv, self._v_idx,
                self._q_idx, self._lower, self._upper, free_base)
        return work

    def warm_start(self, solutions: Sequence[np.ndarray],
                   times_s: Sequence[float] | None = None,
                   at_s: float | None = None) -> np.ndarray:
        """Where to start the next tick's solve, from the last solutions (oldest first).

        The quadratic extrapolation of the last three (constant joint and base accelerations),
        the linear one of two, or the last; joints within their limits. A walking tick then
        starts within about the square root of the tolerance of its solution, where one Newton
        step reaches it. Without ``times_s`` the solutions are one tick apart and the next is
        one tick later; with ``times_s`` (their times [s]) and ``at_s`` (the next one's [s]) the
        extrapolation follows the real spacing (ticks late or early on a loaded machine: an
        equal-spacing guess would put its error into the redundant joints, which the Newton
        step does not correct).
        """
        if times_s is not None and at_s is not None and len(solutions) >= 2:
            q = _lagrange(solutions[-3:], times_s[-3:], at_s)
        elif len(solutions) >= 3:
            # 3 (s[-1] - s[-2]) + s[-3], in place: the same roundings, fewer arrays.
            q = np.subtract(solutions[-1], solutions[-2])
            q *= 3.0
            q += solutions[-3]
        elif len(solutions) == 2:
            q = 2.0 * solutions[-1] - solutions[-2]
        else:
            return np.array(solutions[-1], dtype=float)
        # (the clip ufunc: maximum, then minimum, in one call)
        return np.clip(q, self._q_lower, self._q_upper, out=q)

    def solve(self, targets: IkTargets, q_start: np.ndarray) -> IkResult:
        """Configuration reaching ``targets``, starting the iteration at ``q_start``.

        The base orientation in ``q_start`` is replaced by the target yaw (level body).
        Never returns NaN: a target out of reach gives the least-squares best effort with the
        residuals in the result.
        """
        feet_count = len(self._frames)
        if targets.feet_in_world.shape != (feet_count, 3):
            raise ValueError(f'{self.robot.name} has {feet_count} feet, targets give '
                             f'{len(targets.feet_in_world)}')
        return self.solve_trusted(targets.feet_in_world, targets.foot_yaws_rad.tolist(),
                                  targets.base_yaw_rad, q_start, targets.com_in_world,
                                  targets.base_position_in_world)

    def solve_trusted(self, feet_in_world, foot_yaws_rad: list[float], base_yaw_rad: float,
                      q_start: np.ndarray, com_in_world=None,
                      base_position_in_world=None) -> IkResult:
        """:meth:`solve` for the fields of an :class:`IkTargets` that nobody checks here.

        For a caller that validated its references once, where they entered (the
        whole_body_ik node: contract-checked messages), and would otherwise pay the checks
        of a new :class:`IkTargets` at every tick. The caller vouches for what
        :class:`IkTargets` checks: ``feet_in_world`` (F, 3) [m] (an array or nested lists)
        and ``foot_yaws_rad`` (F,) [rad] as a list, all finite, and exactly one of
        ``com_in_world`` and ``base_position_in_world`` (3,) [m].
        """
        model, data = self.model, self.data
        frames = self._frames
        feet_count = len(frames)
        settings = self.settings
        # Small-array numpy calls are what a solve costs (about 1 us each; pinocchio's are
        # cheaper): np.dot rather than @ for products (the same BLAS call, less dispatch),
        # arrays and views made once in the workspace, scalars set one by one.
        dot = np.dot
        q = np.array(q_start, dtype=float)
        if not math.isfinite(dot(q, q)) and not np.isfinite(q).all():  # (one cheap test)
            raise ValueError('q_start holds a NaN or infinite value')
        half = 0.5 * base_yaw_rad
        q[3] = q[4] = 0.0
        q[5] = math.sin(half)
        q[6] = math.cos(half)
        free_base = com_in_world is not None
        if not free_base:
            q[:3] = base_position_in_world
        work = self._workspace(free_base)
        if work.settings is not settings:
            work.weigh(settings)
        # The feet's frame targets go into the error map's constant row (see _Workspace).
        np.add(feet_in_world, self._frame_offset, out=work.frame_targets)
        orient = self._orient
        if orient:
            work.aim_soles(foot_yaws_rad, self._offsets)
        com_target = np.asarray(com_in_world, dtype=float) if free_base else None
        base_height = (None if not free_base or self._base_above_com is None
                       else float(com_target[2]) + self._base_above_com)
        error, full = work.error, work.full
        placements_flat, error_map, mapped = work.placements_flat, work.error_map, work.mapped
        traces, com_error = work.traces, work.com_error
        jacobian, transposed, normal = work.jacobian, work.transposed, work.normal
        normal_fortran, normal_diagonal, columns = work.normal.T, work.normal_diagonal, \
            work.columns
        base_cols, x_idx = work.base_cols, work.x_idx
        x_lower, x_upper, weights = work.x_lower, work.x_upper, work.weights
        unknowns = q[x_idx]  # base translation (free base), then the IK joints
        world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        placement, frame_jacobian = pin.updateFramePlacement, pin.getFrameJacobian
        foot_placements, foot_blocks, com_block = work.foot_placements, work.foot_blocks, \
            work.com_block
        point_feet = work.rows_per_foot != 6
        iteration = 0
        while True:
            pin.forwardKinematics(model, data, q)
            for view, frame in foot_placements:
                view[...] = placement(model, data, frame).homogeneous
            # Foot position errors, sole orientation errors (small-angle) and the soles'
            # relative rotation traces: one affine map of the placements.
            dot(placements_flat, error_map, out=mapped)
            if orient and min(traces.tolist()) <= SMALL_ANGLE_TRACE:
                work.large_orientation_errors()
            if free_base:
                np.subtract(com_target, pin.centerOfMass(
                    model, data, pin.KinematicLevel.POSITION, False), out=com_error)
                if base_height is not None:  # the body's height, not the COM's
                    com_error[2] = base_height - q[2]
            squares = error * error
            # Every foot's and the COM's squared error over its squared tolerance (at most 1
            # each when converged), then the plain sum of squares (the damping).
            *scaled, damping = dot(squares, weights).tolist()
            converged = max(scaled) <= 1.0
            if converged or iteration >= settings.max_iterations:
                break
            iteration += 1
            pin.computeJointJacobians(model, data)
            for view, frame in foot_blocks:
                block = frame_jacobian(model, data, frame, world)
                view[...] = block[:3] if point_feet else block
            if free_base:
                com_block[...] = pin.jacobianCenterOfMass(model, data, False)
                if base_height is not None:
                    com_block[2] = 0.0  # the row is the base's height: its column alone
            full.take(columns, 1, jacobian, 'clip')  # the unknowns' columns (all valid)
            # Levenberg-Marquardt step (J^T J + lambda I) dx = J^T e, by Cholesky.
            np.matmul(transposed, jacobian, out=normal)  # (matmul's syrk)
            normal_diagonal += damping + DAMPING_BIAS
            # (lower=0, overwrite_a=1, overwrite_b=1 positionally: f2py parses keywords slowly;
            # the symmetric matrix passed as its Fortran-ordered transpose: factored in place)
            _, step, info = lapack.dposv(normal_fortran, dot(transposed, error), 0, 1, 1)
            if info != 0:  # not reached with lambda > 0; keep the iteration defined anyway
                step = np.linalg.lstsq(jacobian, error, rcond=None)[0]
            values = step.tolist()
            largest = max(map(abs, values[base_cols:]), default=0.0)
            if largest > MAX_NEWTON_STEP_RAD:
                step *= MAX_NEWTON_STEP_RAD / largest
            unknowns += step
            np.maximum(unknowns, x_lower, out=unknowns)
            np.minimum(unknowns, x_upper, out=unknowns)
            q[x_idx] = unknowns
        norms = np.sqrt(dot(squares, work.groups))  # feet positions, orientations, COM
        joints = unknowns[base_cols:]
        margins = np.minimum(joints - self._lower, self._upper - joints).tolist()
        at_limit = () if min(margins, default=1.0) > 1e-9 else tuple(
            name for name, margin in zip(self.joint_names, margins, strict=True)
            if margin <= 1e-9)
        return IkResult(q=q, converged=converged, iterations=iteration,
                        foot_position_errors_m=norms[:feet_count],
                        foot_orientation_errors_rad=norms[feet_count:2 * feet_count] if orient
                        else np.zeros(feet_count),
                        com_error_m=float(norms[-1]) if free_base else 0.0,
                        joints_at_limit=at_limit)


#: Maps a row-major flattened rotation E to (vee(E - E^T) / 2, trace(E)).
VEE_AND_TRACE = np.zeros((9, 4))
VEE_AND_TRACE[[7, 2, 3], [0, 1, 2]] = 0.5
VEE_AND_TRACE[[5, 6, 1], [0, 1, 2]] = -0.5
VEE_AND_TRACE[[0, 4, 8], 3] = 1.0
#: trace(E) = 1 + 2 cos(a) above this: rotation angle a below 1e-4 rad.
SMALL_ANGLE_TRACE = 1.0 + 2.0 * math.cos(1e-4)
#: ``dot(R_target.ravel(), SOLE_MAP)`` is the (16, 4) linear map from a foot's flattened
#: homogeneous placement (rotation R) to (vee(E - E^T) / 2, trace(E)) of E = R_target R^T:
#: E[a, b] = sum_c R_target[a, c] R[b, c], and R[b, c] is the placement's entry 4 b + c.
SOLE_MAP = np.zeros((9, 16, 4))
for _e, _m in zip(*np.nonzero(VEE_AND_TRACE), strict=True):
    for _c in range(3):
        SOLE_MAP[3 * (_e // 3) + _c, 4 * (_e % 3) + _c, _m] += VEE_AND_TRACE[_e, _m]
SOLE_MAP = SOLE_MAP.reshape(9, 64)
del _e, _m, _c


class _Workspace:
    """Arrays one solver reuses on every solve (free or fixed base).

    ``full`` holds the stacked task Jacobian over Pinocchio's whole velocity vector, plus three
    constant columns: the world-frame base translation moves every foot and the COM one to
    one. ``columns`` picks the unknowns out of it (base translation, then the IK joints).

    ``error_map`` is the affine map from the feet's homogeneous placements (flattened, their
    constant 1 included) to ``mapped``: the soles' traces of ``E = R_target R^T`` (6-row feet),
    then every foot's position error ``target - p`` (exact: -1 on p, the target on the 1, zero
    elsewhere) and small-angle orientation error ``vee(E - E^T) / 2`` (the rotation vector to a
    relative 2e-9 below 1e-4 rad), which is ``error`` without the COM rows. Its rotation part
    changes only with the sole yaw targets (:meth:`aim_soles`: stance feet keep theirs).
    """

    def __init__(self, frames: tuple[int, ...], rows_per_foot: int, nv: int, v_idx: np.ndarray,
                 q_idx: np.ndarray, lower: np.ndarray, upper: np.ndarray, free_base: bool):
        feet_count = len(frames)
        rows = feet_count * rows_per_foot + (3 if free_base else 0)
        self.rows_per_foot = rows_per_foot
        self.full = np.zeros((rows, nv + 3))
        # Each foot's block of the Pinocchio columns of ``full``.
        # Each foot's block of the Pinocchio columns of ``full`` and the COM's, as views (an
        # assignment to a view skips the indexing of ``full[rows, cols]``), with their frames.
        self.foot_blocks = [(self.full[k * rows_per_foot:(k + 1) * rows_per_foot, :nv], frame)
                            for k, frame in enumerate(frames)]
        self.com_block = self.full[-3:, :nv] if free_base else None
        self.base_cols = 3 if free_base else 0
        base = np.arange(3 if free_base else 0)
        if free_base:
            for k in range(feet_count):
                r = k * rows_per_foot
                self.full[r:r + 3, -3:] = np.eye(3)
            self.full[-3:, -3:] = np.eye(3)
        self.columns = np.concatenate([np.arange(nv, nv + len(base)), v_idx])
        # The unknowns in q (base translation, joints) and their bounds.
        self.x_idx = np.concatenate([base, q_idx])
        self.x_lower = np.concatenate([np.full(len(base), -np.inf), lower])
        self.x_upper = np.concatenate([np.full(len(base), np.inf), upper])
        unknowns = len(self.columns)
        self.jacobian = np.zeros((rows, unknowns))
        self.transposed = self.jacobian.T
        self.normal = np.zeros((unknowns, unknowns))
        self.normal_diagonal = self.normal.reshape(-1)[::unknowns + 1]
        # ``evaluation``: the traces (6-row feet), then the error vector.
        orientation = rows_per_foot == 6
        trace_count = feet_count if orientation else 0
        foot_errors = feet_count * rows_per_foot
        self.evaluation = np.zeros(trace_count + rows)
        self.traces = self.evaluation[:trace_count]
        self.error = self.evaluation[trace_count:]
        self.mapped = self.evaluation[:trace_count + foot_errors]
        self.per_foot = self.error[:foot_errors].reshape(feet_count, rows_per_foot)
        self.com_error = self.error[-3:] if free_base else None
        # Foot frame placements (homogeneous matrices) and views of them.
        self.placements = np.zeros((feet_count, 4, 4))
        self.placements_flat = self.placements.reshape(-1)
        self.foot_placements = list(zip(self.placements, frames, strict=True))
        self.error_map = np.zeros((16 * feet_count, trace_count + foot_errors))
        outputs = self.error_map.shape[1]
        for k in range(feet_count):
            for i in range(3):
                self.error_map[16 * k + 4 * i + 3, trace_count + k * rows_per_foot + i] = -1.0
        #: (F, 3) view of the error map's target entries (the placements' 1 to each error).
        self.frame_targets = np.lib.stride_tricks.as_strided(
            self.error_map[15:, trace_count:], (feet_count, 3),
            ((16 * outputs + rows_per_foot) * 8, 8))
        # Each foot's sole block of the error map: its placement rows, (vee, trace) columns.
        self.sole_blocks = [(np.arange(16 * k, 16 * k + 16)[:, None],
                             np.array([trace_count + k * rows_per_foot + 3 + m
                                       for m in range(3)] + [k])[None, :])
                            for k in range(feet_count)]
        self.yaws: list[float | None] = [None] * feet_count
        self.rotation_targets = np.zeros((feet_count, 3, 3))
        self.relative = np.zeros((feet_count, 3, 3))
        # Sums the squared errors into norms: each foot's position, each foot's orientation
        # (6-row feet), the COM (free base); ``weights`` divides them by their tolerances and
        # adds a last column of ones (the sum of all squares).
        self.groups = np.zeros((rows, (2 if orientation else 1) * feet_count + 1))
        for k in range(feet_count):
            r = k * rows_per_foot
            self.groups[r:r + 3, k] = 1.0
            if orientation:
                self.groups[r + 3:r + 6, feet_count + k] = 1.0
        if free_base:
            self.groups[-3:, -1] = 1.0
        self.weights = None
        self.settings = None

    def weigh(self, settings: IkSettings) -> None:
        """Scale :attr:`weights` to ``settings``' tolerances."""
        feet_count = len(self.per_foot)
        scale = np.full(self.groups.shape[1], settings.position_tolerance_m ** -2)
        scale[feet_count:-1] = settings.orientation_tolerance_rad ** -2
        scale[-1] = settings.com_tolerance_m ** -2
        self.weights = np.column_stack([self.groups * scale, np.ones(len(self.groups))])
        self.settings = settings

    def aim_soles(self, yaws_rad: list[float], offsets: np.ndarray) -> None:
        """Point the error map's sole blocks at the yaw targets (those that changed)."""
        for k, yaw in enumerate(yaws_rad):
            if yaw != self.yaws[k]:
                target = self.rotation_targets[k] = yaw_rotation(yaw) @ offsets[k]
                rows, cols = self.sole_blocks[k]
                self.error_map[rows, cols] = np.dot(target.reshape(9), SOLE_MAP).reshape(16, 4)
                self.yaws[k] = yaw

    def large_orientation_errors(self) -> None:
        """Sole orientation errors ``log3(R_target R^T)`` (world frame), foot by foot.

        For a sole 1e-4 rad or more off its target, where the error map's small-angle form
        (``sin(a) = a``) is no longer the rotation vector.
        """
        np.matmul(self.rotation_targets, self.placements[:, :3, :3].transpose(0, 2, 1),
                  out=self.relative)
        for k, relative in enumerate(self.relative):
            self.per_foot[k, 3:] = pin.log3(relative)


# -- seeds and the nominal stance -------------------------------------------------------------


def limb_ik_family(robot: RobotModel) -> int | None:
    """The default IK family of a robot with closed-form limb IK (``extra.limb_ik``), or None."""
    settings = robot.description.extra.get('limb_ik')
    if settings is None:
        return None
    if not isinstance(settings, dict) or settings.get('kind') != 'robosimian':
        raise ConfigError(f'{robot.description.path}: extra.limb_ik: must be {{kind: '
                          f'robosimian, family: 0..7}}, got {settings!r}')
    family = settings.get('family', 2)
    from gait_nodes.robot.limb_ik import family_bits

    try:
        family_bits(family)
    except ConfigError as exc:
        raise ConfigError(f'{robot.description.path}: extra.limb_ik.family: {exc}') from None
    return int(family)


def seed_configuration(robot: RobotModel, targets: IkTargets, family: int | None = None,
                       base_position_in_world=None) -> np.ndarray:
    """A start for the IK: the posture, or the closed-form limb IK when the robot has one.

    Seeding from the limb IK in ``family`` keeps the whole-body solution in that family.
    """
    if base_position_in_world is None:
        base_position_in_world = (targets.base_position_in_world
                                  if targets.base_position_in_world is not None
                                  else np.asarray(targets.com_in_world)
                                  + np.array([0.0, 0.0, robot.description.body_height_m
                                              - robot.description.com_height_m]))
    q = robot.configuration(base_position_in_world, targets.base_yaw_rad)
    if family is None:
        family = limb_ik_family(robot)
    if family is None:
        return q
    limb_ik = robosimian_limb_ik(robot)
    rotation = yaw_rotation(targets.base_yaw_rad)
    in_base = (targets.feet_in_world - np.asarray(base_position_in_world)) @ rotation
    joints = robot.joint_positions(q)
    for k, foot in enumerate(robot.description.feet):
        angles, _ = limb_ik.solve(in_base[k:k + 1], targets.foot_yaws_rad[k:k + 1]
                                  - targets.base_yaw_rad, family, foot.name)
        joints[robot.indices(foot.joints)] = angles[0]
    robot.set_joint_positions(q, joints)
    return q


_LIMB_IK_CACHE: dict[int, object] = {}


def robosimian_limb_ik(robot: RobotModel):
    """The (cached) :class:`gait_nodes.robot.limb_ik.RoboSimianLimbIk` of ``robot``."""
    from gait_nodes.robot.limb_ik import RoboSimianLimbIk

    key = id(robot)
    cached = _LIMB_IK_CACHE.get(key)
    if cached is None or cached.robot is not robot:
        cached = _LIMB_IK_CACHE[key] = RoboSimianLimbIk(robot)
    return cached


def nominal_configuration(robot: RobotModel, family: int | None = None,
                          base_position_in_world=None, base_yaw_rad: float = 0.0,
                          solver: WholeBodyIkSolver | None = None) -> np.ndarray:
    """The standing configuration: level base, every foot at its YAML nominal position.

    The base is at ``body_height_m`` above the origin unless a position and yaw are given.

    Raises:
        ConfigError: The nominal stance is out of reach of the legs.
    """
    if base_position_in_world is None:
        base_position_in_world = np.array([0.0, 0.0, robot.description.body_height_m])
    feet = robot.nominal_feet_in_world(base_position_in_world, base_yaw_rad)
    targets = IkTargets(feet, np.full(len(feet), base_yaw_rad), base_yaw_rad,
                        base_position_in_world=np.asarray(base_position_in_world, dtype=float))
    solver = solver or WholeBodyIkSolver(robot, IkSettings(max_iterations=200))
    result = solver.solve(targets, seed_configuration(robot, targets, family))
    if result.foot_position_errors_m.max() > 1e-4:
        raise ConfigError(f'{robot.description.path}: the nominal stance is out of reach: foot '
                          f'errors {np.round(result.foot_position_errors_m, 4).tolist()} m')
    return result.q


# -- joint velocity limits --------------------------------------------------------------------


@dataclass(frozen=True)
class VelocitySaturation:
    """How much a step asked of the joint velocity limits.

    Attributes:
        ratio: Largest demanded velocity over its limit (<= 1: no saturation).
        joints: Joints whose demanded velocity exceeded their limit.
        demanded_over_limit: Demanded/limit ratio of each of ``joints``.
        share: The share of the limits the step was kept within (a step that asked for more
            than that share but within the limits was scaled down to it, and is not
            saturated).
    """

    ratio: float
    joints: tuple[str, ...] = ()
    demanded_over_limit: tuple[float, ...] = ()
    share: float = 1.0

    @property
    def saturated(self) -> bool:
        """Whether the step asked for more than the limits (and was scaled down)."""
        return self.ratio > 1.0

    @property
    def scaled(self) -> bool:
        """Whether the step was scaled down (saturated, or above ``share`` of the limits)."""
        return self.ratio > self.share


def limit_joint_velocity(robot: RobotModel, q_previous: np.ndarray, q_target: np.ndarray,
                         dt_s: float, share: float = 1.0
                         ) -> tuple[np.ndarray, np.ndarray, VelocitySaturation]:
    """Move from ``q_previous`` towards ``q_target`` within the joint velocity limits.

    Args:
        robot: The robot (joint velocity limits from its YAML).
        q_previous: Configuration commanded at the previous tick.
        q_target: Configuration the IK asks for now.
        dt_s: Time since the previous tick [s].
        share: Share of the limits, in (0, 1], the step is kept within.

    Returns:
        ``(q, joint_velocities, saturation)``: the configuration to command (the whole step,
        base included, scaled down when some joint asks for more than ``share`` of its limit),
        the joint vector velocities [rad/s] (never above ``share`` of the limits) and the
        saturation report.
    """
    q, _, velocities, saturation = limit_joint_step(
        robot, q_previous, robot.joint_positions(q_previous), q_target, dt_s, share)
    return q, velocities, saturation


def limit_joint_step(robot: RobotModel, q_previous: np.ndarray, previous_joints: np.ndarray,
                     q_target: np.ndarray, dt_s: float, share: float = 1.0
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, VelocitySaturation]:
    """:func:`limit_joint_velocity` for a caller that keeps its last command's joint vector.

    Args:
        robot: The robot (joint velocity limits from its YAML).
        q_previous: Configuration commanded at the previous tick.
        previous_joints: ``robot.joint_positions(q_previous)`` [rad].
        q_target: Configuration the IK asks for now.
        dt_s: Time since the previous tick [s].
        share: Share of the limits, in (0, 1], the step is kept within.

    Returns:
        ``(q, joints, joint_velocities, saturation)`` as :func:`limit_joint_velocity`, with
        ``joints = robot.joint_positions(q)`` [rad] (the next call's ``previous_joints``).
    """
    if not dt_s > 0:
        raise ValueError(f'dt_s must be > 0, got {dt_s}')
    if not 0.0 < share <= 1.0:
        raise ValueError(f'share must be in (0, 1], got {share}')
    target = robot.joint_positions(q_target)
    step = target - previous_joints
    limits = robot.velocity_limits_rad_s
    demanded = np.abs(step) / (limits * dt_s)
    ratio = max(demanded.tolist(), default=0.0)
    if ratio <= share:
        return (np.array(q_target, dtype=float), target, step / dt_s,
                VelocitySaturation(ratio, share=share))
    # Scale a hair more than needed so that rounding never leaves a joint above its share.
    scale = share * (1.0 - 1e-12) / ratio
    q = np.array(q_previous, dtype=float)
    q[:3] += scale * (q_target[:3] - q_previous[:3])
    q[3:7] = q_target[3:7]
    joints = previous_joints + scale * step
    robot.set_joint_positions(q, joints)
    over = np.flatnonzero(demanded > 1.0)
    order = over[np.argsort(-demanded[over])]
    report = VelocitySaturation(ratio, tuple(robot.joint_names[k] for k in order),
                                tuple(float(demanded[k]) for k in order), share)
    return q, robot.joint_positions(q), scale * step / dt_s, report


# -- the commanded joint trajectory ------------------------------------------------------------


class JointKnots:
    """The IK's solved knots: a short joint trajectory, sent as windows of it.

    Knot ``k`` is a joint vector [rad] at ``times_ns[k]``, each reached from the one before
    within the joint velocity limits (:func:`limit_joint_step`). Its velocity [rad/s] is the
    trajectory's derivative there: the central difference of its two neighbours (for uneven
    spacing the time-weighted mean of the two step velocities, so never above the limits the
    steps keep), computed once when the next knot comes; the last knot has its backward
    difference until then; the first knot of a :meth:`restart` starts from rest (zero).
    Positions and velocities are kept as Python lists too: each knot goes into several
    messages, converted once. Each knot may carry a ``state`` of the caller's (what it needs to
    solve on from that knot), given back by :meth:`truncate_after`.

    Args:
        joint_count: Length of a joint vector.
    """

    __slots__ = ('times_ns', 'joints', 'positions', 'velocities', 'states', '_steps', '_step_ns',
                 '_zero')

    def __init__(self, joint_count: int):
        self._zero = [0.0] * joint_count
        self.times_ns: list[int] = []
        self.joints: list[np.ndarray] = []
        self.positions: list[list[float]] = []
        #: Knot velocities, None for the last knot (its backward difference is ``_steps[-1]``).
        self.velocities: list[list[float] | None] = []
        self.states: list[object] = []
        self._steps: list[np.ndarray | None] = []  # velocity of the step into each knot
        self._step_ns = 0  # duration of the step into the last knot [ns]

    def __len__(self) -> int:
        return len(self.times_ns)

    def restart(self, stamp_ns: int, joints: np.ndarray, state: object = None) -> None:
        """Forget every knot; the trajectory starts at rest at ``joints`` at ``stamp_ns``."""
        self.times_ns[:] = [stamp_ns]
        self.joints[:] = [np.array(joints, dtype=float)]
        self.positions[:] = [self.joints[0].tolist()]
        self.velocities[:] = [None]
        self.states[:] = [state]
        self._steps[:] = [None]

    def append(self, stamp_ns: int, joints: np.ndarray, step_velocity: np.ndarray,
               state: object = None) -> None:
        """Add the knot ``joints`` at ``stamp_ns``, reached with ``step_velocity`` [rad/s].

        ``stamp_ns`` is after the last knot's; ``step_velocity`` is ``(joints - last) / dt``.
        """
        if not self.times_ns:
            raise ValueError('JointKnots.append before restart: no knot to step from')
        last_step = self._steps[-1]
        after = stamp_ns - self.times_ns[-1]
        if last_step is None:
            self.velocities[-1] = self._zero
        else:
            before = self._step_ns
            self.velocities[-1] = ((before * last_step + after * step_velocity)
                                   / (before + after)).tolist()
        self._step_ns = after
        self.times_ns.append(stamp_ns)
        self.joints.append(joints)
        self.positions.append(joints.tolist())
        self.velocities.append(None)
        self.states.append(state)
        self._steps.append(step_velocity)

    def truncate_after(self, stamp_ns: int) -> object:
        """Forget the knots after ``stamp_ns`` (never the first); the new last knot's state.

        The last knot kept gets its backward difference again until a knot follows it.
        """
        keep = max(bisect.bisect_right(self.times_ns, stamp_ns), 1)
        if keep < len(self.times_ns):
            for values in (self.times_ns, self.joints, self.positions, self.velocities,
                           self.states, self._steps):
                del values[keep:]
            self.velocities[-1] = None
            if keep > 1:
                self._step_ns = self.times_ns[-1] - self.times_ns[-2]
        return self.states[-1]

    def first_at_or_before(self, stamp_ns: int) -> int:
        """Index of the latest knot at or before ``stamp_ns`` (0 if every knot is later)."""
        return max(bisect.bisect_right(self.times_ns, stamp_ns) - 1, 0)

    def drop_before(self, index: int) -> None:
        """Forget the knots before ``index`` (their velocities are already in the later ones)."""
        if index > 0:
            for values in (self.times_ns, self.joints, self.positions, self.velocities,
                           self.states, self._steps):
                del values[:index]

    def window(self, start: int, ends_at_rest: bool = False
               ) -> tuple[list[int], list[list[float]], list[list[float]]]:
        """Times [ns], positions [rad] and velocities [rad/s] of the knots from ``start`` on.

        The last knot's velocity is its backward difference, or zero if ``ends_at_rest`` (no
        knot will follow it soon: the trajectory stops there).
        """
        velocities = self.velocities[start:]
        last_step = self._steps[-1]
        velocities[-1] = self._zero if last_step is None or ends_at_rest \
            else last_step.tolist()
        return self.times_ns[start:], self.positions[start:], velocities


# -- references at one instant ----------------------------------------------------------------


def _wrap(angle):
    return np.angle(np.exp(1j * np.asarray(angle)))


def com_state_at(states: Sequence[ComState], stamp_ns: int,
                 max_extrapolation_s: float = 0.05) -> tuple[np.ndarray, float]:
    """COM position [m] and body yaw [rad] at ``stamp_ns`` from a COM reference message.

    Hermite between the message's points (:class:`ComTrack`); before the first point, the
    first; after the last, extrapolated with its velocity for at most ``max_extrapolation_s``,
    then held.
    """
    position, yaw = ComTrack.from_states(states).at(stamp_ns, max_extrapolation_s)
    return np.array(position), yaw


def swing_pose_at(trajectory: SwingTrajectory, stamp_ns: int) -> tuple[np.ndarray, float]:
    """Foot position [m] and yaw [rad] on a swing trajectory, linear between waypoints.

    Before the first waypoint, the first; after the last, the last. The yaw turns the short
    way round between two waypoints (it is defined modulo 2 pi).
    """
    position, yaw = SwingPath(trajectory).pose_at(stamp_ns)
    return np.array(position), yaw


def _smoothstep(s: float) -> float:
    """Quintic 0 -> 1 with zero velocity and acceleration at both ends."""
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def fallback_swing_pose(swing: Swing, t_s: float, step_height_m: float
                        ) -> tuple[np.ndarray, float]:
    """Foot pose in a swing the swing-leg policy did not send a trajectory for.

    The foot moves from its lift-off to its landing place along a quintic smoothstep in time
    (zero velocity and acceleration at both ends), horizontally and in yaw, and is lifted by
    ``step_height_m * sin^2(pi s)`` above the straight line (``s`` the swing phase), so that it
    leaves and reaches the ground vertically at rest.

    Args:
        swing: The swing, from the footstep plan.
        t_s: Time from the plan start [s].
        step_height_m: Peak lift [m].
    """
    position, yaw = _FallbackSwing(swing).pose_at(t_s, step_height_m)
    return np.array(position), yaw


# -- references prepared for sampling at every tick -------------------------------------------
#
# The node samples its references 200 times a second and each message many times: these
# classes convert a message's arrays to Python floats once, so that a sample is a few float
# operations (numpy costs about a microsecond per call on a 3-vector). Every sample is the
# same IEEE-754 double arithmetic, in the same order, as the numpy formulas they replace
# (elementwise float64 add/multiply/divide round exactly like Python floats): the public
# functions above are these classes, and test_whole_body_ik checks them bit for bit against
# straightforward numpy versions.


class SwingPath:
    """A :class:`SwingTrajectory`, ready to be sampled by :meth:`pose_at` at every tick.

    Args:
        trajectory: The swing trajectory (validated by the contract: finite, times sorted).
    """

    __slots__ = ('start_ns', 'end_ns', '_times', '_positions', '_yaws')

    def __init__(self, trajectory: SwingTrajectory):
        self.start_ns = trajectory.start_ns
        #: Touch-down [ns]: the trajectory covers ``start_ns <= t <= end_ns``.
        self.end_ns = trajectory.start_ns + int(round(trajectory.duration_s * 1e9))
        self._times = trajectory.times_s.tolist()
        self._positions = trajectory.positions_in_world.tolist()
        self._yaws = trajectory.yaws_rad.tolist()

    def covers(self, stamp_ns: int) -> bool:
        """Whether ``stamp_ns`` is within the swing (lift-off to touch-down, both included)."""
        return self.start_ns <= stamp_ns <= self.end_ns

    def pose_at(self, stamp_ns: int) -> tuple[list[float], float]:
        """Foot position [m] and yaw [rad] at ``stamp_ns`` (see :func:`swing_pose_at`)."""
        t = (stamp_ns - self.start_ns) * 1e-9
        times, positions, yaws = self._times, self._positions, self._yaws
        k = bisect.bisect_right(times, t) - 1
        if k < 0:
            return list(positions[0]), yaws[0]
        if k >= len(times) - 1:
            return list(positions[-1]), yaws[-1]
        # times[k] <= t < times[k + 1]: a segment of positive duration.
        w = (t - times[k]) / (times[k + 1] - times[k])
        (ax, ay, az), (bx, by, bz) = positions[k], positions[k + 1]
        yaw = yaws[k]
        return ([ax + w * (bx - ax), ay + w * (by - ay), az + w * (bz - az)],
                yaw + w * math.remainder(yaws[k + 1] - yaw, 2.0 * math.pi))


class _FallbackSwing:
    """A plan's :class:`Swing`, ready for :func:`fallback_swing_pose` at every tick."""

    __slots__ = ('lift_off_s', 'touch_down_s', '_duration_s', '_start', '_delta', '_yaw',
                 '_turn')

    def __init__(self, swing: Swing):
        self.lift_off_s = swing.lift_off_s
        self.touch_down_s = swing.touch_down_s
        self._duration_s = swing.duration_s
        self._start = [float(x) for x in swing.start_in_world]
        # end - start and the short-way yaw turn, as the per-sample formula computed them.
        self._delta = (np.asarray(swing.end_in_world, dtype=float)
                       - np.asarray(swing.start_in_world, dtype=float)).tolist()
        self._yaw = swing.start_yaw_rad
        self._turn = float(_wrap(swing.end_yaw_rad - swing.start_yaw_rad))

    def pose_at(self, t_s: float, step_height_m: float) -> tuple[list[float], float]:
        """Foot position [m] and yaw [rad] at ``t_s`` from the plan start."""
        duration = self._duration_s
        s = (t_s - self.lift_off_s) / duration if duration > 0 else 1.0
        s = min(max(s, 0.0), 1.0)
        blend = _smoothstep(s)
        (x, y, z), (dx, dy, dz) = self._start, self._delta
        return ([x + blend * dx, y + blend * dy,
                 z + blend * dz + step_height_m * math.sin(math.pi * s) ** 2],
                self._yaw + blend * self._turn)


class ComTrack:
    """COM reference states, interpolated at any instant: the track the IK follows.

    Between two points the position is the quintic Hermite polynomial of their positions,
    velocities and accelerations (the cubic one of positions and velocities when the track has
    no accelerations), and the yaw the cubic Hermite polynomial of their yaws (the difference
    wrapped to (-pi, pi]) and yaw rates. So a track of a generator's states sampled every few
    ticks reproduces them between the samples (to the size of the generator's jerk changes),
    and position, velocity and acceleration are continuous across points. Before the first
    point: the first; after the last: extrapolated with its velocity for at most
    ``max_extrapolation_s``, then held.

    A new message replaces the held track from its first point on (:meth:`spliced`).

    Args:
        stamps_ns: (N,) state times [ns], strictly increasing, at least one.
        positions_in_world: (N, 3) COM positions [m].
        velocities_in_world: (N, 3) COM velocities [m/s].
        yaws_rad: (N,) body yaws [rad].
        yaw_rates_rad_s: (N,) body yaw rates [rad/s].
        accelerations_in_world: (N, 3) COM accelerations [m/s^2]; None: cubic in position.
    """

    __slots__ = ('_stamps', '_positions', '_velocities', '_accelerations', '_yaws',
                 '_yaw_rates', '_segment')

    def __init__(self, stamps_ns: Sequence[int], positions_in_world: Sequence[Sequence[float]],
                 velocities_in_world: Sequence[Sequence[float]], yaws_rad: Sequence[float],
                 yaw_rates_rad_s: Sequence[float],
                 accelerations_in_world: Sequence[Sequence[float]] | None = None):
        if len(stamps_ns) == 0:
            raise ValueError('no COM states')
        # Kept as given (read, never written).
        self._stamps = stamps_ns
        self._positions = positions_in_world
        self._velocities = velocities_in_world
        self._accelerations = accelerations_in_world
        self._yaws = yaws_rad
        self._yaw_rates = yaw_rates_rad_s
        self._segment = 0  # the segment of the last query (the next is usually the same)

    @classmethod
    def from_states(cls, states: Sequence[ComState]) -> ComTrack:
        """The track of the :class:`ComState` list of a /gait/com_reference message."""
        if not states:
            raise ValueError('no COM states')
        return cls([s.stamp_ns for s in states],
                   [np.asarray(s.position_in_world, dtype=float).tolist() for s in states],
                   [np.asarray(s.velocity_in_world, dtype=float).tolist() for s in states],
                   [s.yaw_rad for s in states], [s.yaw_rate_rad_s for s in states],
                   [np.asarray(s.acceleration_in_world, dtype=float).tolist() for s in states])

    @property
    def stamps_ns(self) -> Sequence[int]:
        """(N,) state times [ns] (read only)."""
        return self._stamps

    def spliced(self, newer: ComTrack, keep_s: float = 1.0) -> ComTrack:
        """This track before ``newer``'s first point, then ``newer`` (a message replacing it).

        As a trajectory controller takes a new trajectory: the held points stamped before the
        new first point are kept (those more than ``keep_s`` [s] before it are dropped, so
        that the track stays short), the rest is ``newer``. Mixed with a track without
        accelerations, the result has none (cubic in position).
        """
        first_ns = newer._stamps[0]
        stop = bisect.bisect_left(self._stamps, first_ns)
        start = bisect.bisect_left(self._stamps, first_ns - int(keep_s * 1e9), 0, stop)
        if start == stop:
            return newer
        accelerations = None
        if self._accelerations is not None and newer._accelerations is not None:
            accelerations = [*self._accelerations[start:stop], *newer._accelerations]
        return ComTrack([*self._stamps[start:stop], *newer._stamps],
                        [*self._positions[start:stop], *newer._positions],
                        [*self._velocities[start:stop], *newer._velocities],
                        [*self._yaws[start:stop], *newer._yaws],
                        [*self._yaw_rates[start:stop], *newer._yaw_rates], accelerations)

    def first_change_ns(self, newer: ComTrack, tolerance: float) -> int | None:
        """The earliest instant [ns] from which ``newer`` changes this track, or None.

        ``newer`` is a later window of the same reference (it will be :meth:`spliced` in):
        where it only repeats this track's states and extends it, nothing changed. A point
        of ``newer`` that differs (position, velocity or yaw, summed, by more than
        ``tolerance`` [m, m/s, rad]) changes the track from the point before it on (the
        interpolation between them changes). A point stamped between this track's points is
        compared with this track's interpolation there.
        """
        stamps, last_ns = self._stamps, self._stamps[-1]
        for j, stamp_ns in enumerate(newer._stamps):
            if stamp_ns > last_ns:
                return None  # an extension
            k = bisect.bisect_left(stamps, stamp_ns)
            (x1, y1, z1), yaw1 = newer._positions[j], newer._yaws[j]
            if stamps[k] == stamp_ns:
                (x0, y0, z0), yaw0 = self._positions[k], self._yaws[k]
                (u0, v0, w0), (u1, v1, w1) = self._velocities[k], newer._velocities[j]
                difference = abs(u1 - u0) + abs(v1 - v0) + abs(w1 - w0)
            else:
                (x0, y0, z0), yaw0 = self.at(stamp_ns)
                difference = 0.0
            difference += abs(x1 - x0) + abs(y1 - y0) + abs(z1 - z0) + abs(
                math.remainder(yaw1 - yaw0, 2 * math.pi))
            if difference > tolerance:
                return newer._stamps[j - 1] if j else stamp_ns
        return None

    def at(self, stamp_ns: int, max_extrapolation_s: float = 0.05) -> tuple[list[float], float]:
        """COM position [m] and body yaw [rad] at ``stamp_ns`` (class docstring)."""
        stamps = self._stamps
        if stamp_ns <= stamps[0]:
            return list(self._positions[0]), float(self._yaws[0])
        if stamp_ns >= stamps[-1]:
            dt = min((stamp_ns - stamps[-1]) * 1e-9, max_extrapolation_s)
            (x, y, z), (vx, vy, vz) = self._positions[-1], self._velocities[-1]
            return ([x + dt * vx, y + dt * vy, z + dt * vz],
                    float(self._yaws[-1] + dt * self._yaw_rates[-1]))
        k = self._segment
        if not (k + 1 < len(stamps) and stamps[k] <= stamp_ns < stamps[k + 1]):
            k = self._segment = bisect.bisect_right(stamps, stamp_ns) - 1
        h = (stamps[k + 1] - stamps[k]) * 1e-9
        s = (stamp_ns - stamps[k]) / (stamps[k + 1] - stamps[k])
        s2 = s * s
        s3 = s2 * s
        # Cubic Hermite basis (yaw; position without accelerations).
        c00, c10, c01, c11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, 3 * s2 - 2 * s3, s3 - s2
        yaw0 = self._yaws[k]
        yaw = yaw0 + c10 * h * self._yaw_rates[k] \
            + c01 * math.remainder(self._yaws[k + 1] - yaw0, 2 * math.pi) \
            + c11 * h * self._yaw_rates[k + 1]
        p0, p1 = self._positions[k], self._positions[k + 1]
        v0, v1 = self._velocities[k], self._velocities[k + 1]
        if self._accelerations is None:
            return [c00 * p0[i] + c10 * h * v0[i] + c01 * p1[i] + c11 * h * v1[i]
                    for i in range(3)], float(yaw)
        # Quintic Hermite basis: position, velocity, acceleration at both ends.
        s4 = s3 * s
        s5 = s4 * s
        q0 = 1 - 10 * s3 + 15 * s4 - 6 * s5
        q1 = (s - 6 * s3 + 8 * s4 - 3 * s5) * h
        q2 = 0.5 * (s2 - 3 * s3 + 3 * s4 - s5) * h * h
        q3 = 0.5 * (s3 - 2 * s4 + s5) * h * h
        q4 = (-4 * s3 + 7 * s4 - 3 * s5) * h
        q5 = 10 * s3 - 15 * s4 + 6 * s5
        a0, a1 = self._accelerations[k], self._accelerations[k + 1]
        return [q0 * p0[i] + q1 * v0[i] + q2 * a0[i] + q3 * a1[i] + q4 * v1[i] + q5 * p1[i]
                for i in range(3)], float(yaw)


class FootTargets:
    """The feet's targets from one footstep plan, in the robot's foot order, at every tick.

    Stance feet stand where the plan puts them; a foot in swing follows its swing trajectory
    while one covers the instant (:class:`SwingPath`), else the fallback swing
    (:func:`fallback_swing_pose`).

    Args:
        plan: The footstep plan (its feet are the robot's, in any order).
        foot_names: The robot's foot names, in its order.
    """

    def __init__(self, plan: FootstepPlan, foot_names: Sequence[str]):
        order = [plan.foot_names.index(name) for name in foot_names]
        self.plan = plan
        self._start_ns = plan.start_ns
        self._times = plan.times_s.tolist()
        self._positions = list(plan.positions_in_world[:, order])  # K arrays (F, 3)
        self._yaws = plan.yaws_rad[:, order].tolist()  # [K][F]
        feet = {name: k for k, name in enumerate(foot_names)}
        self._swings = [(swing.lift_off_s, swing.touch_down_s, feet[swing.foot],
                         _FallbackSwing(swing)) for swing in plan.swings()]

    def at(self, stamp_ns: int, swing_paths: Sequence[SwingPath | None],
           step_height_m: float) -> tuple[np.ndarray, list[float], int]:
        """Foot positions [m] and yaws [rad] at ``stamp_ns``, and how many feet fell back.

        Args:
            stamp_ns: The instant [ns].
            swing_paths: The latest swing trajectory of each foot (robot order), or None.
            step_height_m: Peak lift of the fallback swing [m].

        Returns:
            ``(feet, yaws, fallbacks)``: (F, 3) positions (a new array) and (F,) yaws (a new
            list), and the number of feet in swing that followed the fallback swing.

        Raises:
            ValueError: A swing pose is not finite (only an overflow can make one so: the
                plan and the swing trajectories are finite, checked by the contract).
        """
        t_plan = (stamp_ns - self._start_ns) * 1e-9
        # FootstepPlan.index_at: the last point at or before t_plan (0 before the start).
        index = max(bisect.bisect_right(self._times, t_plan) - 1, 0)
        feet = self._positions[index].copy()
        yaws = list(self._yaws[index])
        under_way = {}  # swings_under_way: the later swing of a foot wins
        for lift_off_s, touch_down_s, k, swing in self._swings:
            if lift_off_s < t_plan < touch_down_s:
                under_way[k] = swing
        fallbacks = 0
        for k, swing in under_way.items():
            path = swing_paths[k]
            if path is not None and path.covers(stamp_ns):
                position, yaws[k] = path.pose_at(stamp_ns)
            else:
                position, yaws[k] = swing.pose_at(t_plan, step_height_m)
                fallbacks += 1
            if not math.isfinite(sum(position) + yaws[k]):
                raise ValueError(f'the swing pose of foot {k} is not finite: {position}, '
                                 f'{yaws[k]}')
            feet[k] = position
        return feet, yaws, fallbacks


def current_swing(plan: FootstepPlan, foot: str, t_s: float) -> Swing | None:
    """The swing of ``foot`` under way at ``t_s`` from the plan start, or None."""
    for swing in plan.swings():
        if swing.foot == foot and swing.lift_off_s < t_s < swing.touch_down_s:
            return swing
    return None


def swings_under_way(plan: FootstepPlan, t_s: float) -> dict[str, Swing]:
    """Foot name -> its swing under way at ``t_s`` from the plan start (feet in the air)."""
    return {swing.foot: swing for swing in plan.swings()
            if swing.lift_off_s < t_s < swing.touch_down_s}


def _lagrange(values: Sequence[np.ndarray], times_s: Sequence[float], at_s: float) -> np.ndarray:
    """The polynomial through ``(times_s[k], values[k])`` (two or three) evaluated at ``at_s``."""
    t = [float(x) for x in times_s]
    q = np.zeros_like(np.asarray(values[-1], dtype=float))
    for k, value in enumerate(values):
        weight = 1.0
        for j in range(len(values)):
            if j != k:
                weight *= (at_s - t[j]) / (t[k] - t[j])
        q += weight * value
    return q
