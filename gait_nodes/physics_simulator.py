"""physics_simulator node: the kinematic simulator's topics, measured on the robot in MuJoCo.

``python -m gait_nodes.physics_simulator [--ros-args -p robot:=biped -p publish_clock:=true]``
(needs ``pip install mujoco``). It takes the kinematic simulator's place in the graph
(``python -m gait_nodes run --simulator physics``, ``ros2 launch gait_nodes gait.launch.py
simulator:=physics``): the same inputs (/joint_commands as a ros2_control
joint_trajectory_controller takes them, /gait/footsteps), the same outputs, and it answers the
same way (bad trajectories dropped and reported, a stale input reported, two publishers
refused, /clock when it owns time; see :mod:`gait_nodes.kinematic_simulator`). What differs is
what stands behind the numbers: the robot is simulated with contacts, joint gains, effort limits
and armature (:mod:`gait_nodes.sim.physics`, the model built from the URDF and the robot YAML
by :mod:`gait_nodes.sim.mujoco_model`), and what it publishes is measured there:

- /joint_states: positions and velocities from the simulation, ``effort`` the drives' torques;
- /tf (odom -> base_link): the simulated base pose, not the plan's;
- /gait/zmp, /gait/com: the full-model monitor on the simulated configurations (central
  differences, one tick behind, as the kinematic simulator's);
- /gait/support_polygon: the actual contact polygon, the convex hull of the contact points the
  ground pushed on during the tick (no disc is drawn around them: the feet's shapes are in the
  model); the monitor's stability margin is the ZMP's in that polygon;
- /gait/cop (geometry_msgs/PointStamped, odom): the centre of pressure of the contact forces,
  mean over the tick, on the plane of the lowest contact;
- /gait/contact_wrench/<foot> (geometry_msgs/WrenchStamped, the foot frame): the ground's force
  on each foot and its moment about the foot frame's origin, mean over the tick, as a
  force-torque sensor at the sole reports it;
- /gait/markers: the kinematic simulator's (ZMP and COM spheres, support polygon outline) and a
  magenta sphere at the centre of pressure (id 3, deleted while nothing touches the ground), all
  of the monitor's sample's stamp;
- /diagnostics: the kinematic simulator's stability and input reports; every
  ``diagnostics_period_s`` a summary with the drives at their effort limit ('torque
  saturation'), the contacts (touch-downs, stance-foot slip, the centre of pressure's least
  margin in the contact polygon) and the inputs.

Every tick (``rate_hz``) the joint setpoints are sampled from the held trajectory at the tick's
stamp and handed to the drives, which move them linearly over the tick's physics steps
(``timestep_s``). Under inproc the physics steps are the simulated time: a run is deterministic.
The footstep plan is not used by the simulation (the ground decides the contacts).
"""

from __future__ import annotations

import math
import sys
from collections import deque
from dataclasses import dataclass

import numpy as np

from gait_nodes import graph
from gait_nodes.cli import run_node
from gait_nodes.contract import contact_wrench_to_msg
from gait_nodes.diagnostics import OK, WARN
from gait_nodes.errors import ParameterError
from gait_nodes.interfaces import get_message
from gait_nodes.kinematic_simulator import (
    MIN_RATE_HZ,
    KinematicSimulator,
    KinematicSimulatorParams,
    _flag,
    _Window,
)
from gait_nodes.planning.terrain import STAIRS_PARAMETERS, Staircase
from gait_nodes.settings import checked_number as _number
from gait_nodes.sim.mujoco_model import load_physics_model
from gait_nodes.sim.physics import PhysicsSettings, PhysicsSimulation

NODE_NAME = 'physics_simulator'
#: Largest mismatch [s] between the control period and a whole number of physics steps.
PERIOD_TOLERANCE_S = 1e-9
#: /gait/markers id of the centre of pressure's sphere (after the ZMP, COM and polygon).
COP_MARKER_ID = 3


@dataclass(frozen=True)
class PhysicsSimulatorParams:
    """The node's parameters, validated (meanings in config/physics_simulator.yaml)."""

    robot: str
    rate_hz: float
    timestep_s: float
    publish_clock: bool
    warn_margin_m: float
    stale_after_s: float
    diagnostics_period_s: float
    contact_force_threshold_n: float
    publish_markers: bool
    markers_rate_hz: float
    stairs_start_x_m: float
    stairs_rise_m: float
    stairs_tread_m: float
    stairs_count: int

    #: The ZMP monitor's plane without contacts [m] (the model's floor).
    ground_height_m = 0.0

    @classmethod
    def from_values(cls, values: dict) -> PhysicsSimulatorParams:
        """Validate raw parameter values; ParameterError naming the value and the range."""
        kinematic = KinematicSimulatorParams.from_values(
            {**values, 'contact_height_tolerance_m': 0.0, 'ground_height_m': 0.0})
        rate_hz = _number(values, 'rate_hz', 1.0, 1000.0)
        timestep_s = _number(values, 'timestep_s', 1e-4, 0.01)
        steps = round(1.0 / (rate_hz * timestep_s))
        if steps < 1 or abs(steps * timestep_s - 1.0 / rate_hz) > PERIOD_TOLERANCE_S:
            raise ParameterError(f'rate_hz = {rate_hz:g} Hz: the control period must be a whole '
                                 f'number of physics steps of timestep_s = {timestep_s:g} s')
        stairs = Staircase.from_parameters(values)  # TerrainError (a ParameterError)
        return cls(
            robot=kinematic.robot, rate_hz=rate_hz, timestep_s=timestep_s,
            publish_clock=kinematic.publish_clock, warn_margin_m=kinematic.warn_margin_m,
            stale_after_s=kinematic.stale_after_s,
            diagnostics_period_s=kinematic.diagnostics_period_s,
            contact_force_threshold_n=_number(values, 'contact_force_threshold_n', 0.0, 1e4),
            publish_markers=_flag(values, 'publish_markers'),
            markers_rate_hz=_number(values, 'markers_rate_hz', MIN_RATE_HZ, 2000.0),
            stairs_start_x_m=stairs.start_x_m, stairs_rise_m=stairs.rise_m,
            stairs_tread_m=stairs.tread_m, stairs_count=stairs.count)

    @property
    def staircase(self) -> Staircase:
        """The world's staircase."""
        return Staircase(self.stairs_start_x_m, self.stairs_rise_m, self.stairs_tread_m,
                         self.stairs_count)

    def simulation_settings(self) -> PhysicsSettings:
        """Settings of the simulation core."""
        return PhysicsSettings(contact_force_threshold_n=self.contact_force_threshold_n)


class _PhysicsWindow(_Window):
    """What happened since the last diagnostics summary, with the drives' efforts and the CoP."""

    def __init__(self):
        super().__init__()
        self.saturated_joints: dict[str, float] = {}
        self.peak_effort_ratio = 0.0
        self.min_cop_margin_m = math.inf
        self.cop_samples = 0


class PhysicsSimulator(KinematicSimulator):
    """The physics simulator node (see the module docstring)."""

    NODE_NAME = NODE_NAME
    Params = PhysicsSimulatorParams
    FIXED_PARAMETERS = ('robot', 'publish_clock', 'timestep_s', *STAIRS_PARAMETERS)

    def _make_simulation(self, q_initial: np.ndarray) -> PhysicsSimulation:
        params = self.params
        physics = load_physics_model(self.robot.description, self.robot.joint_names,
                                     params.staircase, params.timestep_s)
        self._continuous_joints = False  # MuJoCo's hinge angles are the joint positions
        self._supports = [(None, None), (None, None)]
        foot_frames = [foot.frame for foot in self.robot.description.feet]
        wrench = get_message('geometry_msgs/msg/WrenchStamped')
        self._wrench_topics = [
            (frame, self.create_publisher(wrench, graph.node_topic_name(topic), 10))
            for frame, topic in zip(foot_frames, graph.foot_topics(self.robot.foot_names),
                                    strict=True)]
        self._cop = self.create_publisher(get_message('geometry_msgs/msg/PointStamped'),
                                          'gait/cop', 10)
        # (odom header, CoP [x, y, z] or None) of the last two ticks: the markers are of the
        # monitor's sample, one tick behind the measurement.
        self._recent_cops: deque = deque(maxlen=2)
        self.get_logger().info(f'MuJoCo model {physics.mjcf_path} ({physics.model.nbody} bodies, '
                               f'{physics.model.nu} drives, {params.timestep_s * 1e3:g} ms steps)')
        return PhysicsSimulation(self.robot, physics, q_initial, params.simulation_settings())

    def _monitor_foot_radius_m(self) -> float:
        return 0.0  # the support polygon is the actual contact points' hull

    def _support_of(self, contact_points: np.ndarray):
        # The contacts change every tick: the supports of the last two ticks' contact points
        # (the CoP's of this tick, the monitor's of the previous one) are kept, by identity.
        for points, support in self._supports:
            if points is contact_points:
                return support
        support = self.monitor.support(contact_points, hull=True)
        self._supports = [self._supports[-1], (contact_points, support)]
        return support

    def _plan_inputs(self, now_ns: int) -> tuple:
        return None, None  # the ground decides the contacts

    def _joint_efforts(self, actuators) -> list:
        return actuators.efforts_nm.tolist()

    def _publish_measurements(self, now_ns: int, step, header) -> None:
        new = self._new
        x, y, z = step.cop_in_world.tolist()
        finite = math.isfinite(x) and math.isfinite(y)
        self._recent_cops.append((header, [x, y, z] if finite else None))
        if finite:
            self._cop.publish(new['PointStamped'](header, new['Point'](x, y, z)))
            if len(step.contact_points_in_world):
                support = self._support_of(step.contact_points_in_world)
                margin = self.monitor.margin_in(step.cop_in_world, support)
                window = self._window
                window.cop_samples += 1
                window.min_cop_margin_m = min(window.min_cop_margin_m, margin)
        for (frame, publisher), wrench in zip(self._wrench_topics, step.foot_wrenches_in_foot,
                                              strict=True):
            publisher.publish(contact_wrench_to_msg(now_ns, frame, wrench))

    # -- markers -------------------------------------------------------------------------------

    def _marker_parts(self) -> dict:
        parts = super()._marker_parts()
        new = self._new
        parts[COP_MARKER_ID] = (new['Vector3'](0.04, 0.04, 0.04),
                                new['ColorRGBA'](0.85, 0.1, 0.85, 1.0))
        return parts

    def _marker_array(self, header, zmp: list | None, com: list | None, outline_points: list):
        """The kinematic simulator's markers and the CoP's sphere, of ``header``'s stamp."""
        array = super()._marker_array(header, zmp, com, outline_points)
        cop = next((xyz for held, xyz in self._recent_cops if held is header), None)
        marker_type, parts = self._msg['Marker'], self._marker_parts_cache
        if cop is None:
            marker = self._marker(header, COP_MARKER_ID, marker_type.SPHERE, marker_type.DELETE,
                                  parts['origin'], parts['empty'])
        else:
            marker = self._marker(header, COP_MARKER_ID, marker_type.SPHERE, marker_type.ADD,
                                  self._new['Pose'](self._new['Point'](*cop),
                                                    parts['orientation']), parts['empty'])
        array.markers.append(marker)
        return array

    # -- diagnostics ---------------------------------------------------------------------------

    def _new_window(self) -> _PhysicsWindow:
        return _PhysicsWindow()

    def _account(self, step) -> None:
        window = self._window
        window.ticks += 1
        actuators = step.actuators
        ratios = actuators.peak_effort_over_limit
        window.peak_effort_ratio = max(window.peak_effort_ratio, float(ratios.max(initial=0.0)))
        if actuators.any_saturated:
            window.saturated_ticks += 1
            for k in np.flatnonzero(actuators.saturated):
                name = self.robot.joint_names[k]
                window.saturated_joints[name] = max(window.saturated_joints.get(name, 0.0),
                                                    float(ratios[k]))
        if actuators.any_clamped:
            for k in np.flatnonzero(actuators.clamped_to_limits):
                window.clamped_joints.add(self.robot.joint_names[k])
        window.max_slip_m = max(window.max_slip_m, step.slip_m)
        window.touch_downs += len(step.touched_down)

    def _summary_statuses(self, window: _PhysicsWindow) -> list:
        statuses = self._stability_summary(window)
        joints = sorted(window.saturated_joints, key=lambda j: -window.saturated_joints[j])
        statuses.append((
            'torque saturation', WARN if window.saturated_ticks else OK,
            (f'{window.saturated_ticks} of {window.ticks} ticks with a drive at its effort '
             f'limit (demanded up to {window.peak_effort_ratio:.3g}x): {", ".join(joints)}')
            if window.saturated_ticks else
            f'efforts within the limits (peak {window.peak_effort_ratio:.3g} of the limit)',
            {'saturated_ticks': window.saturated_ticks, 'ticks': window.ticks,
             'peak_effort_over_limit': window.peak_effort_ratio, 'joints': ','.join(joints),
             'clamped_to_position_limits': ','.join(sorted(window.clamped_joints))}))
        contacts = ','.join(name for name, down in zip(
            self.robot.foot_names, self.simulation.contacts, strict=True) if down)
        cop = (f', centre of pressure at least {window.min_cop_margin_m:.4f} m inside the '
               f'contact polygon' if window.cop_samples else ', no centre of pressure')
        statuses.append((
            'contacts', OK, f'{window.touch_downs} touch-downs, stance feet slip up to '
            f'{window.max_slip_m:.2e} m' + cop,
            {'touch_downs': window.touch_downs, 'max_slip_m': window.max_slip_m,
             'min_cop_margin_m': window.min_cop_margin_m, 'cop_samples': window.cop_samples,
             'contacts': contacts}))
        return statuses


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.physics_simulator [--ros-args ...]``."""
    return run_node(lambda options: PhysicsSimulator(), args,
                    prog='python -m gait_nodes.physics_simulator',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
