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
