"""What /gait/markers shows of the plan: the footholds and the swing paths, for RViz and Foxglove.

/gait/markers (visualization_msgs/MarkerArray) has several publishers, as a ROS marker topic
usually has, each in its own marker namespace (a display shows or hides a namespace):

``gait`` (the simulator, ``markers_rate_hz``)
    ZMP sphere (id 0), COM sphere (id 1), support polygon outline (id 2); the physics simulator
    adds the centre of pressure (id 3).
``footsteps`` (footstep_planner, with each new /gait/footsteps plan)
    One SPHERE_LIST (id 0): the plan's footholds (:func:`footholds`), each a flat disc of the
    robot's foot diameter, coloured by foot. It lasts until the next plan replaces it.
``swing_paths`` (swing_leg_policy, with each /gait/swing_trajectory it sends)
    One LINE_STRIP per foot (id = the foot's index in the robot YAML, so that the swings of
    different feet show together) through the swing's waypoints; it lasts until
    ``SWING_PATH_AFTER_S`` after touch-down.

Every marker is in frame ``odom`` and stamped when it is published (a display looks its frame
up at that stamp: a plan's start or a swing's lift-off may be long past or still ahead).
"""

from __future__ import annotations

import numpy as np

from gait_nodes.contract import WORLD_FRAME, FootstepPlan, SwingTrajectory, ns_to_time_msg
from gait_nodes.interfaces import get_constructor, get_message

SIMULATOR_NAMESPACE = 'gait'
FOOTSTEPS_NAMESPACE = 'footsteps'
SWING_PATHS_NAMESPACE = 'swing_paths'
#: One colour a foot, by its index in the robot YAML (cycled); the walk's video uses them too.
FOOT_COLOURS = ((0.1, 0.55, 0.95), (0.2, 0.75, 0.45), (0.6, 0.35, 0.85), (0.05, 0.75, 0.8),
                (0.9, 0.35, 0.45), (0.6, 0.6, 0.1))
#: Foothold diameter for a robot without a foot radius (point feet) [m].
DEFAULT_FOOTHOLD_DIAMETER_M = 0.05
#: Height of a foothold's disc [m]: flat, so that it reads as a footprint.
FOOTHOLD_HEIGHT_M = 0.01
#: Width of a swing path's line [m].
SWING_PATH_WIDTH_M = 0.008
#: A swing path stays this long after its touch-down [s].
SWING_PATH_AFTER_S = 1.0
_NS_PER_S = 1_000_000_000


def footholds(plan: FootstepPlan) -> tuple[np.ndarray, np.ndarray]:
    """Every place a foot of ``plan`` stands: each foot's at the start, then each landing.

    Returns:
        (N, 3) positions in odom [m] and (N,) foot indices (into ``plan.foot_names``): the feet
        in order at the plan's first point, then the landing place of each swing, by
        contact change then foot.
    """
    changes, feet = np.nonzero(plan.moved())
    positions = np.concatenate([plan.positions_in_world[0],
                                plan.positions_in_world[changes + 1, feet]])
    indices = np.concatenate([np.arange(len(plan.foot_names)), feet])
    return positions, indices


def footsteps_markers(plan: FootstepPlan, stamp_ns: int, foot_radius_m: float):
    """MarkerArray of one SPHERE_LIST: ``plan``'s footholds, coloured by foot.

    Args:
        plan: The plan published on /gait/footsteps.
        stamp_ns: Publication time [ns].
        foot_radius_m: The robot's foot radius [m]; 0 (point feet) draws
            ``DEFAULT_FOOTHOLD_DIAMETER_M``.
    """
    positions, indices = footholds(plan)
    diameter = 2.0 * foot_radius_m if foot_radius_m > 0.0 else DEFAULT_FOOTHOLD_DIAMETER_M
    marker = _marker(stamp_ns, FOOTSTEPS_NAMESPACE, 0, get_message(
        'visualization_msgs/msg/Marker').SPHERE_LIST, (diameter, diameter, FOOTHOLD_HEIGHT_M),
        _colour(0), 0, positions, [_colour(f) for f in indices.tolist()])
    return get_constructor('visualization_msgs/msg/MarkerArray')([marker])


def swing_path_markers(swing: SwingTrajectory, foot_index: int, stamp_ns: int):
    """MarkerArray of one LINE_STRIP through ``swing``'s waypoints (id ``foot_index``).

    Args:
        swing: The trajectory published on /gait/swing_trajectory.
        foot_index: The foot's index in the robot YAML (the marker id and the colour).
        stamp_ns: Publication time [ns]; the marker lasts from it until ``SWING_PATH_AFTER_S``
            after the touch-down.
    """
    touch_down_ns = swing.start_ns + int(round(swing.duration_s * _NS_PER_S))
    lifetime_ns = max(touch_down_ns - stamp_ns, 0) + int(SWING_PATH_AFTER_S * _NS_PER_S)
    marker = _marker(stamp_ns, SWING_PATHS_NAMESPACE, foot_index, get_message(
        'visualization_msgs/msg/Marker').LINE_STRIP, (SWING_PATH_WIDTH_M, 0.0, 0.0),
        _colour(foot_index), lifetime_ns, swing.positions_in_world, [])
    return get_constructor('visualization_msgs/msg/MarkerArray')([marker])


def _colour(foot_index: int):
    red, green, blue = FOOT_COLOURS[foot_index % len(FOOT_COLOURS)]
    return get_constructor('std_msgs/msg/ColorRGBA')(red, green, blue, 1.0)


def _marker(stamp_ns: int, namespace: str, marker_id: int, kind: int, scale: tuple, colour,
            lifetime_ns: int, points: np.ndarray, colours: list):
    """An ADD marker in odom, every field given (as rclpy's message classes take them)."""
    new = {name.rsplit('/', 1)[1]: get_constructor(name) for name in (
        'std_msgs/msg/Header', 'geometry_msgs/msg/Pose', 'geometry_msgs/msg/Point',
        'geometry_msgs/msg/Quaternion', 'geometry_msgs/msg/Vector3',
        'builtin_interfaces/msg/Duration', 'builtin_interfaces/msg/Time',
        'sensor_msgs/msg/CompressedImage', 'visualization_msgs/msg/MeshFile',
        'visualization_msgs/msg/Marker')}
    marker_type = get_message('visualization_msgs/msg/Marker')
    origin = new['Pose'](new['Point'](0.0, 0.0, 0.0), new['Quaternion'](0.0, 0.0, 0.0, 1.0))
    no_texture = new['CompressedImage'](new['Header'](new['Time'](0, 0), ''), '', b'')
    return new['Marker'](
        new['Header'](ns_to_time_msg(stamp_ns), WORLD_FRAME), namespace, int(marker_id), kind,
        marker_type.ADD, origin, new['Vector3'](*map(float, scale)), colour,
        new['Duration'](*divmod(int(lifetime_ns), _NS_PER_S)), False,
        [new['Point'](x, y, z) for x, y, z in np.asarray(points, dtype=float).tolist()],
        colours, '', no_texture, [], '', '', new['MeshFile']('', b''), False)


def from_simulator(array) -> bool:
    """Whether a /gait/markers MarkerArray is the simulator's (namespace ``gait``)."""
    return any(marker.ns == SIMULATOR_NAMESPACE for marker in array.markers)
