"""Physics simulator (issue 27): the MuJoCo model from the URDF, the robot standing, a walk.

The checks are physics: a robot at rest is carried by its feet (the contact forces sum to its
weight, their centre of pressure is under its centre of mass), it stands where it was put, and a
graph run with ``--simulator physics`` records the simulation's measurements (efforts, contact
wrenches, a base that moves as the contacts let it).
"""

import math
import sys

import numpy as np
import pytest

from gait_nodes import graph, runtime
from gait_nodes.contract import base_transforms, contact_wrench_from_msg, time_msg_to_ns
from gait_nodes.geometry import signed_distance
from gait_nodes.interfaces import deserialize_message, get_message
from gait_nodes.node_parameters import parameter_names
from gait_nodes.planning.terrain import Staircase
from gait_nodes.robot.description import available_robots, load_robot_description
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import nominal_configuration
from gait_nodes.sim.mujoco_model import (
    ACTUATOR_PREFIX,
    FOOT_GEOM_PREFIX,
    STAIR_GEOM_PREFIX,
    PhysicsUnavailableError,
    build_spec,
    import_mujoco,
    load_physics_model,
    model_digest,
    urdf_effort_limits,
)
from gait_nodes.sim.physics import PhysicsSimulation, centre_of_pressure

mujoco = pytest.importorskip('mujoco')

NS = 1_000_000_000
GRAVITY = 9.81


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A cache of our own: the test builds its models."""
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'cache'))


def roll_pitch_deg(q) -> tuple[float, float]:
    x, y, z, w = q[3:7]
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    return math.degrees(roll), math.degrees(pitch)


@pytest.mark.parametrize('name', available_robots())
def test_the_model_is_built_from_every_robots_urdf_and_yaml(name, cache):
    robot = load_robot_model(name)
    physics = load_physics_model(robot.description, robot.joint_names)
    model = physics.model
    assert physics.mjcf_path.is_file()
    # The URDF's inertias as they are: MuJoCo's robot weighs what Pinocchio's does.
    assert model.body_subtreemass[model.body(physics.base_body).id] == pytest.approx(
        robot.mass_kg, rel=1e-6)
    assert model.jnt_type[model.body(physics.base_body).jntadr[0]] == mujoco.mjtJoint.mjJNT_FREE
    # One drive per joint, its force limit the URDF's effort limit, the YAML's gains.
    efforts = urdf_effort_limits(robot.description.urdf_path.read_text())
    settings = robot.description.physics
    assert model.nu == len(robot.joint_names)
    for name_, limit in zip(robot.joint_names, physics.effort_limits, strict=True):
        actuator = model.actuator(ACTUATOR_PREFIX + name_)
        assert limit == efforts[name_]
        assert model.actuator_forcerange[actuator.id].tolist() == [-limit, limit]
        assert model.actuator_gainprm[actuator.id, 0] == settings.joint_stiffness_nm_per_rad
        assert model.actuator_biasprm[actuator.id, 2] == -settings.joint_damping_nm_s_per_rad
        assert model.dof_armature[model.joint(name_).dofadr[0]] == settings.joint_armature_kg_m2
    shapes = {'cylinder': mujoco.mjtGeom.mjGEOM_CYLINDER, 'sphere': mujoco.mjtGeom.mjGEOM_SPHERE,
              'box': mujoco.mjtGeom.mjGEOM_BOX}
    for foot in robot.description.feet:
        geom = model.geom(FOOT_GEOM_PREFIX + foot.name)
        assert model.geom_bodyid[geom.id] == model.body(foot.frame).id
        assert model.geom_type[geom.id] == shapes[settings.foot.shape]
        assert model.geom_friction[geom.id, 0] == settings.foot_friction
    # Only the feet collide, and only with the ground.
    colliding = {model.geom(g).name for g in range(model.ngeom) if model.geom_contype[g]}
    assert colliding == {FOOT_GEOM_PREFIX + foot for foot in robot.foot_names}


def test_the_feet_are_what_the_robot_yaml_says():
    shapes = {name: load_robot_description(name).physics.foot for name in
              ('robosimian', 'go2', 'biped')}
    assert (shapes['robosimian'].shape, shapes['robosimian'].size_m[0]) == ('cylinder', 0.055)
    go2 = load_robot_description('go2')
    # go2's YAML says nothing of the physics foot: a sphere of its foot_frame_height_m.
    assert (shapes['go2'].shape, shapes['go2'].size_m) == (
        'sphere', (go2.extra['foot_frame_height_m'],))
    assert shapes['go2'].centre_in_foot.tolist() == [0.0, 0.0, 0.0]
    assert shapes['biped'].shape == 'box'


def test_the_cached_model_is_the_one_built_and_a_change_makes_another(cache):
    robot = load_robot_model('biped')
    first = load_physics_model(robot.description, robot.joint_names)
    again = load_physics_model(robot.description, robot.joint_names)
    assert again.mjcf_path == first.mjcf_path
    assert again.model.nbody == first.model.nbody
    assert np.array_equal(again.model.actuator_gainprm, first.model.actuator_gainprm)
    stairs = Staircase(0.25, 0.07, 0.3, 3)
    assert model_digest(robot.description, stairs, 0.001) != model_digest(
        robot.description, Staircase(), 0.001)
    with_stairs = load_physics_model(robot.description, robot.joint_names, stairs)
    assert with_stairs.mjcf_path != first.mjcf_path
    tops = sorted(with_stairs.model.geom_size[with_stairs.model.geom(f'{STAIR_GEOM_PREFIX}{k}')
                                              .id, 2] * 2 for k in range(3))
    assert tops == pytest.approx([0.07, 0.14, 0.21])


def test_the_model_needs_the_yamls_gains(tmp_path):
    from gait_nodes.errors import ConfigError

    source = load_robot_description('biped')
    text = source.path.read_text()
    yaml_path = tmp_path / 'biped.yaml'
    yaml_path.write_text(text[:text.index('physics:')].replace(
        'urdf: biped.urdf', f'urdf: {source.urdf_path}'))
    description = load_robot_description(yaml_path)
    with pytest.raises(ConfigError, match='physics'):
        build_spec(description, description.joint_names)


def test_mujoco_missing_says_how_to_install_it(monkeypatch, capsys):
    from gait_nodes.__main__ import main

    monkeypatch.setitem(sys.modules, 'mujoco', None)
    with pytest.raises(PhysicsUnavailableError, match='pip install mujoco'):
        import_mujoco()
    assert main(['run', '--fast', '--simulator', 'physics', '--duration', '1']) == 2
    assert 'pip install mujoco' in capsys.readouterr().err


def test_centre_of_pressure_of_flat_contacts_is_their_force_weighted_mean():
    rng = np.random.default_rng(3)
    points = np.c_[rng.uniform(-1, 1, (6, 2)), np.full(6, 0.07)]
    forces = np.c_[rng.uniform(-20, 20, (6, 2)), rng.uniform(10, 100, 6)]
    cop = centre_of_pressure(forces.sum(0), np.cross(points, forces).sum(0), 0.07)
    expected = (points[:, :2] * forces[:, 2:]).sum(0) / forces[:, 2].sum()
    assert cop[:2] == pytest.approx(expected, abs=1e-12)
    assert cop[2] == 0.07
    assert np.isnan(centre_of_pressure(np.zeros(3), np.zeros(3), 0.0)[:2]).all()


def _stand(robot, seconds: float):
    physics = load_physics_model(robot.description, robot.joint_names)
    q0 = nominal_configuration(robot)
    simulation = PhysicsSimulation(robot, physics, q0)
    hold = robot.joint_positions(q0)
    return q0, [simulation.step(hold, 0.01) for _ in range(round(seconds / 0.01))]


def test_the_core_is_deterministic(cache):
    """Built (a cold cache), then loaded (a warm one): the same motion, to the bit."""
    robot = load_robot_model('biped')
    _, first = _stand(robot, 0.3)
    _, second = _stand(robot, 0.3)
    assert all(np.array_equal(a.q, b.q) and np.array_equal(a.foot_wrenches_in_foot,
                                                           b.foot_wrenches_in_foot)
               for a, b in zip(first, second, strict=True))


def test_the_contacts_are_on_the_floor_and_the_cop_in_their_polygon():
    """Go2 on its four 22 mm spheres, sunk by different depths: every force on the floor.

    The contact points are on the floor's surface (not at the middle of each sphere's
    penetration), so the centre of pressure of every step is in the hull of the points the
    floor pushed on: before session 24 the feet's different depths and their friction moved it
    up to 20 um outside, and a 1 N threshold on the points up to 0.2 mm.
    """
    robot = load_robot_model('go2')
    _, steps = _stand(robot, 1.0)
    for step in steps:
        points = step.contact_points_in_world
        assert len(points) >= 4
        assert np.abs(points[:, 2]).max() < 1e-9
        assert signed_distance(step.cop_in_world[None, :2], points[:, :2])[0] > -1e-9
        forces = step.foot_forces_in_world
        assert step.cop_in_world[2] == pytest.approx(0.0, abs=1e-9)
        # The feet's own wrenches give the same centre of pressure on the floor.
        assert centre_of_pressure(forces.sum(0), step.foot_moments_in_world.sum(0), 0.0)[:2] \
            == pytest.approx(step.cop_in_world[:2], abs=1e-12)


class _Listener(runtime.Node):
    """Keeps the physics simulator's outputs."""

    def __init__(self, feet):
        super().__init__('listener', use_global_arguments=False)
        self.messages = {}
        topics = {'/tf': graph.TOPICS['/tf'], '/gait/cop': graph.TOPICS['/gait/cop'],
                  '/gait/com': graph.TOPICS['/gait/com'],
                  '/gait/markers': graph.TOPICS['/gait/markers'],
                  '/joint_states': graph.TOPICS['/joint_states'], **graph.foot_topics(feet)}
        for topic, type_name in topics.items():
            self.messages[topic] = []
            self.create_subscription(get_message(type_name), topic,
                                     self.messages[topic].append, 1000)


def test_robosimian_stands_still_on_its_feet():
    """3 s at rest: the base where it was put, the weight on the feet, the CoP under the COM."""
    from gait_nodes.physics_simulator import PhysicsSimulator

    robot = load_robot_model('robosimian')
    runtime.init(args=[], runtime='inproc', signal_handlers=False)
    try:
        simulator = PhysicsSimulator()
        listener = _Listener(robot.foot_names)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(simulator)
        executor.add_node(listener)
        executor.spin_for(3.0)
    finally:
        runtime.shutdown()
    q0 = nominal_configuration(robot)
    messages = listener.messages
    poses = [t.transform for m in messages['/tf'] for t in base_transforms(m)]
    assert len(poses) == 300
    for pose in poses:
        q = [0, 0, 0, pose.rotation.x, pose.rotation.y, pose.rotation.z, pose.rotation.w]
        roll, pitch = roll_pitch_deg(q)
        assert abs(pose.translation.z - q0[2]) < 0.03
        assert abs(roll) < 3.0 and abs(pitch) < 3.0
        assert math.hypot(pose.translation.x - q0[0], pose.translation.y - q0[1]) < 0.01
    # The last second: at rest, so the ground carries the weight under the COM.
    last = [m for m in messages['/gait/cop'] if time_msg_to_ns(m.header.stamp) > 2 * NS]
    com = {time_msg_to_ns(m.header.stamp): m.point for m in messages['/gait/com']}
    for cop in last:
        point = com.get(time_msg_to_ns(cop.header.stamp))
        if point is not None:
            assert math.hypot(cop.point.x - point.x, cop.point.y - point.y) < 0.005
    weight = robot.mass_kg * GRAVITY
    frames = {foot.frame for foot in robot.description.feet}
    by_stamp = {}
    for topic in graph.foot_topics(robot.foot_names):
        for msg in messages[topic]:
            wrench = contact_wrench_from_msg(msg)
            assert wrench.frame in frames
            by_stamp.setdefault(wrench.stamp_ns, []).append(wrench)
    for stamp, wrenches in by_stamp.items():
        if stamp > 2 * NS:
            assert len(wrenches) == 4
            # RoboSimian's feet stay nearly level: the sum of the normal forces is the weight.
            assert sum(w.force[2] for w in wrenches) == pytest.approx(weight, rel=0.02)
    efforts = messages['/joint_states'][-1].effort
    assert len(efforts) == len(robot.joint_names) and max(map(abs, efforts)) > 1.0
    # /gait/markers: the kinematic simulator's three and the CoP's sphere, at /gait/cop of the
    # same stamp (20 Hz).
    cops = {time_msg_to_ns(m.header.stamp): m.point for m in messages['/gait/cop']}
    arrays = messages['/gait/markers']
    assert len(arrays) >= 59
    for array in arrays:
        assert [m.id for m in array.markers] == [0, 1, 2, 3]
        sphere = array.markers[3]
        stamp = time_msg_to_ns(sphere.header.stamp)
        assert sphere.type == sphere.SPHERE and sphere.action == sphere.ADD
        assert sphere.pose.position == cops[stamp]


def test_the_physics_simulator_declares_the_parameters_known_before_start():
    from gait_nodes.physics_simulator import PhysicsSimulator

    runtime.init(args=['test', '--ros-args', '-p', 'robot:=biped'], runtime='inproc',
                 signal_handlers=False)
    try:
        node = PhysicsSimulator()
        assert set(node._parameters.parameters) == parameter_names('physics_simulator')
        refused = node.set_parameters([runtime.Parameter('stairs_count', value=2)])
        assert not refused[0].successful and 'fixed' in refused[0].reason
        refused = node.set_parameters([runtime.Parameter('rate_hz', value=300.0)])
        assert not refused[0].successful and 'whole number' in refused[0].reason
        assert node.set_parameters([runtime.Parameter('rate_hz', value=200.0)])[0].successful
    finally:
        runtime.shutdown()


def test_a_short_crawl_in_physics_walks_forward_and_records_what_physics_measured(tmp_path):
    from gait_nodes.__main__ import main
    from gait_nodes.bag.reader import BagReader
    from gait_nodes.swing.cache import load_or_build

    robot = load_robot_model('robosimian')
    # The default crawl's value table (family 2, 0.1 m, 1 rad/s), there before the planner
    # starts (built once on a cold cache: the planner then times the walk with it too).
    load_or_build(robot, 2, 0.1, 1.0)
    bag = tmp_path / 'bag'
    assert main(['run', '--fast', '--simulator', 'physics', '--duration', '12',
                 '--record', str(bag), '--no-plot', '--json']) == 0
    q0 = nominal_configuration(robot)
    decoded = {}
    types = {'/tf': graph.TOPICS['/tf'], '/joint_states': graph.TOPICS['/joint_states'],
             '/gait/cop': graph.TOPICS['/gait/cop'], **graph.foot_topics(robot.foot_names)}
    for channel, _, _, payload in BagReader(bag).messages():
        if channel.topic in types:
            decoded.setdefault(channel.topic, []).append(
                deserialize_message(payload, get_message(types[channel.topic])))
    assert set(decoded) == set(types)
    poses = [t.transform for m in decoded['/tf'] for t in base_transforms(m)]
    first, last = poses[0].translation, poses[-1].translation
    assert last.x - first.x > 0.02  # walked forward
    for pose in poses:
        r = pose.rotation
        roll, pitch = roll_pitch_deg([0, 0, 0, r.x, r.y, r.z, r.w])
        assert abs(pose.translation.z - q0[2]) < 0.03
        assert abs(roll) < 3.0 and abs(pitch) < 3.0
    # Measured, not planned: the drives' efforts, and the base carried by the contact forces.
    assert all(len(m.effort) == len(robot.joint_names) for m in decoded['/joint_states'])
    weight = robot.mass_kg * GRAVITY
    totals = {}
    for topic in graph.foot_topics(robot.foot_names):
        for msg in decoded[topic]:
            totals[time_msg_to_ns(msg.header.stamp)] = totals.get(
                time_msg_to_ns(msg.header.stamp), 0.0) + msg.wrench.force.z
    assert np.median(list(totals.values())) == pytest.approx(weight, rel=0.05)
    # The centre of pressure inside the contact polygon (the monitor's, same stamps).
    polygons = {}
    for _, _, _, payload in BagReader(bag).messages(topics=('/gait/support_polygon',)):
        msg = deserialize_message(payload, get_message(graph.TOPICS['/gait/support_polygon']))
        polygons[time_msg_to_ns(msg.header.stamp)] = np.array(
            [(p.x, p.y) for p in msg.polygon.points])
    margins = [signed_distance(np.array([[m.point.x, m.point.y]]),
                               polygons[time_msg_to_ns(m.header.stamp)])[0]
               for m in decoded['/gait/cop'] if time_msg_to_ns(m.header.stamp) in polygons]
    assert len(margins) > 1000 and min(margins) > -1e-6
    # Swings happened: some tick had a foot without load.
    loads = {topic: [m.wrench.force.z for m in decoded[topic]]
             for topic in graph.foot_topics(robot.foot_names)}
    assert any(min(values) < 1.0 for values in loads.values())


def _walk(tmp_path, scenario: str, simulator: str) -> dict:
    """Walk ``scenario`` with ``simulator``; its bag's base poses, CoP and polygons by stamp."""
    from gait_nodes.__main__ import main
    from gait_nodes.bag.analysis import read_gait_series

    bag = tmp_path / f'{scenario}_{simulator}'
    assert main(['run', '--fast', '--scenario', scenario, '--simulator', simulator,
                 '--record', str(bag), '--no-plot', '--json']) == 0
    series = read_gait_series(bag, topics=('/tf', '/gait/cop', '/gait/support_polygon'))
    return {'base': {stamp: pose for stamp, *pose in series.base_poses},
            'cop': {stamp: (x, y) for stamp, x, y, _ in series.cop},
            'polygons': dict(series.polygons)}


def test_the_biped_walks_in_physics_as_planned(tmp_path):
    """biped_walk's 21 s, open loop at the YAML's gains: upright, on the plan, CoP inside."""
    kinematic = _walk(tmp_path, 'biped_walk', 'kinematic')['base']
    physics = _walk(tmp_path, 'biped_walk', 'physics')
    base = physics['base']
    stamps = sorted(set(kinematic) & set(base))
    assert len(stamps) > 2000
    for stamp in stamps:
        x, y, z, qx, qy, qz, qw = base[stamp]
        roll, pitch = roll_pitch_deg([0, 0, 0, qx, qy, qz, qw])
        assert abs(roll) < 3.0 and abs(pitch) < 3.0
        assert abs(z - kinematic[stamp][2]) < 0.03
        assert math.hypot(x - kinematic[stamp][0], y - kinematic[stamp][1]) < 0.05
    walked = base[stamps[-1]][0] - base[stamps[0]][0]
    planned = kinematic[stamps[-1]][0] - kinematic[stamps[0]][0]
    assert planned > 0.9 and walked == pytest.approx(planned, rel=0.05)
    margins = [signed_distance(np.array([cop]), physics['polygons'][stamp])[0]
               for stamp, cop in physics['cop'].items() if stamp in physics['polygons']]
    assert len(margins) > 2000 and min(margins) > -1e-6


def test_a_rolling_foot_does_not_slip_and_a_sliding_one_does():
    """Slip is the contact material's motion, not the foot frame's (a sphere foot rolls)."""
    from gait_nodes.sim.physics import material_displacement

    radius, turn = 0.022, math.radians(20.0)
    steps = 200
    # A sphere rolling along x: its centre moves radius * angle, it turns about y.
    slip = np.zeros(3)
    material = (np.array([0.0, 0.0, -radius]), np.array([0.0, 0.0, 0.0]))
    for k in range(1, steps + 1):
        angle = turn * k / steps
        centre = np.array([radius * angle, 0.0, radius])
        rotation = np.array([[math.cos(angle), 0.0, math.sin(angle)], [0.0, 1.0, 0.0],
                             [-math.sin(angle), 0.0, math.cos(angle)]])
        slip += material_displacement(centre, rotation, material)
        contact = centre - np.array([0.0, 0.0, radius])  # the point under the sphere now
        material = (rotation.T @ (contact - centre), contact)
    assert radius * turn == pytest.approx(0.00768, abs=1e-5)  # how far its frame moved
    assert math.hypot(*slip[:2]) < 1e-5
    # The same foot sliding 5 mm without turning: all of it is slip.
    material = (np.array([0.0, 0.0, -radius]), np.array([0.0, 0.0, 0.0]))
    moved = material_displacement(np.array([0.005, 0.0, radius]), np.eye(3), material)
    assert moved[:2] == pytest.approx([0.005, 0.0])
