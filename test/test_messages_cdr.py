"""CDR of the generated message classes, checked against rosbags' ROS 2 Jazzy typestore.

For every shipped message type (and for a few synthetic types that exercise what the shipped ones
do not: fixed arrays, bounded sequences and strings, every primitive in every container, alignment
after odd-sized fields), random content is generated from the parsed definition itself, never by
hand per message. The tests check that

* our ``serialize()`` gives byte for byte what ``Typestore.serialize_cdr`` gives for the same
  content;
* our ``deserialize()`` reads rosbags' bytes (little and big endian) back to the same content, and
  rosbags reads ours;
* our own round trip keeps the content and the bytes;
* the parsed definitions (fields and constants) equal rosbags' ones, and defaults are the ROS ones;
* malformed input and out-of-range content raise :class:`SerializationError` with a clear message.

Content is compared in a plain form (:func:`plain`): nested tuples and lists of Python values where
a float is ``(value, sign)`` so that ``-0.0`` differs from ``0.0``, and a NaN is the marker
``'nan'`` since NaN != NaN; NaN bit patterns are checked by comparing bytes only.
"""

from __future__ import annotations

import contextlib
import functools
import math
import random
import struct
import sys
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gait_nodes.errors import SerializationError
from gait_nodes.interfaces import available_types, generated_class, msgdef
from gait_nodes.interfaces.generate import make_class
from gait_nodes.interfaces.msgdef import PRIMITIVES, FieldDef, MsgDef, parse_msg

TYPES = available_types()

# -------------------------------------------------------------------------------------------------
# The two sets of types: shipped ones and synthetic ones.


class Universe:
    """Message types of one kind, with their definitions, our classes and a rosbags typestore.

    Args:
        name: Label used in test ids.
        definition: ``type_name -> MsgDef``.
        cls: ``type_name -> our message class``.
        typestore: rosbags typestore that knows the same types.
    """

    def __init__(self, name: str, definition: Callable[[str], MsgDef],
                 cls: Callable[[str], type], typestore):
        self.name = name
        self.definition = definition
        self.cls = cls
        self.ts = typestore

    def fields(self, type_name: str) -> tuple[FieldDef, ...]:
        """Fields of ``type_name`` as our parser sees them."""
        return self.definition(type_name).fields

    def __repr__(self) -> str:
        return self.name


SHIPPED = Universe('shipped', msgdef, generated_class, get_typestore(Stores.ROS2_JAZZY))


def _everything_text() -> str:
    """Definition with each primitive in each container, each after a 1-byte field.

    Every variable-size field is followed by a float64, which needs padding to 8 that can only be
    computed at run time.
    """
    lines = ['# Constants and defaults', 'int8 NEG=-5', 'string NAME="abc # not a comment"',
             'float64 PI=3.14', 'bool FLAG=true', 'uint64 BIG=18446744073709551615']
    for base in PRIMITIVES:
        for suffix, container in (('single', ''), ('array', '[3]'), ('seq', '[]'),
                                  ('bseq', '[<=3]')):
            # uint8[5] puts the count of the unbounded sequence at 4 (mod 8), uint8 puts the
            # count of the bounded one at 0 (mod 8): both phases of an empty sequence of float64.
            lines.append(f'uint8{"[5]" if suffix == "seq" else ""} pad_{base}_{suffix}')
            lines.append(f'{base}{container} {base}_{suffix}')
            if suffix.endswith('seq'):
                lines.append(f'float64 after_{base}_{suffix}')
    lines += [
        'string s', 'float64 after_s', 'uint8 pad_s_bounded', 'string<=5 s_bounded',
        'uint8 pad_s_array', 'string[2] s_array', 'float64 after_s_array', 'string[] s_seq',
        'float64 after_s_seq', 'string<=3[<=2] s_bseq', 'uint8 pad_small', 'Small small',
        'uint8 pad_small_array', 'Small[2] small_array', 'Small[] small_seq',
        'float64 after_small_seq', 'Small[<=2] small_bseq', 'Empty empty', 'Empty[2] empty_array',
        'float64 after_empty_array', 'Empty[] empty_seq', 'Tail tail', 'float64 after_tail',
        'Tail[2] tail_array', 'Tail[] tail_seq', 'uint8 pad_point', 'geometry_msgs/Point point',
        'Header header', 'float64 after_header', 'int32 with_default 42',
        'float64[2] array_default [1.5, -2.0]', 'string string_default "hi # not a comment"',
        'bool bool_default true', 'int16[] seq_default [-1, 2]', 'uint8[4] u8_tail',
    ]
    return '\n'.join(lines) + '\n'


#: Synthetic definitions, dependencies first. ``Small`` needs padding inside; ``Tail`` starts with
#: a sequence and ends with a 1-byte field; ``Empty`` gets ROS 2's placeholder member; ``Record``
#: has no container but strings, a bounded one, and fields of every alignment between them (runs
#: of them are packed at once, see RecordRun), ``Records`` holds them in each kind of container.
SYNTHETIC_TEXT = {
    'cdr_test_msgs/msg/Small': 'uint8 a\nfloat64 b\nint16 c\n',
    'cdr_test_msgs/msg/Record': ('uint8 a\nstring name\nfloat64 b\nHeader header\nstring<=4 tag\n'
                                 'int16 c\nSmall small\nbool d\n'),
    'cdr_test_msgs/msg/Records': ('uint8 pad\nRecord[] records\nfloat64 after\nuint8[3] pad2\n'
                                  'Record[5] record_array\nRecord[<=8] bounded\nint8 last\n'),
    'cdr_test_msgs/msg/Empty': '# No fields: ROS 2 gives the message one uint8 placeholder.\n',
    'cdr_test_msgs/msg/Tail': 'float32[] data\nstring label\nint8 last\n',
    'cdr_test_msgs/msg/Everything': _everything_text(),
}
#: rosbags does not add the placeholder of a message without fields; rosidl's IDL (which is what
#: rosbags reads for the shipped std_msgs/Empty) spells it out.
ROSBAGS_EMPTY_TEXT = 'uint8 structure_needs_at_least_one_member\n'
SYNTHETIC_TYPES = list(SYNTHETIC_TEXT)


def _make_synthetic() -> Universe:
    """Classes of the synthetic types (kept out of the package registry) and a rosbags store."""
    definitions: dict[str, MsgDef] = {}
    classes: dict[str, type] = {}

    def add_shipped(type_name: str) -> None:
        if type_name in definitions:
            return
        for dependency in msgdef(type_name).dependencies:
            add_shipped(dependency)
        definitions[type_name] = msgdef(type_name)
        classes[type_name] = generated_class(type_name)

    typestore = get_typestore(Stores.ROS2_JAZZY)
    rosbags_types = {}
    for type_name, text in SYNTHETIC_TEXT.items():
        definition = parse_msg(type_name, text)
        for dependency in definition.dependencies:
            if not dependency.startswith('cdr_test_msgs/'):
                add_shipped(dependency)
        definitions[type_name] = definition
        make_class(definition, definitions, classes)
        rosbags_text = ROSBAGS_EMPTY_TEXT if type_name.endswith('/Empty') else text
        rosbags_types.update(get_types_from_msg(rosbags_text, type_name))
    typestore.register(rosbags_types)
    return Universe('synthetic', definitions.__getitem__, classes.__getitem__, typestore)


SYNTHETIC = _make_synthetic()
CASES = [(SHIPPED, t) for t in TYPES] + [(SYNTHETIC, t) for t in SYNTHETIC_TYPES]
CASE_IDS = [t for _, t in CASES]

# -------------------------------------------------------------------------------------------------
# Hypothesis strategies built from the parsed definitions.

F32_MAX = struct.unpack('<f', b'\xff\xff\x7f\x7f')[0]
F32_MIN_NORMAL = struct.unpack('<f', b'\x00\x00\x80\x00')[0]
F32_MIN_SUBNORMAL = struct.unpack('<f', b'\x01\x00\x00\x00')[0]
F32_MAX_SUBNORMAL = struct.unpack('<f', b'\xff\xff\x7f\x00')[0]
NEG_NAN = math.copysign(math.nan, -1.0)
FLOAT_EXTREMES = {
    'float32': [0.0, -0.0, math.inf, -math.inf, F32_MAX, -F32_MAX, F32_MIN_NORMAL,
                -F32_MIN_NORMAL, F32_MIN_SUBNORMAL, -F32_MIN_SUBNORMAL, F32_MAX_SUBNORMAL,
                math.nan, NEG_NAN],
    'float64': [0.0, -0.0, math.inf, -math.inf, sys.float_info.max, -sys.float_info.max,
                sys.float_info.min, -sys.float_info.min, 5e-324, -5e-324,
                sys.float_info.min - 5e-324, math.nan, NEG_NAN],
}
INT_RANGES = {
    'byte': (0, 255), 'char': (0, 255), 'uint8': (0, 255), 'int8': (-2**7, 2**7 - 1),
    'int16': (-2**15, 2**15 - 1), 'uint16': (0, 2**16 - 1), 'int32': (-2**31, 2**31 - 1),
    'uint32': (0, 2**32 - 1), 'int64': (-2**63, 2**63 - 1), 'uint64': (0, 2**64 - 1),
}
# CDR strings are NUL-terminated, so a '\x00' inside a string cannot go on the wire (ROS 2 readers
# stop at it): it is excluded. The utf-8 codec also excludes lone surrogates, which cannot be
# encoded.
CHARACTERS = st.characters(codec='utf-8', exclude_characters='\x00')

#: Sequence lengths: ``short`` for the many-examples tests, ``long`` for the top level of the long
#: tests (nested levels stay short so that examples remain of reasonable size).
SHORT_SEQUENCE = 6
SHORT_MESSAGE_SEQUENCE = 3
LONG_MIN, LONG_MAX = 100, 300
LONG_MESSAGE_SEQUENCE = 12


def primitive_strategy(base_type: str) -> st.SearchStrategy:
    """Values of one primitive, with the extremes of its type drawn often."""
    if base_type == 'bool':
        return st.booleans()
    if base_type in FLOAT_EXTREMES:
        width = 32 if base_type == 'float32' else 64
        return st.one_of(st.sampled_from(FLOAT_EXTREMES[base_type]), st.floats(width=width))
    low, high = INT_RANGES[base_type]
    return st.one_of(st.sampled_from(sorted({low, low + 1, 0, high - 1, high})),
                     st.integers(low, high))


def _is_flat(universe: Universe, type_name: str) -> bool:
    """Whether a message has only primitive fields, nested included (cheap to draw in bulk)."""
    return all(
        field.container is None and (field.is_primitive or (
            not field.is_string and _is_flat(universe, field.base_type)))
        for field in universe.fields(type_name)
    )


def element_strategy(universe: Universe, field: FieldDef, long: bool) -> st.SearchStrategy:
    """Values of one element of ``field`` (the field itself when it is not a container)."""
    if field.is_primitive:
        return primitive_strategy(field.base_type)
    if field.is_string:
        max_size = field.string_bound or (LONG_MAX if long else 12)
        return st.text(CHARACTERS, max_size=max_size)
    return message_strategy(universe, field.base_type)


def field_strategy(universe: Universe, field: FieldDef, long: bool = False) -> st.SearchStrategy:
    """Values of ``field`` in our representation.

    ``long``: an unbounded sequence gets 100 to 300 elements (messages with only primitive fields)
    or up to 12 (other messages), a string up to 300 characters; nested levels stay short.
    """
    element = element_strategy(universe, field, long)
    if field.container is None:
        return element
    if field.container == 'array':
        return st.lists(element, min_size=field.size, max_size=field.size)
    if field.size:
        min_size, max_size = 0, field.size
    elif field.is_primitive or field.is_string or not long:
        min_size, max_size = (LONG_MIN, LONG_MAX) if long else (0, SHORT_SEQUENCE)
        if not (field.is_primitive or field.is_string):
            max_size = SHORT_MESSAGE_SEQUENCE
    elif _is_flat(universe, field.base_type):
        min_size, max_size = LONG_MIN, LONG_MAX
    else:
        min_size, max_size = 0, LONG_MESSAGE_SEQUENCE
    if field.base_type == 'uint8':
        return st.binary(min_size=min_size, max_size=max_size)
    return st.lists(element, min_size=min_size, max_size=max_size)


@functools.cache
def message_strategy(universe: Universe, type_name: str, long_field: str | None = None
                     ) -> st.SearchStrategy:
    """Instances of our class of ``type_name`` with random content in every field.

    Args:
        universe: Where ``type_name`` is defined.
        type_name: Message type.
        long_field: Name of a top-level field to draw long (see :func:`field_strategy`).
    """
    return st.builds(universe.cls(type_name), **{
        field.name: field_strategy(universe, field, long=field.name == long_field)
        for field in universe.fields(type_name)
    })


# -------------------------------------------------------------------------------------------------
# Conversions between our messages, rosbags messages and plain content.

NUMPY_DTYPES = {
    # rosbags reads and writes 'byte' as a signed int8 and 'char' as uint8 (see ndtype in
    # rosbags.serde.utils and rosbags.serde.primitives); bool arrays are numpy.bool_.
    'bool': np.bool_, 'byte': np.int8, 'char': np.uint8, 'int8': np.int8, 'uint8': np.uint8,
    'int16': np.int16, 'uint16': np.uint16, 'int32': np.int32, 'uint32': np.uint32,
    'int64': np.int64, 'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64,
}


def _signed_byte(value: int) -> int:
    """Our ``byte`` (0..255, ROS 2 octet) as rosbags' signed representation (same bits)."""
    return value - 256 if value > 127 else value


def to_rosbags(universe: Universe, type_name: str, message) -> object:
    """The rosbags message with the content of our ``message``.

    Primitive arrays and sequences become numpy arrays of the dtype rosbags uses, strings stay
    ``str``, nested messages become rosbags dataclasses.
    """
    values = {}
    for field in universe.fields(type_name):
        value = getattr(message, field.name)
        if field.container is None:
            values[field.name] = _single_to_rosbags(universe, field, value)
        elif field.is_primitive:
            items = list(value)
            if field.base_type == 'byte':
                items = [_signed_byte(item) for item in items]
            values[field.name] = np.array(items, dtype=NUMPY_DTYPES[field.base_type])
        else:
            values[field.name] = [_single_to_rosbags(universe, field, item) for item in value]
    return universe.ts.types[type_name](**values)


def _single_to_rosbags(universe: Universe, field: FieldDef, value):
    """One element of ``field`` converted for rosbags."""
    if field.base_type == 'byte':
        return _signed_byte(value)
    if field.is_primitive or field.is_string:
        return value
    return to_rosbags(universe, field.base_type, value)


def from_rosbags(universe: Universe, type_name: str, message) -> object:
    """Our message with the content of the rosbags ``message`` (our documented representation)."""
    values = {}
    for field in universe.fields(type_name):
        value = getattr(message, field.name)
        if field.container is None:
            values[field.name] = _single_from_rosbags(universe, field, value)
        elif field.is_primitive:
            items = [_single_from_rosbags(universe, field, item) for item in value.tolist()]
            if field.base_type == 'uint8' and field.container == 'sequence':
                items = bytes(items)
            values[field.name] = items
        else:
            values[field.name] = [_single_from_rosbags(universe, field, item) for item in value]
    return universe.cls(type_name)(**values)


def _single_from_rosbags(universe: Universe, field: FieldDef, value):
    """One rosbags element of ``field`` in our representation."""
    base = field.base_type
    if base == 'byte':
        return int(value) & 0xFF
    if base == 'bool':
        return bool(value)
    if base in ('float32', 'float64'):
        return float(value)
    if field.is_primitive:
        return int(value)
    if field.is_string:
        return str(value)
    return from_rosbags(universe, base, value)


def plain(universe: Universe, type_name: str, message) -> tuple:
    """Content of our or a rosbags message as comparable Python values (see module docstring)."""
    return tuple(
        (field.name, _plain_field(universe, field, getattr(message, field.name)))
        for field in universe.fields(type_name)
    )


def _plain_field(universe: Universe, field: FieldDef, value):
    """Plain form of a field value."""
    if field.container is None:
        return _plain_single(universe, field, value)
    items = value.tolist() if isinstance(value, np.ndarray) else list(value)
    return [_plain_single(universe, field, item) for item in items]


def _plain_single(universe: Universe, field: FieldDef, value):
    """Plain form of one element."""
    base = field.base_type
    if base in ('float32', 'float64'):
        value = float(value)
        return 'nan' if math.isnan(value) else (value, math.copysign(1.0, value))
    if base == 'bool':
        return bool(value)
    if base == 'byte':
        return int(value) & 0xFF
    if field.is_primitive:
        return int(value)
    if field.is_string:
        return str(value)
    return plain(universe, base, value)


def check_representation(universe: Universe, type_name: str, message) -> None:
    """Assert that a message we deserialized uses the documented Python types."""
    assert type(message) is universe.cls(type_name)
    for field in universe.fields(type_name):
        value = getattr(message, field.name)
        where = f'{type_name}.{field.name}'
        if field.container is None:
            _check_single(universe, field, value, where)
        elif field.base_type == 'uint8' and field.container == 'sequence':
            assert type(value) is bytes, where
        else:
            assert type(value) is list, where
            if field.container == 'array':
                assert len(value) == field.size, where
            for item in value:
                _check_single(universe, field, item, where)


def _check_single(universe: Universe, field: FieldDef, value, where: str) -> None:
    """Assert the Python type of one element."""
    if field.base_type == 'bool':
        assert type(value) is bool, where
    elif field.base_type in ('float32', 'float64'):
        assert type(value) is float, where
    elif field.is_primitive:
        assert type(value) is int, where
    elif field.is_string:
        assert type(value) is str, where
    else:
        check_representation(universe, field.base_type, value)


def rosbags_desc(field: FieldDef) -> tuple:
    """Our field definition in rosbags' ``fielddefs`` notation."""
    if field.is_primitive or field.is_string:
        element = (Nodetype.BASE, (field.base_type, field.string_bound))
    else:
        element = (Nodetype.NAME, field.base_type)
    if field.container is None:
        return element
    kind = Nodetype.ARRAY if field.container == 'array' else Nodetype.SEQUENCE
    return (kind, (element, field.size))


def assert_conforms(universe: Universe, type_name: str, message) -> bytes:
    """Assert every comparison between our CDR code and rosbags' for one message.

    Returns:
        Our serialization of ``message``.
    """
    cls = universe.cls(type_name)
    expected = plain(universe, type_name, message)
    ours = message.serialize()
    rosbags_message = to_rosbags(universe, type_name, message)
    reference = bytes(universe.ts.serialize_cdr(rosbags_message, type_name, little_endian=True))
    assert type(ours) is bytes
    assert ours[:4] == b'\x00\x01\x00\x00'
    assert ours == reference, _first_difference(ours, reference)
    # rosbags' bytes -> ours.
    decoded = cls.deserialize(reference)
    check_representation(universe, type_name, decoded)
    assert plain(universe, type_name, decoded) == expected
    # Ours -> ours, content and bytes (the bytes keep NaN payloads and signs).
    again = cls.deserialize(ours)
    assert plain(universe, type_name, again) == expected
    assert again.serialize() == ours
    # Ours -> rosbags, and back to our representation.
    theirs = universe.ts.deserialize_cdr(ours, type_name)
    assert plain(universe, type_name, theirs) == expected
    converted = from_rosbags(universe, type_name, theirs)
    check_representation(universe, type_name, converted)
    assert converted.serialize() == ours
    return ours


def _first_difference(ours: bytes, reference: bytes) -> str:
    """Failure message locating the first differing byte."""
    index = next((i for i, (a, b) in enumerate(zip(ours, reference, strict=False)) if a != b),
                 min(len(ours), len(reference)))
    return (f'lengths {len(ours)} (ours) / {len(reference)} (rosbags); first difference at byte '
            f'{index}: ours {ours[index:index + 16].hex()} '
            f'rosbags {reference[index:index + 16].hex()}')


# -------------------------------------------------------------------------------------------------
# Tests.

RANDOM = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
# Long sequences of big elements overrun Hypothesis' buffer now and then; the discarded draws
# show up as 'filtering', which is not a problem with the strategy.
LONG = settings(max_examples=4, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.large_base_example,
                                       HealthCheck.filter_too_much])
FEW = settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def test_every_shipped_type_is_covered():
    """The shipped set is the one the tests iterate over, and rosbags knows every type."""
    assert len(TYPES) >= 30
    assert 'sensor_msgs/msg/JointState' in TYPES
    for type_name in TYPES:
        assert type_name in SHIPPED.ts.types, type_name


@pytest.mark.parametrize(('universe', 'type_name'), CASES, ids=CASE_IDS)
def test_definitions_match_rosbags(universe, type_name):
    """Field names, types, containers, bounds and constants equal rosbags' Jazzy definitions."""
    definition = universe.definition(type_name)
    consts, fields = universe.ts.fielddefs[type_name]
    assert [(f.name, rosbags_desc(f)) for f in definition.fields] == list(fields)
    assert [(c.name, c.type, c.value) for c in definition.constants] == list(consts)
    cls = universe.cls(type_name)
    for constant in definition.constants:
        value = getattr(cls, constant.name)
        assert value == constant.value and type(value) is type(constant.value)


@pytest.mark.parametrize(('universe', 'type_name'), CASES, ids=CASE_IDS)
@RANDOM
@given(data=st.data())
def test_random_content_matches_rosbags(universe, type_name, data):
    """Random content: same bytes as rosbags, and each side reads the other's bytes back."""
    message = data.draw(message_strategy(universe, type_name), label='message')
    assert_conforms(universe, type_name, message)


LONG_CASES = [(u, t, f.name) for u, t in CASES for f in u.fields(t)
              if f.container == 'sequence' and not f.size]


@pytest.mark.parametrize(('universe', 'type_name', 'field_name'), LONG_CASES,
                         ids=[f'{t}.{f}' for _, t, f in LONG_CASES])
@LONG
@given(data=st.data())
def test_long_sequences_match_rosbags(universe, type_name, field_name, data):
    """One top-level unbounded sequence with 100 to 300 elements (up to 12 big messages)."""
    message = data.draw(message_strategy(universe, type_name, field_name), label='message')
    ours = assert_conforms(universe, type_name, message)
    field = next(f for f in universe.fields(type_name) if f.name == field_name)
    length = len(getattr(message, field_name))
    if field.is_primitive or field.is_string or _is_flat(universe, field.base_type):
        assert LONG_MIN <= length <= LONG_MAX
    assert len(ours) >= 8 + length


@pytest.mark.parametrize(('universe', 'type_name'), CASES, ids=CASE_IDS)
@FEW
@given(data=st.data())
def test_big_endian_from_rosbags(universe, type_name, data):
    """Big-endian CDR (header ``00 00``) written by rosbags is read to the same content."""
    message = data.draw(message_strategy(universe, type_name), label='message')
    rosbags_message = to_rosbags(universe, type_name, message)
    big = bytes(universe.ts.serialize_cdr(rosbags_message, type_name, little_endian=False))
    assert big[:4] == b'\x00\x00\x00\x00'
    decoded = universe.cls(type_name).deserialize(big)
    check_representation(universe, type_name, decoded)
    assert plain(universe, type_name, decoded) == plain(universe, type_name, message)
    # Read from big endian, written (little endian) as rosbags writes the original content.
    little = bytes(universe.ts.serialize_cdr(rosbags_message, type_name, little_endian=True))
    assert decoded.serialize() == little


@pytest.mark.parametrize(('universe', 'type_name'), CASES, ids=CASE_IDS)
def test_defaults_are_the_ros_defaults(universe, type_name):
    """Default construction: ``.msg`` defaults, else zero or empty; containers not shared."""
    cls = universe.cls(type_name)
    message = cls()
    for field in universe.fields(type_name):
        value = getattr(message, field.name)
        if field.default is not None:
            expected = field.default
            if field.base_type == 'uint8' and field.container == 'sequence':
                expected = bytes(expected)
            assert value == expected and type(value) is type(expected), field.name
        elif field.container == 'array':
            assert len(value) == field.size
        elif field.container == 'sequence':
            assert len(value) == 0
        elif field.is_primitive:
            assert value == 0 and not math.copysign(1.0, value) < 0, field.name
        elif field.is_string:
            assert value == ''
        else:
            assert type(value) is universe.cls(field.base_type)
    check_representation(universe, type_name, message)
    assert_conforms(universe, type_name, message)
    other = cls()
    for field in universe.fields(type_name):
        if field.container is not None or not (field.is_primitive or field.is_string):
            assert getattr(other, field.name) is not getattr(message, field.name) or isinstance(
                getattr(message, field.name), bytes), f'{field.name} shared between instances'


def test_known_ros_defaults_and_constants():
    """A few values every ROS 2 user relies on."""
    quaternion = generated_class('geometry_msgs/msg/Quaternion')()
    assert (quaternion.x, quaternion.y, quaternion.z, quaternion.w) == (0.0, 0.0, 0.0, 1.0)
    data = quaternion.serialize()
    assert data == b'\x00\x01\x00\x00' + struct.pack('<4d', 0.0, 0.0, 0.0, 1.0)
    assert SHIPPED.ts.deserialize_cdr(data, 'geometry_msgs/msg/Quaternion').w == 1.0
    assert generated_class('geometry_msgs/msg/Pose')().orientation.w == 1.0
    marker = generated_class('visualization_msgs/msg/Marker')
    assert (marker.ARROW, marker.CUBE, marker.TEXT_VIEW_FACING) == (0, 1, 9)
    assert marker.ARROW_STRIP == 12
    assert (marker.ADD, marker.MODIFY, marker.DELETE, marker.DELETEALL) == (0, 0, 2, 3)
    assert marker().pose.orientation.w == 1.0
    status = generated_class('diagnostic_msgs/msg/DiagnosticStatus')
    assert (status.OK, status.WARN, status.ERROR, status.STALE) == (0, 1, 2, 3)
    assert status(level=status.ERROR).serialize()[4] == 2
    joint_state = generated_class('sensor_msgs/msg/JointState')
    first = joint_state()
    first.name.append('hip')
    assert joint_state().name == []
    everything = SYNTHETIC.cls('cdr_test_msgs/msg/Everything')
    assert (everything.NEG, everything.NAME, everything.PI, everything.FLAG, everything.BIG) == (
        -5, 'abc # not a comment', 3.14, True, 2**64 - 1)
    message = everything()
    assert (message.with_default, message.array_default, message.string_default) == (
        42, [1.5, -2.0], 'hi # not a comment')
    assert message.bool_default is True and message.seq_default == [-1, 2]
    assert message.bool_array == [False] * 3 and message.uint8_array == [0, 0, 0]
    assert message.uint8_seq == b'' and message.small_array[1].b == 0.0


@pytest.mark.parametrize(('universe', 'type_name'), CASES, ids=CASE_IDS)
@FEW
@given(data=st.data())
def test_truncated_data_raises(universe, type_name, data):
    """Every strict prefix of valid data (either byte order) is refused with a clear error."""
    message = data.draw(message_strategy(universe, type_name), label='message')
    cls = universe.cls(type_name)
    little = message.serialize()
    big = bytes(universe.ts.serialize_cdr(to_rosbags(universe, type_name, message), type_name,
                                          little_endian=False))
    for whole in (little, big):
        cls.deserialize(whole)
        for end in range(len(whole)):
            with pytest.raises(SerializationError, match=f'cannot deserialize {type_name}') as exc:
                cls.deserialize(whole[:end])
            text = str(exc.value)
            if end < 4:
                assert 'not plain CDR' in text
            else:
                assert f'{end} bytes' in text or f'data ends at byte {end}' in text, text


@pytest.mark.parametrize('type_name', TYPES)
@pytest.mark.parametrize('header', [
    b'\x00\x02\x00\x00', b'\x00\x03\x00\x00', b'\x00\x06\x00\x00', b'\x00\x07\x00\x00',
    b'\x01\x01\x00\x00', b'\x01\x00\x00\x00', b'\xff\xff\xff\xff',
], ids=lambda header: header.hex())
def test_wrong_header_raises(type_name, header):
    """Only plain CDR headers (``00 00`` / ``00 01``) are accepted; the error shows the header."""
    cls = generated_class(type_name)
    body = cls().serialize()[4:]
    with pytest.raises(SerializationError, match=f'{type_name}: not plain CDR') as info:
        cls.deserialize(header + body)
    assert header.hex() in str(info.value)


@pytest.mark.parametrize('data', [b'', b'\x00', b'\x00\x01', b'\x00\x01\x00'])
def test_missing_header_raises(data):
    """Data shorter than the 4-byte encapsulation header is refused."""
    cls = generated_class('std_msgs/msg/Header')
    with pytest.raises(SerializationError, match='std_msgs/msg/Header: not plain CDR') as info:
        cls.deserialize(data)
    assert (data.hex() or 'missing') in str(info.value)


def test_malformed_content_raises():
    """A corrupt count, length or encoding in the body is reported, never a bare exception."""
    joint_state = generated_class('sensor_msgs/msg/JointState')
    data = bytearray(joint_state(name=['a'], position=[1.0]).serialize())
    huge = data[:]
    struct.pack_into('<I', huge, 20, 0xFFFFFFFF)  # name count: after stamp, frame_id and padding
    with pytest.raises(SerializationError, match='cannot deserialize sensor_msgs/msg/JointState'):
        joint_state.deserialize(bytes(huge))
    string = generated_class('std_msgs/msg/String')
    with pytest.raises(SerializationError, match='std_msgs/msg/String'):
        string.deserialize(b'\x00\x01\x00\x00' + struct.pack('<I', 3) + b'\xff\xfe\x00')
    with pytest.raises(SerializationError, match='std_msgs/msg/String'):
        string.deserialize(b'\x00\x01\x00\x00' + struct.pack('<I', 0x7FFFFFFF) + b'ab\x00')
    image = generated_class('sensor_msgs/msg/CompressedImage')
    data = bytearray(image(data=b'\x01\x02').serialize())
    struct.pack_into('<I', data, len(data) - 6, 3)
    with pytest.raises(SerializationError, match='message needs'):
        image.deserialize(bytes(data))


def test_string_sequences_sent_again_or_changed_match_rosbags():
    """Sequences of strings are encoded once per content, and stay right.

    A name list sent again (the same or an equal list), edited in place, or at another
    alignment still gives rosbags' bytes.
    """
    joint_state = generated_class('sensor_msgs/msg/JointState')
    names = [f'joint_{k}' * (1 + k % 3) for k in range(7)]
    first = assert_conforms(SHIPPED, 'sensor_msgs/msg/JointState',
                            joint_state(name=names, position=[0.5] * 7))
    assert joint_state(name=list(names), position=[0.5] * 7).serialize() == first
    for edit in (lambda: names.append('x'), lambda: names.__setitem__(0, 'other_joint'),
                 lambda: names.__setitem__(slice(None), []), lambda: names.append('é\u00fc')):
        edit()
        for frame_id in ('', 'a', 'ab', 'abc'):  # every alignment of the sequence's count
            message = joint_state(name=names, position=[1.5] * len(names))
            message.header.frame_id = frame_id
            assert_conforms(SHIPPED, 'sensor_msgs/msg/JointState', message)
    with pytest.raises(SerializationError, match='JointState'):
        joint_state(name=['a', 3]).serialize()


EVERYTHING = 'cdr_test_msgs/msg/Everything'


@pytest.mark.parametrize(('field', 'value', 'match'), [
    ('float64_array', [1.0, 2.0], 'float64_array must have exactly 3 elements, got 2'),
    ('float64_array', [1.0] * 4, 'float64_array must have exactly 3 elements, got 4'),
    ('bool_array', [], 'bool_array must have exactly 3 elements, got 0'),
    ('uint8_array', [1, 2, 3, 4], 'uint8_array must have exactly 3 elements, got 4'),
    ('char_array', [1], 'char_array must have exactly 3 elements'),
    ('s_array', ['a', 'b', 'c'], 's_array must have exactly 2 elements, got 3'),
    ('small_array', [], 'small_array must have exactly 2 elements, got 0'),
    ('u8_tail', [0] * 5, 'u8_tail must have exactly 4 elements, got 5'),
])
def test_wrong_fixed_array_length_raises(field, value, match):
    """A fixed array must have exactly its size."""
    message = SYNTHETIC.cls(EVERYTHING)(**{field: value})
    with pytest.raises(SerializationError, match=f'cannot serialize {EVERYTHING}: {match}'):
        message.serialize()


@pytest.mark.parametrize(('field', 'too_long', 'at_bound', 'match'), [
    ('int32_bseq', [1, 2, 3, 4], [1, 2, 3], 'int32_bseq has 4 elements, at most 3 allowed'),
    ('uint8_bseq', b'\x00' * 4, b'\xff' * 3, 'uint8_bseq has 4 elements, at most 3 allowed'),
    ('bool_bseq', [True] * 10, [True] * 3, 'bool_bseq has 10 elements, at most 3 allowed'),
    ('small_bseq', [None] * 3, [None] * 2, 'small_bseq has 3 elements, at most 2 allowed'),
    ('s_bseq', ['a', 'b', 'c'], ['a', 'b'], 's_bseq has 3 elements, at most 2 allowed'),
    ('s_bseq', ['abcd'], ['abc', ''], 'string longer than bound 3'),
    ('s_bounded', 'abcdef', 'abcde', 'string longer than bound 5'),
])
def test_beyond_bound_raises(field, too_long, at_bound, match):
    """A bounded sequence or string longer than its bound is refused; at the bound it is not."""
    cls = SYNTHETIC.cls(EVERYTHING)
    if field == 'small_bseq':
        small = SYNTHETIC.cls('cdr_test_msgs/msg/Small')
        too_long, at_bound = [small() for _ in too_long], [small(a=7) for _ in at_bound]
    with pytest.raises(SerializationError, match=f'cannot serialize {EVERYTHING}: {match}'):
        cls(**{field: too_long}).serialize()
    assert_conforms(SYNTHETIC, EVERYTHING, cls(**{field: at_bound}))


@pytest.mark.parametrize(('type_name', 'values'), [
    ('builtin_interfaces/msg/Time', {'sec': 2**31}),
    ('builtin_interfaces/msg/Time', {'nanosec': -1}),
    ('builtin_interfaces/msg/Time', {'sec': 1.5}),
    ('geometry_msgs/msg/Point32', {'x': 1e39}),
    ('geometry_msgs/msg/Point32', {'y': -sys.float_info.max}),
    ('geometry_msgs/msg/Point', {'z': 'one'}),
    ('sensor_msgs/msg/JointState', {'position': [1e39, 'a']}),
    ('sensor_msgs/msg/JointState', {'name': [None]}),
    ('sensor_msgs/msg/CompressedImage', {'data': [256]}),
    ('diagnostic_msgs/msg/DiagnosticStatus', {'level': 256}),
    ('std_msgs/msg/String', {'data': '\ud800'}),
])
def test_out_of_range_content_raises(type_name, values):
    """Values that do not fit the field type raise SerializationError, not a bare exception."""
    cls = generated_class(type_name)
    with pytest.raises(SerializationError, match=f'cannot serialize {type_name}: '):
        cls(**values).serialize()


def test_float32_limits_are_accepted():
    """The largest finite float32 and the smallest subnormal serialize exactly (no overflow)."""
    point = generated_class('geometry_msgs/msg/Point32')
    message = point(x=F32_MAX, y=-F32_MAX, z=F32_MIN_SUBNORMAL)
    data = assert_conforms(SHIPPED, 'geometry_msgs/msg/Point32', message)
    assert data[4:] == b'\xff\xff\x7f\x7f\xff\xff\x7f\xff\x01\x00\x00\x00'


# -------------------------------------------------------------------------------------------------
# Runs of container-free structs packed at once (RecordRun): every string layout they meet.

#: (universe, message type, field): a sequence or array of container-free structs.
RECORD_RUNS = [
    (SHIPPED, 'nav_msgs/msg/Path', 'poses'),
    (SHIPPED, 'tf2_msgs/msg/TFMessage', 'transforms'),
    (SHIPPED, 'diagnostic_msgs/msg/DiagnosticStatus', 'values'),
    (SYNTHETIC, 'cdr_test_msgs/msg/Records', 'records'),
    (SYNTHETIC, 'cdr_test_msgs/msg/Records', 'record_array'),
    (SYNTHETIC, 'cdr_test_msgs/msg/Records', 'bounded'),
]
#: Characters of 1 to 4 bytes in UTF-8, to make strings of one byte length but other contents.
PIECES = ['a', 'Z', '\u00e9', '\u20ac', '\U0001f600']
#: How the values of one string field vary across the elements of a run.
STRING_MODES = ['same object', 'equal copies', 'same byte length', 'free']


def _string_paths(universe: Universe, type_name: str) -> list[tuple[tuple[str, ...], int]]:
    """Attribute paths and bounds of every string field of a container-free struct."""
    paths = []
    for field in universe.fields(type_name):
        if field.is_string:
            paths.append(((field.name,), field.string_bound))
        elif not field.is_primitive:
            paths += [((field.name, *path), bound)
                      for path, bound in _string_paths(universe, field.base_type)]
    return paths


def _set_path(message, path: tuple[str, ...], value) -> None:
    for name in path[:-1]:
        message = getattr(message, name)
    setattr(message, path[-1], value)


def _string_of_bytes(data, length: int) -> str:
    """A string of ``length`` UTF-8 bytes made of random 1- to 4-byte characters."""
    text, left = '', length
    while left:
        piece = data.draw(st.sampled_from([p for p in PIECES if len(p.encode()) <= left]))
        text += piece
        left -= len(piece.encode())
    return text


def draw_record_run(data, universe: Universe, type_name: str, field: FieldDef) -> list:
    """Elements for ``field`` whose string fields are each drawn in one of STRING_MODES."""
    element_type = field.base_type
    if field.container == 'array':
        count = field.size
    else:
        count = data.draw(st.integers(0, field.size or 40), label='count')
    elements = [data.draw(message_strategy(universe, element_type)) for _ in range(count)]
    for path, bound in _string_paths(universe, element_type):
        mode = data.draw(st.sampled_from(STRING_MODES), label=f'{".".join(path)} mode')
        length = data.draw(st.integers(0, bound or 9), label='bytes')
        if mode == 'free':
            continue
        first = _string_of_bytes(data, length)
        for element in elements:
            if mode == 'same object':
                value = first
            elif mode == 'equal copies':
                value = ''.join(list(first))
            else:
                value = _string_of_bytes(data, length)
            _set_path(element, path, value)
    return elements


@contextlib.contextmanager
def record_runs_watched(cls: type):
    """Within: what the RecordRun calls of ``cls``'s serializer did (True: packed at once)."""
    serialize_fn = next(cell.cell_contents for cell in cls.serialize.__closure__
                        if hasattr(cell.cell_contents, '__source__'))
    namespace = serialize_fn.__globals__
    runs = {name: value for name, value in namespace.items() if name.startswith('RUN')}
    results = []

    def watched(run):
        def call(*args):
            data = run(*args)
            results.append(data is not None)
            return data

        return call

    namespace.update({name: watched(run) for name, run in runs.items()})
    try:
        yield results
    finally:
        namespace.update(runs)


@pytest.mark.parametrize(('universe', 'type_name', 'field_name'), RECORD_RUNS,
                         ids=[f'{t}.{f}' for _, t, f in RECORD_RUNS])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_record_runs_match_rosbags(universe, type_name, field_name, data):
    """Runs of container-free structs give rosbags' bytes in every string layout.

    Each string field of the elements is one object in all, equal copies, strings of one byte
    length but different contents (multi-byte characters), or free; every start alignment
    (random content before the run), empty runs, runs below the packed-at-once size.
    """
    field = next(f for f in universe.fields(type_name) if f.name == field_name)
    message = data.draw(message_strategy(universe, type_name), label='message')
    setattr(message, field_name, draw_record_run(data, universe, type_name, field))
    assert_conforms(universe, type_name, message)


def test_record_runs_are_packed_at_once_when_strings_agree():
    """The one-pack path is taken when it should be, and falls back when lengths differ."""
    path_type = generated_class('nav_msgs/msg/Path')
    pose = generated_class('geometry_msgs/msg/PoseStamped')
    with record_runs_watched(path_type) as packed:
        for frame in ('', 'a', 'odom', 'world', 'map_frame'):
            for count in (3, 4, 5, 201):
                poses = [pose() for _ in range(count)]
                for k, element in enumerate(poses):
                    element.header.frame_id = frame
                    element.header.stamp.sec = k
                    element.pose.position.x = 0.1 * k
                message = path_type(poses=poses)
                for header_frame in ('', 'a', 'ab', 'abc'):
                    message.header.frame_id = header_frame
                    assert_conforms(SHIPPED, 'nav_msgs/msg/Path', message)
        assert packed and all(packed)
        packed.clear()
        poses = [pose() for _ in range(6)]
        poses[3].header.frame_id = 'longer'
        assert_conforms(SHIPPED, 'nav_msgs/msg/Path', path_type(poses=poses))
        assert packed and not any(packed)


def test_nested_record_runs_match_rosbags():
    """Runs inside the elements of a sequence (DiagnosticArray.status[k].values)."""
    array = generated_class('diagnostic_msgs/msg/DiagnosticArray')
    status = generated_class('diagnostic_msgs/msg/DiagnosticStatus')
    key_value = generated_class('diagnostic_msgs/msg/KeyValue')
    statuses = []
    for k in range(6):
        values = [key_value(key=f'k{k}', value=str(j % 10)) for j in range(k * 3)]
        statuses.append(status(level=k % 3, name='n' * k, message='m' * (5 - k), values=values))
    for frame in ('', 'a', 'ab', 'abc'):
        message = array(status=statuses)
        message.header.frame_id = frame
        assert_conforms(SHIPPED, 'diagnostic_msgs/msg/DiagnosticArray', message)


@pytest.mark.parametrize('uniform', [True, False])
def test_record_runs_refuse_strings_beyond_bound(uniform):
    """A bounded string too long in a run raises as element by element packing does."""
    records = SYNTHETIC.cls('cdr_test_msgs/msg/Records')
    record = SYNTHETIC.cls('cdr_test_msgs/msg/Record')
    elements = [record(tag='abcd' if uniform or k % 2 else 'ab') for k in range(6)]
    assert_conforms(SYNTHETIC, 'cdr_test_msgs/msg/Records', records(bounded=elements))
    elements[4].tag = 'abcde'
    if uniform:
        for element in elements:
            element.tag = 'abcde'
    with pytest.raises(SerializationError, match='string longer than bound 4'):
        records(bounded=elements).serialize()


def test_get_constructor_is_looked_up_again_when_the_runtime_changes(monkeypatch):
    """get_constructor keeps what it found per name, for the runtime selected at the time."""
    from gait_nodes import interfaces
    from gait_nodes.runtime import selection

    vector_class = generated_class('geometry_msgs/msg/Vector3')
    monkeypatch.setattr(selection, '_selected', 'inproc')
    vector = interfaces.get_constructor('geometry_msgs/msg/Vector3')
    assert vector(1.0, 2.0, 3.0) == vector_class(x=1.0, y=2.0, z=3.0)
    assert interfaces.get_constructor('geometry_msgs/Vector3') is vector
    resolved = []

    def resolve(type_name, rclpy_active):
        resolved.append((type_name, rclpy_active))
        return generated_class(type_name)

    monkeypatch.setattr(interfaces, '_resolve_message', resolve)
    assert interfaces.get_constructor('geometry_msgs/msg/Vector3') is vector
    assert resolved == []
    monkeypatch.setattr(selection, '_selected', 'dds')
    assert interfaces.get_constructor('geometry_msgs/msg/Vector3') is vector
    assert interfaces.get_constructor('geometry_msgs/msg/Vector3') is vector
    assert resolved == [('geometry_msgs/msg/Vector3', False)]


def test_published_sequences_are_packed_once_and_stay_right():
    """serialize_published gives serialize's bytes when it copies a sequence met before.

    The same vertex list in successive messages and twice in one message (at another
    alignment), equal but new lists, more lists than are remembered, short lists, and lists
    freed and made again (ids reused). serialize() never uses what serialize_published kept: a
    list edited after it (as a DDS publisher may do) is packed anew.
    """
    polygon_stamped = generated_class('geometry_msgs/msg/PolygonStamped')
    polygon = generated_class('geometry_msgs/msg/Polygon')
    point32 = generated_class('geometry_msgs/msg/Point32')
    marker_array = generated_class('visualization_msgs/msg/MarkerArray')
    marker = generated_class('visualization_msgs/msg/Marker')
    point = generated_class('geometry_msgs/msg/Point')
    vertices = [point32(x=float(k), y=-k / 4, z=0.5) for k in range(12)]  # exact in float32
    outline = [point(x=k / 7, y=float(k), z=-1.0) for k in range(9)]
    for frame in ('', 'a', 'ab', 'abc', 'abcd'):
        message = polygon_stamped(polygon=polygon(points=vertices))
        message.header.frame_id = frame
        data = assert_conforms(SHIPPED, 'geometry_msgs/msg/PolygonStamped', message)
        assert message.serialize_published() == data
        markers = marker_array(markers=[marker(ns=frame, points=outline),
                                        marker(ns=frame + 'x', text='t', points=outline)])
        data = assert_conforms(SHIPPED, 'visualization_msgs/msg/MarkerArray', markers)
        assert markers.serialize_published() == data
    rng = random.Random(5)
    for size in [3, 7, 8, 9, 30] * 6:  # fresh lists, freed after use
        points = [point32(x=rng.randint(-99, 99) / 8, y=rng.randint(-99, 99) / 16, z=0.0)
                  for _ in range(size)]
        message = polygon_stamped(polygon=polygon(points=points))
        assert message.serialize_published() == message.serialize()
        assert polygon_stamped(polygon=polygon(points=list(points))).serialize_published() == \
            message.serialize()
        del points, message
    message = polygon_stamped(polygon=polygon(points=vertices))
    published = message.serialize_published()
    vertices[3].x = 42.0
    assert message.serialize() != published
    assert_conforms(SHIPPED, 'geometry_msgs/msg/PolygonStamped', message)



def _run_of(cls: type):
    """The (one) RecordRun of ``cls``'s serializer."""
    serialize_fn = next(cell.cell_contents for cell in cls.serialize.__closure__
                        if hasattr(cell.cell_contents, '__source__'))
    [run] = [value for name, value in serialize_fn.__globals__.items() if name.startswith('RUN')]
    return run


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(steps=st.lists(st.tuples(st.integers(-3, 12), st.sampled_from(['', 'a', 'odom', 'world']),
                                st.sampled_from(['odom', 'odom', 'map', 'world', 'mapx']),
                                st.integers(0, 3)), min_size=1, max_size=12))
def test_published_zmp_reference_windows_match_serialize(steps):
    """A Path sliding along one list of poses, as the footstep planner publishes it.

    Each published message's leading poses are (``is``) a stretch of the previous one's; its
    bytes are serialize()'s whatever the shift (none, ahead, back, past the end), the header
    frame (the run's alignment), the frame of the new poses (another length: no one layout),
    and messages of another publisher in between.
    """
    path_type = generated_class('nav_msgs/msg/Path')
    pose = generated_class('geometry_msgs/msg/PoseStamped')

    def new_pose(k: int, frame: str):
        element = pose()
        element.header.frame_id = frame
        element.header.stamp.sec = k
        element.pose.position.x, element.pose.orientation.z = k / 8, -k / 3
        return element

    poses = [new_pose(k, 'odom') for k in range(40)]
    other = [new_pose(-k, 'odom') for k in range(12)]
    start = 0
    for shift, header_frame, tail_frame, others in steps:
        start = max(start + shift, 0)
        window = poses[start:start + 20]
        window += [new_pose(100 + k, tail_frame) for k in range(20 - len(window))]
        for message_poses in [other[:6 + others]] * (others > 1) + [window]:
            message = path_type(poses=message_poses)
            message.header.frame_id = header_frame
            assert message.serialize_published() == message.serialize()


def test_published_zmp_reference_packs_only_its_new_poses():
    """Sliding by 4 poses: 4 are gathered and packed, the other 196 copied."""
    path_type = generated_class('nav_msgs/msg/Path')
    pose = generated_class('geometry_msgs/msg/PoseStamped')
    run = _run_of(path_type)
    gather = run.gather
    gathered = []
    poses = [pose() for _ in range(240)]
    for k, element in enumerate(poses):
        element.header.frame_id = 'odom'
        element.header.stamp.sec = k
    try:
        run.gather = lambda elements: gathered.append(len(elements)) or gather(elements)
        for start in range(0, 40, 4):
            message = path_type(poses=poses[start:start + 200])
            message.header.frame_id = 'odom'
            assert message.serialize_published() == message.serialize()
    finally:
        run.gather = gather
    # serialize() gathers all 200 each time; the first published message too.
    assert gathered[0::2] == [200] + [4] * 9 and gathered[1::2] == [200] * 10


def test_primitive_sequences_of_every_length_match_rosbags_beyond_the_struct_cache():
    """Primitive sequences of 0 to 2.5x SequenceStructs.KEPT elements: rosbags' bytes.

    The cache forgets its Structs twice on the way; both ways, big endian read too, bad values
    refused as before.
    """
    from gait_nodes.interfaces.generate import SequenceStructs

    rng = random.Random(7)
    type_name = 'sensor_msgs/msg/JointState'
    lengths = list(range(int(2.5 * SequenceStructs.KEPT)))
    rng.shuffle(lengths)
    cls = SHIPPED.cls(type_name)
    for n in lengths:
        message = cls(name=[f'j{k}' for k in range(n)],
                      position=[rng.uniform(-1e3, 1e3) for _ in range(n)],
                      velocity=[rng.choice([math.inf, -0.0, 1e-300, 2.5]) for _ in range(n)],
                      effort=[float(k) for k in range(n % 7)])
        assert_conforms(SHIPPED, type_name, message)
        big = bytes(SHIPPED.ts.serialize_cdr(to_rosbags(SHIPPED, type_name, message),
                                             type_name, little_endian=False))
        assert cls.deserialize(big).position == message.position
    assert len(SequenceStructs.of('<d')) <= SequenceStructs.KEPT
    with pytest.raises(SerializationError):
        cls(name=['a'], position=['x']).serialize()
    with pytest.raises(SerializationError):
        cls.deserialize(cls(name=['a'], position=[1.0] * 9).serialize()[:-8])
