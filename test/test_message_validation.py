"""rclpy-strict field checks of generated messages (gait_nodes.interfaces.validate_message)."""

import pytest

from gait_nodes.errors import InterfaceError
from gait_nodes.interfaces import available_types, generated_class, validate_message


@pytest.mark.parametrize('type_name', available_types())
def test_default_messages_are_valid(type_name):
    validate_message(generated_class(type_name)())


@pytest.mark.parametrize(('type_name', 'field', 'value', 'fragment'), [
    ('geometry_msgs/msg/Point', 'x', 1, 'must be float'),
    ('geometry_msgs/msg/Point', 'x', '1.0', 'must be float'),
    ('builtin_interfaces/msg/Time', 'nanosec', -1, 'int in [0, 4294967295]'),
    ('builtin_interfaces/msg/Time', 'sec', 1 << 31, 'int in'),
    ('builtin_interfaces/msg/Time', 'sec', True, 'int in'),
    ('std_msgs/msg/String', 'data', b'bytes', 'must be str'),
    ('sensor_msgs/msg/JointState', 'position', [0.0, 1], 'position[1] must be float'),
    ('sensor_msgs/msg/JointState', 'name', 'abc', 'must be a sequence of string'),
    ('std_msgs/msg/ColorRGBA', 'a', None, 'must be float'),
    ('std_msgs/msg/Header', 'stamp', 0, 'must be a builtin_interfaces/msg/Time'),
    # Values a quick look at their types would let through.
    ('sensor_msgs/msg/JointState', 'position', (0.0, True), 'position[1] must be float'),
    ('sensor_msgs/msg/JointState', 'name', ['hip', 1], 'name[1] must be str'),
    ('sensor_msgs/msg/JointState', 'name', b'hip', 'name[0] must be str'),
    ('sensor_msgs/msg/CompressedImage', 'data', [0, 256], 'data[1] must be int in [0, 255]'),
    ('sensor_msgs/msg/CompressedImage', 'data', [255, -1], 'data[1] must be int in [0, 255]'),
    ('diagnostic_msgs/msg/DiagnosticStatus', 'level', 256, 'int in [0, 255]'),
    ('nav_msgs/msg/Path', 'poses', [generated_class('geometry_msgs/msg/PoseStamped')(),
                                    generated_class('geometry_msgs/msg/Pose')()],
     'poses[1] must be a geometry_msgs/msg/PoseStamped'),
])
def test_wrong_field_values_are_named(type_name, field, value, fragment):
    msg = generated_class(type_name)()
    setattr(msg, field, value)
    with pytest.raises(InterfaceError, match=fragment.replace('[', r'\[').replace(']', r'\]')):
        validate_message(msg)


def test_fixed_array_size_is_checked():
    cls = generated_class('visualization_msgs/msg/UVCoordinate')
    validate_message(cls(u=0.5, v=0.25))
    pose = generated_class('geometry_msgs/msg/Pose')()
    pose.position = generated_class('geometry_msgs/msg/Quaternion')()
    with pytest.raises(InterfaceError, match='Pose.position must be a geometry_msgs/msg/Point'):
        validate_message(pose)


def test_nested_error_path():
    stamped = generated_class('geometry_msgs/msg/PointStamped')()
    stamped.header.stamp.sec = 1.5
    with pytest.raises(InterfaceError, match=r'PointStamped\.header\.stamp\.sec'):
        validate_message(stamped)


def test_a_wrong_value_deep_in_a_sequence_is_named():
    path = generated_class('nav_msgs/msg/Path')()
    path.poses = [generated_class('geometry_msgs/msg/PoseStamped')() for _ in range(3)]
    validate_message(path)
    path.poses[2].pose.position.x = 1
    with pytest.raises(InterfaceError, match=r'Path\.poses\[2\]\.pose\.position\.x must be float'):
        validate_message(path)


def test_values_of_other_accepted_types_pass():
    # What rclpy's setters take besides the plain types: numpy floats, tuples, bytes.
    import numpy as np

    state = generated_class('sensor_msgs/msg/JointState')(
        name=('hip', 'knee'), position=[np.float64(0.5), 1.0], velocity=(0.0, np.float32(2.0)))
    validate_message(state)
    image = generated_class('sensor_msgs/msg/CompressedImage')(data=bytearray(b'\x00\xff'))
    validate_message(image)
    image.data = [0, 255]
    validate_message(image)
