"""Parser of ROS 2 ``.msg`` interface definitions.

The definitions themselves are the ROS 2 Jazzy files, kept verbatim in ``msgs_schema/msg/<pkg>/``.
This module turns one file into a :class:`MsgDef`; :mod:`gait_nodes.interfaces.generate` turns a
:class:`MsgDef` into a message class and its CDR code.
"""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

from gait_nodes.errors import InterfaceError

#: Primitive ROS 2 types: name -> (struct format character, size in bytes).
PRIMITIVES: dict[str, tuple[str, int]] = {
    'bool': ('?', 1),
    'byte': ('B', 1),
    'char': ('B', 1),
    'int8': ('b', 1),
    'uint8': ('B', 1),
    'int16': ('h', 2),
    'uint16': ('H', 2),
    'int32': ('i', 4),
    'uint32': ('I', 4),
    'int64': ('q', 8),
    'uint64': ('Q', 8),
    'float32': ('f', 4),
    'float64': ('d', 8),
}
STRING_TYPES = ('string', 'wstring')

_FIELD_RE = re.compile(
    r'^(?P<type>[A-Za-z_][\w/]*)(?:<=(?P<strbound>\d+))?'
    r'(?:\[(?P<arr>(?:<=)?\d*)\])?\s+(?P<name>[A-Za-z_]\w*)\s*(?P<rest>.*)$'
)


@dataclasses.dataclass(frozen=True)
class FieldDef:
    """One field of a message.

    Attributes:
        name: Field name.
        base_type: Primitive name, ``string``/``wstring`` or a full ``pkg/msg/Name``.
        container: ``None`` for a single value, ``'array'`` (fixed size) or ``'sequence'``.
        size: Array length, sequence bound (0 for unbounded) or ``None``.
        string_bound: Maximum length of a bounded string, 0 when unbounded.
        default: Default value from the definition, or ``None``.
    """

    name: str
    base_type: str
    container: str | None = None
    size: int | None = None
    string_bound: int = 0
    default: object = None

    @property
    def is_primitive(self) -> bool:
        """Whether the base type is a fixed-size primitive."""
        return self.base_type in PRIMITIVES

    @property
    def is_string(self) -> bool:
        """Whether the base type is a (w)string."""
        return self.base_type in STRING_TYPES


@dataclasses.dataclass(frozen=True)
class ConstantDef:
    """A constant declared in a message: ``int32 ARROW=0``."""

    name: str
    type: str
    value: object


@dataclasses.dataclass(frozen=True)
class MsgDef:
    """A parsed message definition.

    Attributes:
        type_name: Full name, ``pkg/msg/Name``.
        fields: Fields in declaration order.
        constants: Constants in declaration order.
        text: The verbatim ``.msg`` text (used for MCAP schemas).
    """

    type_name: str
    fields: tuple[FieldDef, ...]
    constants: tuple[ConstantDef, ...]
    text: str

    @property
    def dependencies(self) -> tuple[str, ...]:
        """Message types used directly by the fields, in order of first use."""
        seen: dict[str, None] = {}
        for field in self.fields:
            if not field.is_primitive and not field.is_string:
                seen.setdefault(field.base_type, None)
        return tuple(seen)


def _qualify(type_token: str, package: str) -> str:
    if type_token in PRIMITIVES or type_token in STRING_TYPES:
        return type_token
    if type_token == 'Header':
        return 'std_msgs/msg/Header'
    parts = type_token.split('/')
    if len(parts) == 1:
        return f'{package}/msg/{parts[0]}'
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3 and parts[1] == 'msg':
        return type_token
    raise InterfaceError(f'invalid type name {type_token!r}')


def _strip_comment(line: str) -> str:
    # A '#' inside a quoted string default is not a comment.
    quote = None
    for i, char in enumerate(line):
        if quote:
            if char == quote:
                quote = None
        elif char in '"\'':
            quote = char
        elif char == '#':
            return line[:i]
    return line


def _literal(text: str, base_type: str, where: str) -> object:
    text = text.strip()
    if base_type in STRING_TYPES:
        if len(text) >= 2 and text[0] == text[-1] and text[0] in '"\'':
            return ast.literal_eval(text)
        return text
    if base_type == 'bool':
        lowered = text.lower()
        if lowered in ('true', '1'):
            return True
        if lowered in ('false', '0'):
            return False
        raise InterfaceError(f'{where}: bool value must be true/false, got {text!r}')
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError) as exc:
        raise InterfaceError(f'{where}: cannot parse value {text!r}') from exc
    if base_type.startswith('float'):
        return float(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise InterfaceError(f'{where}: integer value expected for {base_type}, got {text!r}')
    return value


def _default(rest: str, field: FieldDef, where: str) -> object:
    if field.container is None:
        return _literal(rest, field.base_type, where)
    items = ast.literal_eval(rest) if field.base_type not in STRING_TYPES else None
    if items is None:
        inner = rest.strip()
        if not (inner.startswith('[') and inner.endswith(']')):
            raise InterfaceError(f'{where}: array default must be [..], got {rest!r}')
        items = [part for part in inner[1:-1].split(',') if part.strip()]
    return [_literal(str(item), field.base_type, where) for item in items]


def parse_msg(type_name: str, text: str) -> MsgDef:
    """Parse the text of a ``.msg`` file.

    Args:
        type_name: Full name of the message, ``pkg/msg/Name``.
        text: Contents of the ``.msg`` file.

    Returns:
        The parsed definition.

    Raises:
        InterfaceError: The text is not a valid ROS 2 message definition.
    """
    package = type_name.split('/')[0]
    fields: list[FieldDef] = []
    constants: list[ConstantDef] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        where = f'{type_name} line {lineno}'
        constant = _CONST_RE.match(raw.strip())
        if constant is not None:
            constants.append(_parse_constant(constant, where))
            continue
        line = _strip_comment(raw).strip()
        if not line:
            continue
        match = _FIELD_RE.match(line)
        if match is None:
            raise InterfaceError(f'{where}: cannot parse {raw.strip()!r}')
        arr = match['arr']
        container = size = None
        if arr is not None:
            if arr == '' or arr.startswith('<='):
                container, size = 'sequence', int(arr[2:]) if arr else 0
            else:
                container, size = 'array', int(arr)
        field = FieldDef(
            name=match['name'], base_type=_qualify(match['type'], package),
            container=container, size=size, string_bound=int(match['strbound'] or 0),
        )
        rest = match['rest'].strip()
        if rest:
            field = dataclasses.replace(field, default=_default(rest, field, where))
        fields.append(field)
    if not fields:
        # ROS 2 gives a message without fields one placeholder member.
        fields.append(FieldDef('structure_needs_at_least_one_member', 'uint8'))
    return MsgDef(type_name, tuple(fields), tuple(constants), text)


_CONST_RE = re.compile(r'^(?P<type>\w+)\s+(?P<name>[A-Za-z]\w*)\s*=(?P<value>.*)$')


def _parse_constant(match: re.Match, where: str) -> ConstantDef:
    base_type = match['type']
    if base_type not in PRIMITIVES and base_type not in STRING_TYPES:
        raise InterfaceError(f'{where}: constant type must be primitive, got {base_type!r}')
    value_text = match['value']
    if base_type not in STRING_TYPES:
        value_text = _strip_comment(value_text)
    return ConstantDef(match['name'], base_type, _literal(value_text, base_type, where))


def schema_dir() -> Path:
    """Directory holding ``msg/<pkg>/<Name>.msg`` (installed copy first, then the source tree)."""
    from gait_nodes.errors import ConfigError
    from gait_nodes.paths import data_dir

    try:
        return data_dir('msgs_schema')
    except ConfigError as exc:
        raise InterfaceError(f'message definitions not found: {exc}') from exc


def load_msg(type_name: str, root: Path | None = None) -> MsgDef:
    """Load and parse ``pkg/msg/Name`` from the shipped Jazzy definitions."""
    parts = type_name.split('/')
    if len(parts) != 3 or parts[1] != 'msg':
        raise InterfaceError(f'message type must be pkg/msg/Name, got {type_name!r}')
    path = (root or schema_dir()) / 'msg' / parts[0] / f'{parts[2]}.msg'
    if not path.is_file():
        raise InterfaceError(f'unknown message type {type_name!r}: no definition at {path}')
    return parse_msg(type_name, path.read_text(encoding='utf-8'))


def available_types(root: Path | None = None) -> list[str]:
    """All message types whose definitions are shipped."""
    base = (root or schema_dir()) / 'msg'
    return sorted(f'{p.parent.name}/msg/{p.stem}' for p in base.glob('*/*.msg'))
