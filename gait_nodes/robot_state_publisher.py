"""robot_state_publisher node: the robot's URDF and every link's frame, as ROS's own gives them.

``python -m gait_nodes.robot_state_publisher [--ros-args -p robot:=go2]``. What ROS's
robot_state_publisher publishes, for the robot that the graph's ``robot`` parameter names (its
URDF, from ``config/robots/<robot>.yaml``), so that RViz and Foxglove draw the robot from a live
graph or from a bag alone, with or without ROS:

- /robot_description (std_msgs/String, reliable, transient local, depth 1): the URDF file's
  text, once at start (latched: a tool that starts later still gets it);
- /tf_static (tf2_msgs/TFMessage, reliable, transient local, depth 1, as tf2's
  StaticTransformBroadcaster): one message holding every fixed joint's transform, parent link
  -> child link, once at start; when the URDF's root link is not ``base_link`` (the Go2's is
  ``base``), an identity ``base_link -> <root link>`` too;
- /tf (tf2_msgs/TFMessage, reliable, keep-last 100, volatile, as tf2's TransformBroadcaster):
  for each /joint_states message (at most ``publish_frequency`` of them per second), one message
  with the transform of every moving joint it names, parent link -> child link, stamped with
  the /joint_states message's own stamp (time is in the data: never the moment it arrived).

Frame names are the URDF's link names. The floating base is the simulator's: ``odom ->
base_link`` (REP-105) comes on /tf from the kinematic or the physics simulator, in messages of
its own; this node never publishes it. The maths (:mod:`gait_nodes.robot.link_poses`) has no
ROS in it.

``publish_frequency`` [Hz] bounds the /tf rate by the stamps, as ROS's parameter of that name
does: a /joint_states message stamped less than ``1 / publish_frequency`` after the last one
published is skipped before any work. The default is ROS's, 20 Hz (one /joint_states message in
five of the simulators'); 0 publishes one /tf message for every /joint_states message. Joints of
/joint_states that the URDF does not move are ignored, as ROS's node does.
A /joint_states message that breaks its contract (positions not one per name, a repeated name,
a NaN) is dropped and reported on /diagnostics (``robot_state_publisher: input
/joint_states``).

Under ROS, ROS's own node can take this one's place: ``python -m gait_nodes run
--no-state-publisher`` or ``ros2 launch gait_nodes gait.launch.py state_publisher:=false``, then
``ros2 run robot_state_publisher robot_state_publisher --ros-args -p
robot_description:="$(cat URDF)"`` (docs/ros_tools.md).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np

from gait_nodes.cli import run_node
from gait_nodes.contract import BASE_FRAME, time_msg_to_ns
from gait_nodes.diagnostics import DiagnosticsReporter
from gait_nodes.errors import ConfigError, GaitNodesError, ParameterError, os_error_text
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.interfaces import get_constructor, get_message
from gait_nodes.paths import node_defaults as shipped_node_defaults
from gait_nodes.robot.link_poses import LinkPoses, LinkTransforms
from gait_nodes.robot.model import load_robot_model
from gait_nodes.runtime import DurabilityPolicy, QoSProfile, SetParametersResult
from gait_nodes.settings import checked_number

NODE_NAME = 'robot_state_publisher'
JOINT_STATES_TOPIC = '/joint_states'
#: Depth of /tf, as tf2's TransformBroadcaster offers it.
TF_DEPTH = 100
#: Highest ``publish_frequency`` [Hz].
MAX_PUBLISH_FREQUENCY_HZ = 10000.0
#: Parameters read once, at start.
FIXED_PARAMETERS = ('robot',)
_NS_PER_S = 1_000_000_000


def node_defaults() -> dict:
    """Parameter defaults from ``config/robot_state_publisher.yaml``."""
    return shipped_node_defaults(NODE_NAME)


@dataclass(frozen=True)
class StatePublisherParams:
    """The node's parameters, validated (meanings in config/robot_state_publisher.yaml)."""

    robot: str
    publish_frequency: float

    @classmethod
    def from_values(cls, values: dict) -> StatePublisherParams:
        """Validate raw parameter values; ParameterError naming the value and the range."""
        robot = values['robot']
        if not isinstance(robot, str) or not robot:
            raise ParameterError(f'robot must be a robot name or YAML path, got {robot!r}')
        return cls(robot=robot, publish_frequency=checked_number(
            values, 'publish_frequency', 0.0, MAX_PUBLISH_FREQUENCY_HZ))

    @property
    def period_ns(self) -> int:
        """Least stamp difference between two /tf messages [ns]; 0: no limit."""
        if self.publish_frequency == 0.0:
            return 0
        return int(math.ceil(_NS_PER_S / self.publish_frequency))


class RobotStatePublisher(GuardedNode):
    """Publishes /robot_description, /tf_static and /tf (see the module docstring)."""

    def __init__(self):
        super().__init__(NODE_NAME)
        values = {name: self.declare_parameter(name, default).value
                  for name, default in node_defaults().items()}
        self.params = StatePublisherParams.from_values(values)
        robot = load_robot_model(self.params.robot)
        self.urdf_path = robot.description.urdf_path
        try:
            # The file's own text, byte for byte (no newline translation).
            self.urdf_text = self.urdf_path.read_bytes().decode('utf-8')
        except (OSError, UnicodeDecodeError) as exc:
            reason = os_error_text(exc) if isinstance(exc, OSError) else str(exc)
            raise ConfigError(f'{self.urdf_path}: cannot read the URDF: {reason}') from exc
        self.poses = LinkPoses(robot, BASE_FRAME)
        self.diagnostics = DiagnosticsReporter(self, robot.name)
        self.faults = FaultGuard(self, self.diagnostics)
        self._new = {name.rsplit('/', 1)[1]: get_constructor(name) for name in (
            'std_msgs/msg/Header', 'geometry_msgs/msg/TransformStamped',
            'geometry_msgs/msg/Transform', 'geometry_msgs/msg/Vector3',
            'geometry_msgs/msg/Quaternion', 'tf2_msgs/msg/TFMessage', 'std_msgs/msg/String')}
        # Joint names of the last /joint_states message, once checked for repeats.
        self._checked_names: tuple[str, ...] | None = None
        self._last_published_ns: int | None = None
        # The last Vector3 of each child link, reused while its value stays (a revolute
        # joint's translation never changes): published messages are read-only.
        self._translations: dict[str, tuple] = {}

        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        tf_message = get_message('tf2_msgs/msg/TFMessage')
        self._description_publisher = self.create_publisher(
            get_message('std_msgs/msg/String'), 'robot_description', latched)
        self._static_publisher = self.create_publisher(tf_message, '/tf_static', latched)
        self._tf_publisher = self.create_publisher(tf_message, '/tf', TF_DEPTH)
        self.create_subscription(get_message('sensor_msgs/msg/JointState'), 'joint_states',
                                 self._on_joint_states, 10)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._description_publisher.publish(self._new['String'](self.urdf_text))
        self._static_publisher.publish(
            self._message(self.get_clock().now().to_msg(), self.poses.static))
        self.get_logger().info(
            f'{robot.name}: {self.urdf_path.name} on robot_description, '
            f'{len(self.poses.static)} fixed transforms on /tf_static, '
            f'{len(self.poses.moving_joints)} moving joints on /tf '
            + (f'at most {self.params.publish_frequency:g} Hz'
               if self.params.period_ns else 'for every /joint_states message'))

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        values = {'robot': self.params.robot,
                  'publish_frequency': self.params.publish_frequency}
        for parameter in parameters:
            if parameter.name in values:
                values[parameter.name] = parameter.value
        try:
            params = StatePublisherParams.from_values(values)
            for fixed in FIXED_PARAMETERS:
                if getattr(params, fixed) != getattr(self.params, fixed):
                    raise ParameterError(f'{fixed} is fixed at start '
                                         f'({getattr(self.params, fixed)}); restart the node')
        except GaitNodesError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.params = params
        return SetParametersResult(successful=True)

    def _on_joint_states(self, msg) -> None:
        names, positions = msg.name, msg.position
        if len(positions) != len(names):
            self.diagnostics.drop(JOINT_STATES_TOPIC, f'{len(positions)} positions for '
                                                      f'{len(names)} joint names')
            return
        names = tuple(names)
        if names != self._checked_names:
            if len(set(names)) != len(names):
                repeated = sorted({n for n in names if names.count(n) > 1})
                self.diagnostics.drop(JOINT_STATES_TOPIC, f'joint names repeated: {repeated}')
                return
            self._checked_names = names
        stamp = msg.header.stamp
        stamp_ns = time_msg_to_ns(stamp)
        last_ns, period_ns = self._last_published_ns, self.params.period_ns
        if period_ns and last_ns is not None and 0 <= stamp_ns - last_ns < period_ns:
            return
        values = np.asarray(positions, dtype=float)
        if not np.isfinite(values).all():
            bad = [n for n, v in zip(names, values.tolist(), strict=True) if not math.isfinite(v)]
            self.diagnostics.drop(JOINT_STATES_TOPIC, f'positions not finite: {bad}')
            return
        transforms = self.poses.moving(names, values)
        if len(transforms):
            self._tf_publisher.publish(self._message(stamp, transforms))
            self._last_published_ns = stamp_ns

    def _message(self, stamp, transforms: LinkTransforms):
        """The TFMessage of ``transforms``, every header stamped ``stamp`` (shared)."""
        new = self._new
        header, transform_stamped = new['Header'], new['TransformStamped']
        transform, quaternion = new['Transform'], new['Quaternion']
        cache = self._translations
        rows = []
        for parent, child, translation, rotation in zip(
                transforms.parents, transforms.children, transforms.translations_m.tolist(),
                transforms.rotations_xyzw.tolist(), strict=True):
            cached = cache.get(child)
            if cached is None or cached[0] != translation:
                cached = cache[child] = (translation, new['Vector3'](*translation))
            rows.append(transform_stamped(header(stamp, parent), child,
                                          transform(cached[1], quaternion(*rotation))))
        return new['TFMessage'](rows)


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.robot_state_publisher [--ros-args ...]``."""
    return run_node(lambda options: RobotStatePublisher(), args,
                    prog='python -m gait_nodes.robot_state_publisher',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
