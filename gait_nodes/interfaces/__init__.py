"""ROS 2 message classes, with or without ROS.

``get_message('sensor_msgs/msg/JointState')`` returns the class to use in this process: the real
rclpy class when the ``rclpy`` runtime is active, otherwise the class generated from the Jazzy
definitions in ``msgs_schema/``. Package attributes mirror the ROS import style::

    from gait_nodes.interfaces import sensor_msgs
    msg = sensor_msgs.msg.JointState(name=['hip'], position=[0.1])

``serialize_message`` / ``deserialize_message`` have the signatures of ``rclpy.serialization``.
"""

from __future__ import annotations

import itertools
import threading

from gait_nodes.errors import InterfaceError
from gait_nodes.interfaces.msgdef import FieldDef, MsgDef, available_types, load_msg

__all__ = [
    'available_types', 'definition_text', 'deserialize_message', 'get_constructor', 'get_message',
    'is_message', 'message_type_name', 'msgdef', 'raw_twins', 'serialize_message', 'type_hash',
    'validate_message',
]

_lock = threading.RLock()
_definitions: dict[str, MsgDef] = {}
_classes: dict[str, type] = {}

SCHEMA_SEPARATOR = '=' * 80


def msgdef(type_name: str) -> MsgDef:
    """Parsed definition of ``pkg/msg/Name``."""
    with _lock:
        definition = _definitions.get(type_name)
        if definition is None:
            definition = _definitions[type_name] = load_msg(type_name)
        return definition


def _closure(type_name: str) -> list[str]:
    """``type_name`` and its dependencies, dependencies first, each once."""
    order: list[str] = []

    def visit(name: str, path: tuple[str, ...]) -> None:
        if name in order:
            return
        if name in path:
            raise InterfaceError(f'recursive message definition: {" -> ".join(path + (name,))}')
        for dependency in msgdef(name).dependencies:
            visit(dependency, path + (name,))
        order.append(name)

    visit(type_name, ())
    return order


def generated_class(type_name: str) -> type:
    """The class generated from the shipped definition (never the rclpy one)."""
    with _lock:
        cls = _classes.get(type_name)
        if cls is not None:
            return cls
        from gait_nodes.interfaces.generate import make_class

        for name in _closure(type_name):
            if name not in _classes:
                make_class(msgdef(name), _definitions, _classes)
        return _classes[type_name]


#: Classes already looked up, by the name as asked, for the runtime in ``_resolved_runtime``
#: (node code calls get_message per message built: the lookup must cost a dict access).
_resolved: dict[str, type] = {}
_resolved_runtime: list = [None]
_selection = []
#: Constructors already looked up, by the name as asked, for the runtime in ``_resolved_runtime``
#: (node code calls get_constructor for each message it builds, ~20 times per graph tick).
_constructors_by_name: dict[str, object] = {}


def get_message(type_name: str) -> type:
    """Message class for ``pkg/msg/Name`` (also accepts ``pkg/Name``) in the active runtime."""
    if not _selection:
        from gait_nodes.runtime import selection

        _selection.append(selection)
    runtime = _selection[0].active_runtime()
    if runtime is _resolved_runtime[0]:
        cls = _resolved.get(type_name)
        if cls is not None:
            return cls
    else:
        _resolved.clear()
        _constructors_by_name.clear()
        _resolved_runtime[0] = runtime
    cls = _resolve_message(type_name, runtime == 'rclpy')
    _resolved[type_name] = cls
    return cls


_constructors: dict[type, object] = {}


def get_constructor(type_name: str):
    """Callable building a ``type_name`` message from all its fields given positionally.

    The fields come in the order of the ``.msg`` definition. This is the fast way to build many
    messages: the generated class itself (a dataclass), or for rclpy's classes (keyword
    arguments only) a wrapper passing the fields by name.
    """
    runtime = _resolved_runtime[0]
    if runtime is not None and _selection[0]._selected is runtime:
        constructor = _constructors_by_name.get(type_name)
        if constructor is not None:
            return constructor
    cls = get_message(type_name)  # (re)sets _resolved_runtime, clears _constructors_by_name
    constructor = _constructors.get(cls)
    if constructor is None:
        if hasattr(cls, '__ros_type__'):
            constructor = cls
        else:
            names = tuple(cls.get_fields_and_field_types())

            def constructor(*values, _cls=cls, _names=names):
                return _cls(**dict(zip(_names, values, strict=True)))

        _constructors[cls] = constructor
    _constructors_by_name[type_name] = constructor
    return constructor


def _resolve_message(type_name: str, rclpy_active: bool) -> type:
    parts = type_name.split('/')
    if len(parts) == 2:
        type_name = f'{parts[0]}/msg/{parts[1]}'
    if rclpy_active:
        import importlib

        package, _, name = type_name.split('/')
        try:
            return getattr(importlib.import_module(f'{package}.msg'), name)
        except (ImportError, AttributeError) as exc:
            raise InterfaceError(f'message type {type_name!r} not found in ROS: {exc}') from exc
    return generated_class(type_name)


class RawSample:
    """CDR bytes of one message as DDS delivered them (encapsulation header, padding)."""

    __slots__ = ('data', 'sample_info')

    def __init__(self, data: bytes):
        self.data = bytes(data)
        self.sample_info = None


#: (reader twin, writer twin) of each generated class, by class.
_raw_twins: dict[type, tuple[type, type]] = {}


def raw_twins(cls: type) -> tuple[type, type]:
    """Two classes of ``cls``'s DDS type for moving CDR bytes without decoding them.

    The first is a class generated anew from the same definition (the same DDS type) whose
    ``deserialize`` keeps the bytes (a :class:`RawSample`): a Cyclone DataReader on a Topic of
    it hands them over through its public ``take``. The second is a subclass of ``cls`` whose
    instances (made by ``of(data)``) ``serialize`` to the bytes they hold, which a DataWriter
    of ``cls`` writes through its public ``write``.
    """
    with _lock:
        twins = _raw_twins.get(cls)
        if twins is not None:
            return twins
        from gait_nodes.interfaces.generate import make_class

        type_name = cls.__ros_type__
        classes = {name: value for name, value in _classes.items() if name != type_name}
        reader_twin = make_class(msgdef(type_name), _definitions, classes)

        def keep_bytes(_cls, data, has_header=True, use_version_2=None) -> RawSample:
            return RawSample(data)

        reader_twin.deserialize = classmethod(keep_bytes)

        class RawMessage(cls):
            """A message given as its CDR bytes."""

            @classmethod
            def of(cls_, data: bytes):
                message = cls_.__new__(cls_)
                message.__dict__['cdr'] = bytes(data)
                return message

            def serialize(self, buffer=None, endianness=None, use_version_2=None) -> bytes:
                return self.__dict__['cdr']

        twins = _raw_twins[cls] = (reader_twin, RawMessage)
        return twins


def is_message(obj: object) -> bool:
    """Whether ``obj`` is an instance of a ROS message class (ours or rclpy's)."""
    cls = type(obj)
    return hasattr(cls, '__ros_type__') or hasattr(cls, '_TYPE_SUPPORT')


def message_type_name(msg_or_cls) -> str:
    """``pkg/msg/Name`` of a message class or instance (ours or rclpy's)."""
    cls = msg_or_cls if isinstance(msg_or_cls, type) else type(msg_or_cls)
    name = getattr(cls, '__ros_type__', None)
    if name:
        return name
    module = getattr(cls, '__module__', '')
    package = module.split('.')[0]
    if '.msg' in module and hasattr(cls, '_TYPE_SUPPORT'):
        return f'{package}/msg/{cls.__name__}'
    raise InterfaceError(f'{cls!r} is not a ROS message class')


def serialize_message(message) -> bytes:
    """CDR bytes (with encapsulation header) of ``message``, as rclpy.serialization does."""
    if hasattr(type(message), '__ros_type__'):
        return message.serialize()
    from rclpy.serialization import serialize_message as rclpy_serialize

    return rclpy_serialize(message)


def deserialize_message(serialized_message: bytes, message_type: type):
    """Message of class ``message_type`` from CDR bytes, as rclpy.serialization does."""
    if hasattr(message_type, '__ros_type__'):
        return message_type.deserialize(serialized_message)
    from rclpy.serialization import deserialize_message as rclpy_deserialize

    return rclpy_deserialize(serialized_message, message_type)


def definition_text(type_name: str) -> str:
    """Full ``ros2msg`` schema: the definition, then each dependency after a separator line.

    This is the text rosbag2 stores in MCAP schemas and ``ros2 bag`` / Foxglove parse.
    """
    parts = [msgdef(type_name).text.rstrip('\n')]
    for dependency in reversed(_closure(type_name)[:-1]):
        package, _, name = dependency.split('/')
        parts.append(f'{SCHEMA_SEPARATOR}\nMSG: {package}/{name}\n'
                     f'{msgdef(dependency).text.rstrip(chr(10))}')
    return '\n'.join(parts) + '\n'


def type_hash(type_name: str) -> str:
    """ROS 2 type hash ``RIHS01_<sha256>`` of a message type (as Jazzy computes it)."""
    from rosbags.typesys import Stores, get_typestore

    global _typestore
    with _lock:
        if _typestore is None:
            _typestore = get_typestore(Stores.ROS2_JAZZY)
        return _typestore.hash_rihs01(type_name)


_typestore = None


class _MsgNamespace:
    def __init__(self, package: str):
        self._package = package

    def __getattr__(self, name: str) -> type:
        if name.startswith('_'):
            raise AttributeError(name)
        return get_message(f'{self._package}/msg/{name}')

    def __repr__(self) -> str:
        return f'<messages of {self._package}>'


class _Package:
    def __init__(self, package: str):
        self.msg = _MsgNamespace(package)


def __getattr__(name: str) -> _Package:
    if name.endswith('_msgs') or name in ('builtin_interfaces',):
        return _Package(name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


_INT_RANGES = {
    'byte': (0, 255), 'char': (0, 255), 'int8': (-128, 127), 'uint8': (0, 255),
    'int16': (-(1 << 15), (1 << 15) - 1), 'uint16': (0, (1 << 16) - 1),
    'int32': (-(1 << 31), (1 << 31) - 1), 'uint32': (0, (1 << 32) - 1),
    'int64': (-(1 << 63), (1 << 63) - 1), 'uint64': (0, (1 << 64) - 1),
}


def _check_scalar(base_type: str, value, where: str) -> None:
    import numbers

    if base_type in ('float32', 'float64'):
        ok = isinstance(value, float) or (isinstance(value, numbers.Real)
                                          and not isinstance(value, (bool, numbers.Integral)))
        expected = 'float'
    elif base_type == 'bool':
        ok, expected = isinstance(value, bool), 'bool'
    elif base_type in _INT_RANGES:
        low, high = _INT_RANGES[base_type]
        ok = (isinstance(value, numbers.Integral) and not isinstance(value, bool)
              and low <= value <= high)
        expected = f'int in [{low}, {high}]'
    elif base_type in ('string', 'wstring'):
        ok, expected = isinstance(value, str), 'str'
    else:
        cls = generated_class(base_type)
        if not isinstance(value, cls):
            raise InterfaceError(f'{where} must be a {base_type}, got {type(value).__name__}')
        validate_message(value, where)
        return
    if not ok:
        raise InterfaceError(f'{where} must be {expected} ({base_type}), got {value!r}')


def validate_message(msg, where: str | None = None) -> None:
    """Check every field the way rclpy's message setters do (types, ranges, array sizes).

    Our generated classes accept any value and only fail when serialized; rclpy refuses a wrong
    type at assignment (``msg.x = 1`` into a float64 fails). Tests run with this check on every
    inproc publish (``GAIT_NODES_STRICT_MESSAGES=1``) so that node code working here also works
    on a real ROS 2 install.

    A message whose every value has its field's plain Python type (``float``, ``int`` in range,
    ``str``, ``bool``, the exact message class; lists and tuples of them) passes a quick check;
    any other is checked field by field, value by value, which names the first wrong one.

    Raises:
        InterfaceError: Naming the field path, the expected type and the value.
    """
    cls = type(msg)
    quick = _quick_checks.get(cls)
    if quick is None:
        quick = _quick_check_of(cls)
    if not quick(msg):
        _validate_fields(msg, where)


#: The quick check of each message class (see :func:`validate_message`).
_quick_checks: dict[type, object] = {}

#: The Python type a value of each non-integer primitive has in the quick check.
_PLAIN_TYPES = {'float32': 'float', 'float64': 'float', 'bool': 'bool', 'string': 'str',
                'wstring': 'str'}


def _quick_check_of(cls: type):
    """``check(msg) -> bool``: True only if every field of ``msg`` would pass the full check.

    The check is compiled once per class into straight-line code (as the CDR functions of
    :mod:`gait_nodes.interfaces.generate` are), its nested messages inlined: one ``type(value)
    is ...`` test per value, a loop per sequence of messages, and one pass in C over a sequence
    of primitives (``list(map(type, values)).count(float)``, ``min``/``max`` for an integer
    range). A message thus costs no Python call per nested message or per element: inproc
    checks every message published in the tests.
    """
    source = _QuickCheckSource()
    source.fields(cls.__msgdef__, 'm', 1)
    text = '\n'.join(['def check(m):', *source.lines, '    return True'])
    namespace = dict(source.constants)
    exec(compile(text, f'<quick check {cls.__msgdef__.type_name}>', 'exec'),  # noqa: S102
         namespace)
    check = namespace['check']
    check.__source__ = text
    _quick_checks[cls] = check
    return check


class _QuickCheckSource:
    """The lines of a quick check (see :func:`_quick_check_of`).

    They ``return False`` at the first value that is not of its field's plain type:

    - ``float32``/``float64``, ``bool``, ``string``/``wstring``: exactly ``float``, ``bool``,
      ``str``; an integer type: exactly ``int`` (not ``bool``) within the type's range;
    - a nested message: exactly its generated class (not a subclass), and its fields;
    - an array or sequence: a ``list`` or ``tuple`` (also ``bytes`` or ``bytearray`` for an
      integer type whose range holds [0, 255]) of the array's size or within the sequence's
      bound, each element as above.

    Every such value passes the full check too; any other goes to the full check, which
    decides (numpy floats pass it, for one).
    """

    def __init__(self):
        self.lines: list[str] = []
        self.constants: dict[str, object] = {'SEQUENCES': (list, tuple),
                                             'SEQUENCES_OR_BYTES': (list, tuple, bytes,
                                                                    bytearray)}
        self._names = itertools.count()
        self._class_names: dict[str, str] = {}  # message type -> name of its class

    def emit(self, indent: int, line: str) -> None:
        self.lines.append('    ' * indent + line)

    def local(self, indent: int, expr: str) -> str:
        """A name for ``expr``: itself if it is one, else a new local bound to it."""
        if expr.isidentifier():
            return expr
        name = f'v{next(self._names)}'
        self.emit(indent, f'{name} = {expr}')
        return name

    def fields(self, definition: MsgDef, expr: str, indent: int) -> None:
        """Check each field of the message ``expr`` (already known to be of its class)."""
        for field in definition.fields:
            if field.container is None:
                self.value(field.base_type, f'{expr}.{field.name}', indent)
            else:
                self.sequence(field, f'{expr}.{field.name}', indent)

    def value(self, base_type: str, expr: str, indent: int) -> None:
        """Check the single value ``expr`` of type ``base_type``."""
        if base_type in _PLAIN_TYPES:
            self.emit(indent, f'if type({expr}) is not {_PLAIN_TYPES[base_type]}: return False')
        elif base_type in _INT_RANGES:
            low, high = _INT_RANGES[base_type]
            name = self.local(indent, expr)
            self.emit(indent, f'if type({name}) is not int or not {low} <= {name} <= {high}: '
                              f'return False')
        else:
            cls_name = self._class_names.get(base_type)
            if cls_name is None:
                cls_name = self._class_names[base_type] = f'C{len(self._class_names)}'
                self.constants[cls_name] = generated_class(base_type)
            name = self.local(indent, expr)
            self.emit(indent, f'if type({name}) is not {cls_name}: return False  # {base_type}')
            self.fields(msgdef(base_type), name, indent)

    def sequence(self, field: FieldDef, expr: str, indent: int) -> None:
        """Check the array or sequence field ``field`` whose value is ``expr``."""
        base = field.base_type
        name = self.local(indent, expr)
        # bytes hold ints in [0, 255]: fine for uint8, byte and char.
        in_bytes = base in _INT_RANGES and _INT_RANGES[base][0] <= 0 and \
            _INT_RANGES[base][1] >= 255
        containers = 'SEQUENCES_OR_BYTES' if in_bytes else 'SEQUENCES'
        self.emit(indent, f'if type({name}) not in {containers}: return False')
        if field.container == 'array':
            self.emit(indent, f'if len({name}) != {field.size}: return False')
        elif field.size:
            self.emit(indent, f'if len({name}) > {field.size}: return False')
        if base in _PLAIN_TYPES:
            self.emit(indent, f'if list(map(type, {name})).count({_PLAIN_TYPES[base]}) '
                              f'!= len({name}): return False')
        elif base in _INT_RANGES:
            low, high = _INT_RANGES[base]
            self.emit(indent, f'if {name} and (list(map(type, {name})).count(int) != len({name})'
                              f' or min({name}) < {low} or max({name}) > {high}): return False')
        else:
            item = f'e{next(self._names)}'
            self.emit(indent, f'for {item} in {name}:')
            self.value(base, item, indent + 1)


def _validate_fields(msg, where: str | None = None) -> None:
    """The full check of :func:`validate_message`, field by field and value by value."""
    definition = type(msg).__msgdef__
    where = where or definition.type_name
    for field in definition.fields:
        value = getattr(msg, field.name)
        path = f'{where}.{field.name}'
        if field.container is None:
            _check_scalar(field.base_type, value, path)
            continue
        if isinstance(value, str):
            raise InterfaceError(f'{path} must be a sequence of {field.base_type}, got a str')
        if field.base_type == 'uint8' and isinstance(value, (bytes, bytearray)):
            items = list(value)
        else:
            try:
                items = list(value)
            except TypeError:
                raise InterfaceError(f'{path} must be a sequence, got {value!r}') from None
        if field.container == 'array' and len(items) != field.size:
            raise InterfaceError(f'{path} must have exactly {field.size} elements, '
                                 f'got {len(items)}')
        if field.container == 'sequence' and field.size and len(items) > field.size:
            raise InterfaceError(f'{path} has {len(items)} elements, at most {field.size}')
        for index, item in enumerate(items):
            _check_scalar(field.base_type, item, f'{path}[{index}]')
