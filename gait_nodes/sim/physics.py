"""Rigid-body simulation with contacts: the robot in MuJoCo, its joints position-controlled.

:class:`PhysicsSimulation` has the interface of :class:`gait_nodes.sim.kinematics.
KinematicSimulation` (``step(commanded_joints, dt_s, ...)`` returning the state after the step)
but nothing in it is placed by the plan: the base moves as the contact forces and the joint
torques make it, and a foot is in contact when the ground pushes on it.

**The joints** are driven as a ros2_control position interface drives a robot's joints: the
controller sends a setpoint (position and velocity) every control period (the node's tick) and
each joint's drive interpolates it linearly over its own servo cycles (the physics steps,
CiA 402's interpolated position mode) and applies ``tau = kp (q_ref - q) + kd (qd_ref - qd)``,
clamped at the URDF's effort limit (:mod:`gait_nodes.sim.mujoco_model`). What the step reports
is measured: joint positions and velocities from the simulation, efforts as applied.

**The contacts** are MuJoCo's (soft, elliptic friction cones). Every physics step the force of
each contact is read from the constraint solver (``efc_force``, the contact frame's normal and
tangential components) and summed per foot, force and moment about the world origin; a step's
report averages them over its physics steps (a force sensor sampled at the servo rate and read
at the control rate). From them:

- the **centre of pressure** on the plane ``z = h`` (the lowest contact point, as the ZMP
  monitor's plane): with the net force ``F`` and the net moment ``M`` about the origin, the point
  of the plane about which the horizontal moment vanishes,
  ``p_x = (h F_x - M_y) / F_z``, ``p_y = (h F_y + M_x) / F_z`` (on flat ground the mean of the
  contact points weighted by their normal forces);
- each foot's **contact wrench**: the ground's force on the foot and its moment about the foot
  frame's origin, in the foot frame (what a force-torque sensor at the sole reports);
- the **contact points**: every contact point the ground pushed on during the step (a normal
  force above zero at one of its physics steps); their convex hull is the actual contact
  polygon. Every force the centre of pressure counts is at one of them, so on flat ground the
  centre of pressure is in that polygon (a threshold on the points, 1 N until session 24, left
  the CoP up to 0.2 mm outside the hull of the points that passed it);
- a foot is **in contact** when its normal force exceeds that threshold; its **slip** is how
  far (horizontally) the foot's material at its contact moved since it touched down: at every
  step (a control tick), the point of the foot that was under its contacts (their centre,
  weighted by their normal forces) at the last physics step of the step before, where the foot
  has taken it since (:func:`material_displacement`), summed. A foot that rolls on the ground
  (go2's spheres, as the lower leg turns) does not slip, though its frame moves: the frame's
  own displacement counted a sphere of 22 mm turning by 20 degrees as 7.7 mm of slip, while
  the material of a sphere of radius r rolling by an angle a moves r (a - sin a) horizontally
  (nanometres over a 10 ms tick). Until session 24 this was done at every physics step, at ten
  times the cost: ``bench/physics.py`` read the same slips to 0.1 mm (go2's 4.0 mm then, 3.9
  now; RoboSimian's and the biped's the same to the digit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from gait_nodes.errors import ParameterError
from gait_nodes.robot.model import RobotModel
from gait_nodes.sim.mujoco_model import PhysicsModel, import_mujoco


@dataclass(frozen=True)
class PhysicsSettings:
    """Settings of :class:`PhysicsSimulation`.

    Attributes:
        contact_force_threshold_n: A foot carrying at least this normal force (its mean over
            the step) is in contact [N]: it touches down, and its slip counts.
    """

    contact_force_threshold_n: float = 1.0

    def __post_init__(self):
        value = self.contact_force_threshold_n
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value) or not 0.0 <= value <= 1e4:
            raise ParameterError(f'contact_force_threshold_n must be a number in [0, 10000] N, '
                                 f'got {value!r}')


@dataclass(slots=True)
class JointStep:
    """The joints over one step, as measured (read-only).

    Attributes:
        positions_rad: (J,) joint positions after the step [rad or m].
        velocities_rad_s: (J,) joint velocities after the step [rad/s or m/s].
        efforts_nm: (J,) actuator torques at the end of the step [N m or N].
        commanded_rad: (J,) the setpoint at the end of the step [rad or m].
        peak_effort_over_limit: (J,) the largest ``|unclamped PD torque| / effort limit`` over
            the step's physics steps; above 1 the drive was at its limit.
        lower_rad, upper_rad: (J,) the joints' position limits [rad or m].
    """

    positions_rad: np.ndarray
    velocities_rad_s: np.ndarray
    efforts_nm: np.ndarray
    commanded_rad: np.ndarray
    peak_effort_over_limit: np.ndarray
    lower_rad: np.ndarray
    upper_rad: np.ndarray

    @property
    def saturated(self) -> np.ndarray:
        """(J,) booleans: the drive was at its effort limit during the step."""
        return self.peak_effort_over_limit >= 1.0

    @property
    def any_saturated(self) -> bool:
        """Whether any drive was at its effort limit."""
        return bool(np.count_nonzero(self.saturated))

    @property
    def clamped_to_limits(self) -> np.ndarray:
        """(J,) booleans: the setpoint was beyond the joint's position limits."""
        return (self.commanded_rad < self.lower_rad) | (self.commanded_rad > self.upper_rad)

    @property
    def any_clamped(self) -> bool:
        """Whether any setpoint was beyond its joint's limits."""
        return bool(np.count_nonzero(self.clamped_to_limits))


@dataclass(slots=True)
class PhysicsStep:
    """What one step of :class:`PhysicsSimulation` measured (read-only).

    Attributes:
        q: Pinocchio configuration after the step (the simulated base pose and joints).
        actuators: The joints (:class:`JointStep`).
        contacts: (F,) booleans: feet in contact (normal force over the threshold).
        contact_points_in_world: (C, 3) contact points the ground pushed on during the step, those
            on the convex hull of their horizontal projections [m].
        foot_forces_in_world: (F, 3) ground force on each foot, mean over the step [N].
        foot_moments_in_world: (F, 3) its moment about the world origin [N m].
        foot_wrenches_in_foot: (F, 6) force [N] and moment about the foot frame's origin
            [N m], in the foot frame (at the end of the step), mean over the step.
        cop_in_world: (3,) centre of pressure on the plane of the lowest contact [m]; NaN
            without vertical force.
        normal_force_n: Total vertical ground force [N].
        slip_m: Largest horizontal slip of a stance foot since its touch-down [m] (the
            module docstring).
        touched_down: Names of the feet that came into contact in this step.
    """

    q: np.ndarray
    actuators: JointStep
    contacts: np.ndarray
    contact_points_in_world: np.ndarray
    foot_forces_in_world: np.ndarray
    foot_moments_in_world: np.ndarray
    foot_wrenches_in_foot: np.ndarray
    cop_in_world: np.ndarray
    normal_force_n: float
    slip_m: float
    touched_down: tuple[str, ...]


def centre_of_pressure(force: np.ndarray, moment_about_origin: np.ndarray,
                       plane_height_m: float) -> np.ndarray:
    """(3,) point of the plane ``z = plane_height_m`` where the horizontal moment vanishes.

    Args:
        force: (3,) net ground force [N].
        moment_about_origin: (3,) its moment about the world origin [N m].
        plane_height_m: Height of the plane [m].

    Returns:
        ``(x, y, plane_height_m)``; NaN in x and y without an upward force.
    """
    fx, fy, fz = (float(v) for v in force)
    mx, my, _ = (float(v) for v in moment_about_origin)
    if not fz > 1e-9:
        return np.array([math.nan, math.nan, plane_height_m])
    h = float(plane_height_m)
    return np.array([(h * fx - my) / fz, (h * fy + mx) / fz, h])


def material_displacement(frame_position: np.ndarray, frame_rotation: np.ndarray,
                          material: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(3,) how far a foot took the point of it that was under its contact a step before [m].

    Args:
        frame_position: (3,) the foot frame's position now [m] (or (F, 3), one per foot).
        frame_rotation: (3, 3) its rotation now (frame to world) (or (F, 3, 3)).
        material: ``(in_frame, in_world)``: that point in the foot frame and in the world,
            then ((3,) each, or (F, 3)).

    A foot rolling without slipping leaves its contact material where it was (zero, to first
    order in the step); a sliding one carries it along.
    """
    in_frame, in_world = material
    return frame_position + np.einsum('...ij,...j->...i', frame_rotation, in_frame) - in_world


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (N, 3) arrays (np.cross costs more for few rows)."""
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    bx, by, bz = b[:, 0], b[:, 1], b[:, 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], 1)


def _world_contacts(read: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot indices (C,), points (C, 3) and forces on the feet (C, 3) of contacts as read.

    ``read``: :meth:`PhysicsSimulation._foot_contacts` of some physics steps. A contact's point
    is on the ground's surface (the floor's, a stair's), where a rigid ground takes the force,
    not MuJoCo's midpoint of the soft contact's penetration: feet sunk by different depths
    would put the forces of one flat floor at different heights, and their friction would move
    the centre of pressure off the hull of the contacts. World frame [m], [N].
    """
    foot, second, position, half_depth, frame, local = (
        np.concatenate(column) for column in zip(*read, strict=True))
    frame = frame.reshape(-1, 3, 3)
    # The force on geom 2 (the normal points from geom 1 to geom 2), then on the foot; the
    # midpoint is half the distance from each surface along the normal.
    sign = np.where(second, 1.0, -1.0)[:, None]
    force_on_foot = sign * np.einsum('ci,cij->cj', local, frame)
    on_ground = position - (half_depth[:, None] * sign) * frame[:, 0]
    return foot, on_ground, force_on_foot


def _hull_points(points: np.ndarray) -> np.ndarray:
    """The points (N, 3) whose horizontal projections are the vertices of their convex hull.

    Counter-clockwise, read-only: a few points instead of every contact of every physics step.
    Fewer than three distinct points, or collinear ones (two point feet on a diagonal), are kept
    as they are, in their order: their hull is a segment, which
    :func:`gait_nodes.geometry.signed_distance` measures against without any order. Vertices
    micrometres apart (a resting foot's contacts move that much between physics steps) are kept:
    the margin's inside test counts crossings, which such short edges do not upset.
    """
    if len(points) > 3:
        try:
            points = points[ConvexHull(points[:, :2]).vertices]
        except QhullError:
            pass  # fewer than three distinct points, or collinear: keep them all
    points = np.array(points, dtype=float).reshape(-1, 3)
    points.flags.writeable = False
    return points


class PhysicsSimulation:
    """The robot in MuJoCo, following joint setpoints (see the module docstring).

    Args:
        robot: The robot (its Pinocchio model gives the configuration's layout).
        physics: The compiled MuJoCo model (:func:`gait_nodes.sim.mujoco_model.
            load_physics_model`), actuating ``robot.joint_names``.
        q_initial: Pinocchio configuration to start from (at rest), the setpoint held there.
        settings: Contact threshold.
    """

    def __init__(self, robot: RobotModel, physics: PhysicsModel, q_initial: np.ndarray,
                 settings: PhysicsSettings | None = None):
        mujoco = self._mujoco = import_mujoco()
        if tuple(physics.joint_names) != tuple(robot.joint_names):
            raise ValueError('the physics model must actuate the robot\'s joints in its order')
        self.robot = robot
        self.physics = physics
        self.settings = settings or PhysicsSettings()
        model = self.model = physics.model
        self.data = mujoco.MjData(model)
        joint_ids = [model.joint(name).id for name in robot.joint_names]
        self._qpos = np.array([model.jnt_qposadr[j] for j in joint_ids])
        self._dof = np.array([model.jnt_dofadr[j] for j in joint_ids])
        base = model.body(physics.base_body).id
        free = int(np.flatnonzero(model.jnt_bodyid == base)[0])
        self._base_qpos = int(model.jnt_qposadr[free])
        self._base_dof = int(model.jnt_dofadr[free])
        self._foot_bodies = np.array([model.body(name).id for name in physics.foot_bodies])
        # Geom -> foot index (-1: not a foot), for reading the contacts.
        self._foot_of_geom = np.full(model.ngeom, -1)
        for k, name in enumerate(physics.foot_geoms):
            self._foot_of_geom[model.geom(name).id] = k
        self._kp = model.actuator_gainprm[:, 0].copy()
        self._kd_over_kp = np.divide(-model.actuator_biasprm[:, 2], self._kp,
                                     out=np.zeros_like(self._kp), where=self._kp > 0)
        self._effort_limits = np.array(physics.effort_limits)
        self._lower = np.array(robot.lower_limits)
        self._upper = np.array(robot.upper_limits)
        self._q_layout = np.array(q_initial, dtype=float)
        self.timestep_s = float(model.opt.timestep)
        feet = len(physics.foot_bodies)
        # Each foot's slip since its touch-down [m] (x, y), and the material under its contact
        # at the last physics step (see material_displacement), None when it had none.
        self._slip = np.zeros((feet, 2))
        # Each foot's contact material (module docstring): the point in the foot frame and
        # in the world, and whether the foot has one (not since it left the ground).
        self._material_in_frame = np.zeros((feet, 3))
        self._material_in_world = np.zeros((feet, 3))
        self._has_material = np.zeros(feet, dtype=bool)
        self._three = np.arange(3)

        self.set_configuration(q_initial)
        self.joints = robot.joint_positions(np.asarray(q_initial))
        self._setpoint = (self.joints.copy(), np.zeros(len(self.joints)))
        self.q = self.configuration()
        self.contacts = np.zeros(feet, dtype=bool)

    # -- state ---------------------------------------------------------------------------------

    def set_configuration(self, q: np.ndarray) -> None:
        """Put the robot at Pinocchio configuration ``q``, at rest."""
        mujoco, data = self._mujoco, self.data
        q = np.asarray(q, dtype=float)
        mujoco.mj_resetData(self.model, data)
        b = self._base_qpos
        data.qpos[b:b + 3] = q[:3]
        data.qpos[b + 3:b + 7] = (q[6], q[3], q[4], q[5])  # MuJoCo's quaternion is w, x, y, z
        data.qpos[self._qpos] = self.robot.joint_positions(q)
        data.ctrl[:] = data.qpos[self._qpos]
        mujoco.mj_forward(self.model, data)

    def configuration(self) -> np.ndarray:
        """The Pinocchio configuration of the simulated state (read-only)."""
        qpos = self.data.qpos
        b = self._base_qpos
        q = self._q_layout.copy()
        q[:3] = qpos[b:b + 3]
        w, x, y, z = qpos[b + 3:b + 7]
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        q[3:7] = (x / norm, y / norm, z / norm, w / norm)
        self.robot.set_joint_positions(q, qpos[self._qpos])
        q.flags.writeable = False
        return q

    def contact_points(self) -> np.ndarray:
        """(C, 3) the contact points of the last step (none before the first) [m]."""
        return getattr(self, '_points', np.zeros((0, 3)))

    def base_velocity_in_world(self) -> np.ndarray:
        """(6,) linear [m/s] and angular [rad/s] velocity of the base, in the world frame."""
        d = self._base_dof
        linear = np.array(self.data.qvel[d:d + 3])
        # A free joint's angular velocity is in the body frame.
        return np.concatenate([linear, self.data.xmat[self.model.jnt_bodyid[
            self.model.dof_jntid[d]]].reshape(3, 3) @ self.data.qvel[d + 3:d + 6]])

    # -- stepping ------------------------------------------------------------------------------

    def _foot_contacts(self) -> tuple | None:
        """The feet's contacts of the current physics step, as the solver has them.

        ``(foot, foot_is_second, position, half_depth, frame, local_force)``: ``(C,)`` foot
        indices and whether the foot is the contact's second geom, ``(C, 3)`` MuJoCo's contact
        points [m], ``(C,)`` half their (negative) distances [m], ``(C, 9)`` contact frames
        (rows: normal, tangent 1, tangent 2) and ``(C, 3)`` the constraint solver's forces in
        them (elliptic cones: normal and tangential rows) [N]; None without any. Copied, and
        turned into world forces and points by :func:`_world_contacts` once per step (several
        physics steps at once).
        """
        data = self.data
        n = data.ncon
        if n == 0:
            return None
        contact = data.contact
        address = contact.efc_address[:n]
        geoms = contact.geom[:n]
        foot_1 = self._foot_of_geom[geoms[:, 0]]
        foot_2 = self._foot_of_geom[geoms[:, 1]]
        active = (address >= 0) & ((foot_1 >= 0) | (foot_2 >= 0))
        if not active.all():
            if not active.any():
                return None
            address, foot_1, foot_2 = address[active], foot_1[active], foot_2[active]
        second = foot_2 >= 0
        return (np.where(second, foot_2, foot_1), second, contact.pos[:n][active],
                0.5 * contact.dist[:n][active], contact.frame[:n][active],
                data.efc_force[address[:, None] + self._three])

    def _follow_material(self, contacts) -> None:
        """Add each foot's slip over the step just taken (see the module docstring).

        ``contacts``: :func:`_world_contacts` of the step's last physics step, or None. A foot
        without contact in that physics step keeps its last contact's material: a foot
        in stance that skips along the ground (its contact lost for a step or two) counts the
        way that material went meanwhile.
        """
        if contacts is None:
            return
        foot, points, forces = contacts
        feet = len(self._has_material)
        normal = forces[:, 2]
        load = np.bincount(foot, weights=normal, minlength=feet)
        loaded = load > 0.0
        if not loaded.any():
            return
        # Each loaded foot's contacts' centre, weighted by their normal forces.
        weighted = points * normal[:, None]
        centre = np.stack([np.bincount(foot, weights=weighted[:, i], minlength=feet)
                           for i in range(3)], 1)[loaded] / load[loaded, None]
        positions = self.data.xpos[self._foot_bodies][loaded]
        rotations = self.data.xmat[self._foot_bodies].reshape(-1, 3, 3)[loaded]
        followed = self._has_material[loaded]
        if followed.any():
            index = np.flatnonzero(loaded)[followed]
            moved = material_displacement(positions[followed], rotations[followed],
                                          (self._material_in_frame[index],
                                           self._material_in_world[index]))
            self._slip[index] += moved[:, :2]
        self._material_in_frame[loaded] = np.einsum('fji,fj->fi', rotations,
                                                    centre - positions)
        self._material_in_world[loaded] = centre
        self._has_material[loaded] = True

    def step(self, commanded_joints: np.ndarray, dt_s: float,
             contacts: np.ndarray | None = None,
             commanded_velocities: np.ndarray | None = None,
             contact_heights_m: np.ndarray | None = None) -> PhysicsStep:
        """Advance by ``dt_s`` [s] with the joints driven toward the setpoint.

        The setpoint moves linearly from the previous one to ``commanded_joints`` (and its
        velocity to ``commanded_velocities``) over the step's physics steps.

        Args:
            commanded_joints: (J,) joint setpoint at the end of the step [rad or m].
            dt_s: Step [s]; a whole number of physics steps (at least one).
            contacts: Ignored (a plan's contacts: in physics the ground decides).
            commanded_velocities: (J,) the setpoint's velocity [rad/s], or None for zero.
            contact_heights_m: Ignored.
        """
        mujoco, model, data = self._mujoco, self.model, self.data
        steps = max(1, int(round(dt_s / self.timestep_s)))
        start_q, start_v = self._setpoint
        end_q = np.asarray(commanded_joints, dtype=float)
        end_v = np.zeros_like(end_q) if commanded_velocities is None \
            else np.asarray(commanded_velocities, dtype=float)
        feet = len(self._foot_bodies)
        read = []
        peak = np.zeros(len(end_q))
        limits = self._effort_limits
        for k in range(1, steps + 1):
            s = k / steps
            q_ref = start_q + s * (end_q - start_q)
            v_ref = start_v + s * (end_v - start_v)
            data.ctrl[:] = q_ref + self._kd_over_kp * v_ref
            mujoco.mj_step(model, data)
            unclamped = self._kp * (q_ref - data.qpos[self._qpos]) \
                + self._kp * self._kd_over_kp * (v_ref - data.qvel[self._dof])
            np.maximum(peak, np.abs(unclamped) / limits, out=peak)
            contacts_read = self._foot_contacts()
            if contacts_read is not None:
                read.append(contacts_read)
        # The contact material, from the last physics step's contacts (module docstring).
        self._follow_material(None if contacts_read is None
                              else _world_contacts([contacts_read]))
        self._setpoint = (end_q.copy(), end_v.copy())

        # Sums over the step's contacts, divided by its physics steps: the mean per foot.
        forces = np.zeros((feet, 3))
        moments = np.zeros((feet, 3))
        if read:
            foot, points, on_foot = _world_contacts(read)
            np.add.at(forces, foot, on_foot / steps)
            np.add.at(moments, foot, _cross(points, on_foot) / steps)
        else:
            points, on_foot = np.zeros((0, 3)), np.zeros((0, 3))
        threshold = self.settings.contact_force_threshold_n
        carrying = _hull_points(points[on_foot[:, 2] > 0.0])
        self._points = carrying
        contacts_now = forces[:, 2] >= max(threshold, 1e-9)
        contacts_now.flags.writeable = False

        frames_xpos = data.xpos[self._foot_bodies]
        frames_xmat = data.xmat[self._foot_bodies].reshape(-1, 3, 3)
        touched, slip = [], 0.0
        for k in range(feet):
            if contacts_now[k] and self.contacts[k]:
                slip = max(slip, math.hypot(*self._slip[k]))
            else:
                self._slip[k] = 0.0  # in the air, or touching down: its slip starts here
                if contacts_now[k]:
                    touched.append(self.robot.foot_names[k])
                else:
                    self._has_material[k] = False
        self.contacts = contacts_now

        # Each foot's wrench about its frame's origin, in its frame.
        moments_at_foot = moments - _cross(frames_xpos, forces)
        wrenches = np.concatenate([np.einsum('fji,fj->fi', frames_xmat, forces),
                                   np.einsum('fji,fj->fi', frames_xmat, moments_at_foot)], 1)
        plane = float(carrying[:, 2].min()) if len(carrying) else 0.0
        total_force = forces.sum(0)
        cop = centre_of_pressure(total_force, moments.sum(0), plane)

        self.joints = np.array(data.qpos[self._qpos])
        velocities = np.array(data.qvel[self._dof])
        self.q = self.configuration()
        joint_step = JointStep(self.joints, velocities, np.array(data.actuator_force), end_q,
                               peak, self._lower, self._upper)
        return PhysicsStep(self.q, joint_step, contacts_now, carrying, forces, moments,
                           wrenches, cop, float(total_force[2]), slip, tuple(touched))
