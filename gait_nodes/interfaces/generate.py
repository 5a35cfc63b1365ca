"""Message classes and their CDR code, generated from the ROS 2 ``.msg`` definitions.

Each message becomes a Cyclone DDS ``IdlStruct`` dataclass, ``@final`` (plain CDR, XCDR1) and
named the ROS 2 way on the wire (``sensor_msgs::msg::dds_::JointState_``), so that the ``dds``
runtime can publish it as it is. Its ``serialize``/``deserialize`` are replaced by Python source
generated per type: straight-line ``struct`` calls over the known field layout, which produce
exactly the bytes of ROS 2 (rosbags' Jazzy typestore is the reference in the tests) several times
faster than the generic interpreter of cyclonedds-python.

CDR rules applied (OMG CDR / XCDR1 as ROS 2 uses it): a 4-byte encapsulation header
(``00 01 00 00`` little endian), every primitive aligned to its own size counted from the end of
the header, strings as uint32 length including the NUL terminator, sequences as a uint32 count
followed by the elements, no padding after the last field.
"""

from __future__ import annotations

import dataclasses
import itertools
import struct
from collections.abc import Callable
from operator import is_, is_not

import cyclonedds.idl.types as idl_types
from cyclonedds.idl import IdlMeta, IdlStruct
from cyclonedds.idl.annotations import final

from gait_nodes.errors import SerializationError
from gait_nodes.interfaces.msgdef import PRIMITIVES, FieldDef, MsgDef

_IDL_PRIMITIVES = {
    'bool': bool,
    'byte': idl_types.byte,
    'char': idl_types.uint8,
    'int8': idl_types.int8,
    'uint8': idl_types.uint8,
    'int16': idl_types.int16,
    'uint16': idl_types.uint16,
    'int32': idl_types.int32,
    'uint32': idl_types.uint32,
    'int64': idl_types.int64,
    'uint64': idl_types.uint64,
    'float32': idl_types.float32,
    'float64': idl_types.float64,
}
_ZERO = {'bool': False, 'float32': 0.0, 'float64': 0.0}
_HEADER_LE = b'\x00\x01\x00\x00'
_BYTE_LIKE = ('byte', 'char', 'uint8')


def dds_type_name(type_name: str) -> str:
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_`` (the DDS type name ROS 2 uses)."""
    package, _, name = type_name.split('/')
    return f'{package}::msg::dds_::{name}_'


class _Alignment:
    """What is statically known of the write position: position = remainder (mod modulus)."""

    def __init__(self, modulus: int = 8, remainder: int = 0):
        self.modulus = modulus
        self.remainder = remainder

    def copy(self) -> _Alignment:
        return _Alignment(self.modulus, self.remainder)

    def static_pad(self, align: int) -> int | None:
        if align <= self.modulus:
            return (-self.remainder) % align
        return None

    def advance(self, nbytes: int) -> None:
        self.remainder = (self.remainder + nbytes) % self.modulus

    def reset(self, modulus: int) -> None:
        self.modulus, self.remainder = modulus, 0


class SequenceStructs(dict):
    """``structs[n]``: the Struct of ``n`` primitives of one format, made on first use.

    A sequence of primitives (JointState.position) is packed with the Struct of its length,
    which is found here at once rather than built from a format string made for each message
    (``struct.pack('<%dd' % n, ...)`` costs twice as much for 28 doubles). Same bytes, same
    errors.
    """

    #: Lengths kept per format (all forgotten at once beyond).
    KEPT = 64
    _shared: dict[str, SequenceStructs] = {}

    def __init__(self, fmt: str):
        super().__init__()
        self.order, self.char = fmt[0], fmt[1:]

    @classmethod
    def of(cls, fmt: str) -> SequenceStructs:
        """The one instance for ``fmt`` (byte order character and format character)."""
        structs = cls._shared.get(fmt)
        if structs is None:
            structs = cls._shared[fmt] = cls(fmt)
        return structs

    def __missing__(self, count: int) -> struct.Struct:
        if len(self) >= self.KEPT:
            self.clear()
        made = self[count] = struct.Struct(f'{self.order}{count}{self.char}')
        return made


class _CodeWriter:
    def __init__(self):
        self.lines: list[str] = []
        self.constants: dict[str, object] = {}
        self._counter = 0
        self._struct_names: dict[str, str] = {}

    def emit(self, indent: int, line: str) -> None:
        self.lines.append('    ' * indent + line)

    def unique(self, prefix: str) -> str:
        self._counter += 1
        return f'{prefix}{self._counter}'

    def sequence_structs(self, fmt: str) -> str:
        """Name of the :class:`SequenceStructs` of ``fmt`` (byte order and one format char)."""
        char = 'bool' if fmt[1] == '?' else fmt[1]
        name = f'SEQ_{"LE" if fmt[0] == "<" else "BE"}_{char}'
        self.constants[name] = SequenceStructs.of(fmt)
        return name

    def struct_const(self, fmt: str) -> str:
        name = self._struct_names.get(fmt)
        if name is None:
            name = self._struct_names[fmt] = f'S{len(self._struct_names)}'
            self.constants[name] = struct.Struct(fmt)
        return name


class _SerializerBuilder:
    """Emits ``b += ...`` statements appending the CDR of a value to bytearray ``b``.

    Positions are counted from the start of ``b``, whose first 4 bytes are the header, hence the
    ``len(b) - 4`` of dynamic alignment.
    """

    def __init__(self, definitions: dict[str, MsgDef], writer: _CodeWriter):
        self.definitions = definitions
        self.w = writer
        self.pending_fmt = ''
        self.pending_values: list[str] = []
        self.pending_indent = 0

    def flush(self) -> None:
        if self.pending_fmt:
            name = self.w.struct_const('<' + self.pending_fmt)
            self.w.emit(self.pending_indent,
                        f'b += {name}.pack({", ".join(self.pending_values)})')
        self.pending_fmt, self.pending_values = '', []

    def pure(self, indent: int, line: str) -> None:
        """Emit a line that does not touch ``b`` ahead of the pending run (which keeps growing).

        Its values are read when the run is packed, after this line: names bound here are
        fresh, and the message is not modified meanwhile.
        """
        if self.pending_fmt and indent != self.pending_indent:
            self.flush()
        self.w.emit(indent, line)

    def align(self, indent: int, align: int, state: _Alignment) -> None:
        pad = state.static_pad(align)
        if pad is None:
            self.flush()
            self.w.emit(indent, f'b += PAD[(4 - len(b)) % {align}]')
            state.reset(align)
        elif pad:
            self.push(indent, 'x' * pad, [])
            state.advance(pad)

    def push(self, indent: int, fmt: str, values: list[str]) -> None:
        if self.pending_fmt and indent != self.pending_indent:
            self.flush()
        self.pending_indent = indent
        self.pending_fmt += fmt
        self.pending_values.extend(values)

    def primitive(self, indent: int, base: str, expr: str, state: _Alignment) -> None:
        fmt, size = PRIMITIVES[base]
        self.align(indent, size, state)
        self.push(indent, fmt, [expr])
        state.advance(size)

    def string(self, indent: int, field: FieldDef, expr: str, state: _Alignment) -> None:
        # The length joins the pending run of primitives; the characters follow it.
        self.align(indent, 4, state)
        var = self.w.unique('s')
        if field.base_type == 'wstring':
            self.pure(indent, f'{var} = {expr}.encode("utf-16-le")')
            self.push(indent, 'I', [f'len({var}) // 2'])
            self.flush()
            self.w.emit(indent, f'b += {var}')
        else:
            self.pure(indent, f'{var} = {expr}.encode()')
            if field.string_bound:
                self.pure(indent, f'if len({expr}) > {field.string_bound}: '
                                  f'raise ValueError("string longer than bound '
                                  f'{field.string_bound}")')
            self.push(indent, 'I', [f'len({var}) + 1'])
            self.flush()
            self.w.emit(indent, f'b += {var}')
            self.w.emit(indent, "b += b'\\x00'")
        state.reset(1)

    def single(self, indent: int, field: FieldDef, expr: str, state: _Alignment) -> None:
        if field.is_primitive:
            self.primitive(indent, field.base_type, expr, state)
        elif field.is_string:
            self.string(indent, field, expr, state)
        else:
            self.struct(indent, self.definitions[field.base_type], expr, state)

    def struct(self, indent: int, msgdef: MsgDef, expr: str, state: _Alignment) -> None:
        if len(msgdef.fields) > 1:
            var = self.w.unique('m')
            self.pure(indent, f'{var} = {expr}')
            expr = var
        for field in msgdef.fields:
            self.field(indent, field, f'{expr}.{field.name}', state)

    def flat_layout(self, msgdef: MsgDef, expr: str) -> tuple[str, list[str], int] | None:
        """Format, value expressions and alignment of a struct of same-size primitives only.

        Such a struct has no padding inside and its size is a multiple of its alignment, so a
        sequence of them is one run of primitives (None for any other struct).
        """
        fmt, values, sizes = '', [], set()
        for field in msgdef.fields:
            if field.container is not None or field.is_string:
                return None
            if field.is_primitive:
                char, size = PRIMITIVES[field.base_type]
                fmt += char
                values.append(f'{expr}.{field.name}')
                sizes.add(size)
                continue
            inner = self.flat_layout(self.definitions[field.base_type], f'{expr}.{field.name}')
            if inner is None:
                return None
            fmt += inner[0]
            values.extend(inner[1])
            sizes.add(inner[2])
        if len(sizes) != 1:
            return None
        return fmt, values, sizes.pop()

    def field(self, indent: int, field: FieldDef, expr: str, state: _Alignment) -> None:
        if field.container is None:
            self.single(indent, field, expr, state)
            return
        single = dataclasses.replace(field, container=None, size=None)
        var = self.w.unique('v')
        self.pure(indent, f'{var} = {expr}')
        if field.container == 'array':
            self.pure(indent, f'if len({var}) != {field.size}: '
                              f'raise ValueError("{field.name} must have exactly '
                              f'{field.size} elements, got %d" % len({var}))')
            count = field.size
        else:
            if field.size:
                self.pure(indent, f'if len({var}) > {field.size}: '
                                  f'raise ValueError("{field.name} has %d elements, at most '
                                  f'{field.size} allowed" % len({var}))')
            self.primitive(indent, 'uint32', f'len({var})', state)
            count = None
        if field.is_primitive:
            fmt, size = PRIMITIVES[field.base_type]
            if count is None:
                self.flush()
                self.w.emit(indent, f'if {var}:')
                if size > 1:
                    self.w.emit(indent + 1, f'b += PAD[(4 - len(b)) % {size}]')
                self._primitive_run(indent + 1, field.base_type, var)
                state.reset(min(size, 4))
            else:
                if count:
                    self.align(indent, size, state)
                    self.flush()
                    self._primitive_run(indent, field.base_type, var)
                    state.advance(size * count)
            return
        loop_var = self.w.unique('e')
        if not field.is_string:
            flat = self.flat_layout(self.definitions[field.base_type], loop_var)
            if flat is not None:
                self._flat_run(indent, var, count, *flat, state)
                return
            record = self.record_layout(self.definitions[field.base_type], loop_var)
            if record is not None:
                self._record_run(indent, var, loop_var, single, *record)
                state.reset(1)
                return
        elif count is None and field.base_type == 'string' and not field.string_bound:
            # After its count a sequence of strings starts 4-aligned and holds 4-aligned
            # items only: its bytes depend on its content alone, and a name list sent again
            # and again (JointState.name) is encoded once.
            self.flush()
            key, data = self.w.unique('k'), self.w.unique('c')
            self.w.emit(indent, f'{key} = tuple({var})')
            self.w.emit(indent, f'{data} = STRINGS.get({key})')
            self.w.emit(indent, f'if {data} is None: {data} = string_sequence({key})')
            self.w.emit(indent, f'b += {data}')
            state.reset(1)
            return
        self.flush()
        self.w.emit(indent, f'for {loop_var} in {var}:')
        self.single(indent + 1, single, loop_var, _Alignment(1))
        self.flush()
        state.reset(1)

    def record_layout(self, msgdef: MsgDef, expr: str) -> tuple[list, list[str], list[str]] | None:
        """Items, value expressions and name bindings of a struct without containers.

        Such a struct (PoseStamped, TransformStamped, KeyValue...) has primitives and strings
        only, nested structs included. Items are ``(format character, size)`` for a primitive
        and ``('s', bound)`` for a string, which takes two values: the string twice (its length
        and its bytes, once encoded). None for a struct with a container or a wstring.
        """
        items, values, bindings = [], [], []
        if len(msgdef.fields) > 1 and '.' in expr:
            var = self.w.unique('r')
            bindings.append(f'{var} = {expr}')
            expr = var
        for field in msgdef.fields:
            if field.container is not None or field.base_type == 'wstring':
                return None
            value = f'{expr}.{field.name}'
            if field.is_primitive:
                items.append(PRIMITIVES[field.base_type])
                values.append(value)
            elif field.is_string:
                items.append(('s', field.string_bound))
                values += [value, value]
            else:
                inner = self.record_layout(self.definitions[field.base_type], value)
                if inner is None:
                    return None
                items += inner[0]
                values += inner[1]
                bindings += inner[2]
        return items, values, bindings

    def _record_run(self, indent: int, var: str, loop_var: str, single: FieldDef,
                    items: list, values: list[str], bindings: list[str]) -> None:
        """A sequence or array of container-free structs: one pack for all, when it can be.

        Packing each element field by field costs a few appends per element; gathering every
        element's values in one list and packing them with one Struct (:class:`RecordRun`) is
        several times faster. That works when each string field has the same encoded length in
        every element (frame ids usually are one string): then every element has the same layout
        but for its alignment, which the Struct spells out from the position of the first. When
        it does not, or for a few elements, the general per-element code runs instead.
        """
        self.flush()
        gather = ['def gather(elements):', '    g = []', f'    for {loop_var} in elements:',
                  *(f'        {line}' for line in bindings),
                  f'        g += ({", ".join(values)},)', '    return g']
        namespace: dict = {}
        exec(compile('\n'.join(gather), '<cdr gather>', 'exec'), namespace)  # noqa: S102
        namespace['gather'].__source__ = '\n'.join(gather)
        run, data = self.w.unique('RUN'), self.w.unique('d')
        self.w.constants[run] = RecordRun(items, namespace['gather'])
        self.w.emit(indent, f'if {var}:')
        self.w.emit(indent + 1, f'{data} = {run}({var}, (len(b) - 4) % 8, published) '
                                f'if len({var}) >= {RecordRun.MIN_ELEMENTS} else None')
        self.w.emit(indent + 1, f'if {data} is not None:')
        self.w.emit(indent + 2, f'b += {data}')
        self.w.emit(indent + 1, 'else:')
        self.w.emit(indent + 2, f'for {loop_var} in {var}:')
        self.single(indent + 3, single, loop_var, _Alignment(1))
        self.flush()

    def _flat_run(self, indent: int, var: str, count: int | None, fmt: str, values: list[str],
                  size: int, state: _Alignment) -> None:
        """A sequence (``count`` None) or array of flat structs: aligned once, one pack each."""
        loop_var = values[0].split('.')[0]
        element = self.w.struct_const('<' + fmt)
        if count is None:
            # Once aligned, the run's bytes depend on its content alone: a sequence object met
            # again in a published message (never edited, see serialize_published) is not
            # packed again (the support polygon's vertices, the same for hundreds of ticks).
            self.flush()
            memo, known, start = self.w.unique('MEMO'), self.w.unique('k'), self.w.unique('t')
            self.w.constants[memo] = {}
            self.w.emit(indent, f'if {var}:')
            if size > 4:
                self.w.emit(indent + 1, f'b += PAD[(4 - len(b)) % {size}]')
            self.w.emit(indent + 1, f'{known} = {memo}.get(id({var})) if published and '
                                    f'len({var}) >= MEMO_MIN else None')
            self.w.emit(indent + 1, f'if {known} is not None and {known}[0] is {var}:')
            self.w.emit(indent + 2, f'b += {known}[1]')
            self.w.emit(indent + 1, 'else:')
            self.w.emit(indent + 2, f'{start} = len(b)')
            self.w.emit(indent + 2, f'for {loop_var} in {var}:')
            self.w.emit(indent + 3, f'b += {element}.pack({", ".join(values)})')
            self.w.emit(indent + 2, f'if published and len({var}) >= MEMO_MIN: '
                                    f'remember({memo}, {var}, b, {start})')
            state.reset(min(size, 4))
        elif count:
            self.align(indent, size, state)
            self.flush()
            self.w.emit(indent, f'for {loop_var} in {var}:')
            self.w.emit(indent + 1, f'b += {element}.pack({", ".join(values)})')
            state.advance(size * len(fmt) * count)

    def _primitive_run(self, indent: int, base: str, var: str) -> None:
        fmt = PRIMITIVES[base][0]
        if base in _BYTE_LIKE:
            self.w.emit(indent, f'b += bytes({var})')
        else:
            structs = self.w.sequence_structs('<' + fmt)
            self.w.emit(indent, f'b += {structs}[len({var})].pack(*{var})')


class _DeserializerBuilder:
    """Emits statements reading a value from ``d`` (bytes or memoryview) at position ``p``.

    ``E`` is the byte-order character of the data, bound when the function is made.
    """

    def __init__(self, definitions: dict[str, MsgDef], classes: dict[str, type],
                 writer: _CodeWriter, order: str):
        self.definitions = definitions
        self.classes = classes
        self.w = writer
        self.order = order
        # A run of fixed-position primitives read with one unpack: (indent, targets, format),
        # and the struct constructions waiting for it (they only use values read before).
        self._run: tuple[int, list[str], str] | None = None
        self._deferred: list[str] = []

    def emit(self, indent: int, line: str) -> None:
        self.flush()
        self.w.emit(indent, line)

    def flush(self) -> None:
        """Emit the pending run of primitives as one ``unpack_from``."""
        if self._run is None:
            return
        indent, targets, fmt = self._run
        deferred, self._run, self._deferred = self._deferred, None, []
        name = self.w.struct_const(self.order + fmt)
        self.w.emit(indent, f'{", ".join(targets)}, = {name}.unpack_from(d, p)')
        self.w.emit(indent, f'p += {struct.calcsize(self.order + fmt)}')
        for line in deferred:
            self.w.emit(indent, line)

    def align(self, indent: int, align: int, state: _Alignment) -> None:
        pad = state.static_pad(align)
        if pad is None:
            self.emit(indent, f'p += (4 - p) % {align}')
            state.reset(align)
        elif pad:
            self.emit(indent, f'p += {pad}')
            state.advance(pad)

    def single(self, indent: int, field: FieldDef, target: str, state: _Alignment) -> None:
        if field.is_primitive:
            fmt, size = PRIMITIVES[field.base_type]
            pad = state.static_pad(size)
            if pad is None:
                self.align(indent, size, state)
                pad = 0
            if self._run is None or self._run[0] != indent:
                self.flush()
                self._run = (indent, [], '')
            run_indent, targets, run_fmt = self._run
            self._run = (run_indent, [*targets, target], run_fmt + 'x' * pad + fmt)
            state.advance(pad + size)
        elif field.is_string:
            self.align(indent, 4, state)
            length = self.w.unique('n')
            name = self.w.struct_const(self.order + 'I')
            self.emit(indent, f'{length}, = {name}.unpack_from(d, p)')
            if field.base_type == 'wstring':
                self.emit(indent, f'{target} = bytes(d[p + 4:p + 4 + 2 * {length}])'
                                    f'.decode("utf-16-le")')
                self.emit(indent, f'p += 4 + 2 * {length}')
            else:
                self.emit(indent, f'{target} = bytes(d[p + 4:p + 3 + {length}]).decode()')
                self.emit(indent, f'p += 4 + {length}')
            state.reset(1)
        else:
            self.struct(indent, self.definitions[field.base_type], target, state)

    def struct(self, indent: int, msgdef: MsgDef, target: str, state: _Alignment) -> None:
        values = []
        for field in msgdef.fields:
            var = self.w.unique('f')
            self.field(indent, field, var, state)
            values.append(var)
        cls = f'C_{msgdef.type_name.replace("/", "_")}'
        self.w.constants[cls] = self.classes[msgdef.type_name]
        construction = f'{target} = {cls}({", ".join(values)})'
        if self._run is not None and self._run[0] == indent:
            self._deferred.append(construction)
        else:
            self.emit(indent, construction)

    def field(self, indent: int, field: FieldDef, target: str, state: _Alignment) -> None:
        if field.container is None:
            self.single(indent, field, target, state)
            return
        single = dataclasses.replace(field, container=None, size=None)
        count = self.w.unique('c')
        if field.container == 'array':
            self.emit(indent, f'{count} = {field.size}')
        else:
            self.single(indent, FieldDef('count', 'uint32'), count, state)
        if field.is_primitive:
            fmt, size = PRIMITIVES[field.base_type]
            if field.container == 'sequence' and size > 1:
                self.emit(indent, f'if {count}: p += (4 - p) % {size}')
            elif field.container == 'array':
                self.align(indent, size, state)
            if field.base_type in _BYTE_LIKE:
                self.emit(indent, f'{target} = bytes(d[p:p + {count}])')
                if field.base_type != 'uint8' or field.container == 'array':
                    self.emit(indent, f'{target} = list({target})')
            else:
                structs = self.w.sequence_structs(self.order + fmt)
                self.emit(indent, f'{target} = list({structs}[{count}].unpack_from(d, p))')
            self.emit(indent, f'p += {size} * {count}')
            if field.container == 'array':
                state.advance(size * field.size)
            else:
                state.reset(min(size, 4))
            return
        if field.container == 'sequence' and field.base_type == 'string':
            self._string_sequence(indent, single, count, target)
            state.reset(1)
            return
        element = self.w.unique('e')
        self.emit(indent, f'{target} = []')
        self.emit(indent, f'for _ in range({count}):')
        self.single(indent + 1, single, element, _Alignment(1))
        self.emit(indent + 1, f'{target}.append({element})')
        state.reset(1)

    def _string_sequence(self, indent: int, single: FieldDef, count: str, target: str) -> None:
        """A sequence of strings, decoded once for the bytes met last with its count here.

        After its count the strings start 4-aligned, so their bytes alone decide them and where
        they end: a name list received again and again (JointState.name, 28 names decoded in
        17 of the 22 us of a RoboSimian /joint_states) is compared, not decoded. Bytes that
        run past the end of the data are not remembered.
        """
        memo, known, start = self.w.unique('MEMO'), self.w.unique('k'), self.w.unique('t')
        element = self.w.unique('e')
        self.w.constants[memo] = {}
        self.emit(indent, f'{known} = {memo}.get({count})')
        self.emit(indent, f'if {known} is not None and bytes(d[p:p + {known}[1]]) == {known}[0]:')
        self.emit(indent + 1, f'{target} = list({known}[2])')
        self.emit(indent + 1, f'p += {known}[1]')
        self.emit(indent, 'else:')
        self.emit(indent + 1, f'{start} = p')
        self.emit(indent + 1, f'{target} = []')
        self.emit(indent + 1, f'for _ in range({count}):')
        self.single(indent + 2, single, element, _Alignment(1))
        self.emit(indent + 2, f'{target}.append({element})')
        self.emit(indent + 1, f'if p <= len(d): remember_strings({memo}, {count}, '
                              f'bytes(d[{start}:p]), {target})')


class RecordRun:
    """The CDR of a run of container-free structs whose strings have the same length in each.

    Called with the elements and the position of the first modulo 8 (counted from the end of
    the encapsulation header). The elements' values are gathered in one list (each string
    twice, see :meth:`_SerializerBuilder.record_layout`). Each string field is encoded once
    when it is the same string in every element (the usual frame id), else element by element;
    when its encoded length varies, the run has no single layout and None is returned (the
    caller packs element by element). Otherwise the elements' layout is fixed by the string
    lengths and the start position: one Struct for them all, compiled once per layout and kept,
    gives the same bytes as packing the elements one by one.

    A run of a published message (``published``, see ``serialize_published``) whose leading
    elements are the very objects of a stretch of the previous published run here (a ZMP
    reference sliding along its horizon) copies their bytes from then and packs only the rest,
    when every element of both has the same size, a multiple of 8 (each element then starts at
    the same alignment, so that its bytes depend on its content alone).

    Args:
        items: Per element, ``(format character, size)`` of each primitive and
            ``('s', bound)`` of each string (bound 0: unbounded), in field order.
        gather: ``gather(elements) -> list`` of the elements' values, in item order.
    """

    #: Below this many elements the element by element code is as fast.
    MIN_ELEMENTS = 4
    #: Layouts kept per run (a new one is compiled when the run meets a new length or shape).
    LAYOUTS_KEPT = 64

    def __init__(self, items: list, gather: Callable[[list], list]):
        self.items = list(items)
        self.gather = gather
        self.width = sum(2 if kind == 's' else 1 for kind, _ in items)
        self.strings = []  # (column of the first of the string's two values, bound)
        column = 0
        for kind, size in items:
            if kind == 's':
                self.strings.append((column, size))
                column += 2
            else:
                column += 1
        #: (start alignment, count, string lengths...) -> (Struct, element size or None).
        self.layouts: dict[tuple, tuple[struct.Struct, int | None]] = {}
        #: The last published run: (elements, start alignment, element size, bytes), or None.
        self.published: tuple | None = None

    def __call__(self, elements, phase: int, published: bool = False) -> bytes | None:
        """CDR of the ``elements`` starting at ``phase`` (mod 8), or None (see above)."""
        known, prefix, size = 0, b'', None
        if published and self.published is not None and self.published[1] == phase:
            previous, _, size, data = self.published
            known, offset = _shared_lead(elements, previous)
            prefix = data[offset * size:(offset + known) * size]
        tail = elements[known:] if known else elements
        packed = self._pack(self.gather(tail), len(tail), phase) if tail else (b'', size)
        if packed is None:
            self.published = None
            return None
        data = prefix + packed[0] if known else packed[0]
        if published:
            uniform = packed[1] is not None and (not known or packed[1] == size)
            self.published = (elements, phase, packed[1], data) if uniform else None
        return data

    def _pack(self, values: list, count: int, phase: int) -> tuple[bytes, int | None] | None:
        """Bytes and element size (None if not one multiple of 8) of gathered values."""
        width = self.width
        lengths = []
        for column, bound in self.strings:
            strings = values[column::width]
            first = strings[0]
            if strings.count(first) == count:
                if bound and len(first) > bound:
                    raise ValueError(f'string longer than bound {bound}')
                encoded = first.encode()
                values[column + 1::width] = [encoded] * count
            else:
                if bound and max(map(len, strings)) > bound:
                    raise ValueError(f'string longer than bound {bound}')
                encoded = [string.encode() for string in strings]
                if len(set(map(len, encoded))) > 1:
                    return None
                values[column + 1::width] = encoded
                encoded = encoded[0]
            values[column::width] = [len(encoded) + 1] * count
            lengths.append(len(encoded))
        key = (phase, count, *lengths)
        layout = self.layouts.get(key)
        if layout is None:
            layout = self._layout(phase, count, lengths)
        return layout[0].pack(*values), layout[1]

    def _layout(self, phase: int, count: int, lengths: list[int]) -> tuple:
        """Struct of ``count`` elements starting at ``phase`` (mod 8) and their one size."""
        parts, position, sizes = ['<'], phase, set()
        for _ in range(count):
            string_lengths = iter(lengths)
            start = position
            for kind, size in self.items:
                if kind == 's':
                    length = next(string_lengths)
                    pad = -position % 4
                    parts.append(f'{pad}xI{length + 1}s' if pad else f'I{length + 1}s')
                    position += pad + 5 + length
                else:
                    pad = -position % size
                    parts.append(f'{pad}x{kind}' if pad else kind)
                    position += pad + size
            sizes.add(position - start)
        size = sizes.pop() if len(sizes) == 1 else None
        if len(self.layouts) >= self.LAYOUTS_KEPT:
            self.layouts.clear()
        layout = self.layouts[(phase, count, *lengths)] = (
            struct.Struct(''.join(parts)), size if size is not None and size % 8 == 0 else None)
        return layout


def _shared_lead(elements, previous) -> tuple[int, int]:
    """How many leading ``elements`` are (``is``) ``previous[offset:]``'s, and the offset.

    (0, 0) when the first element is not in ``previous``. Searched without a Python loop.
    """
    offset = next(itertools.compress(itertools.count(),
                                     map(is_, itertools.repeat(elements[0]), previous)), None)
    if offset is None:
        return 0, 0
    same = elements[:len(previous) - offset]
    return next(itertools.compress(itertools.count(), map(is_not, same, previous[offset:])),
                len(same)), offset


#: Encoded sequences of strings by content (see :func:`_string_sequence`), for all types.
_STRING_SEQUENCES: dict[tuple, bytes] = {}
_STRING_SEQUENCES_KEPT = 256
_U32_LE = struct.Struct('<I')


def _string_sequence(strings: tuple) -> bytes:
    """CDR of the items of a sequence of unbounded strings that starts 4-aligned, remembered."""
    out = bytearray()
    for string in strings:
        out += bytes((-len(out)) % 4)
        encoded = string.encode()
        out += _U32_LE.pack(len(encoded) + 1)
        out += encoded
        out += b'\x00'
    out = bytes(out)
    if len(_STRING_SEQUENCES) >= _STRING_SEQUENCES_KEPT:
        _STRING_SEQUENCES.clear()
    _STRING_SEQUENCES[strings] = out
    return out


#: Sequences shorter than this are packed again rather than looked up.
_MEMO_MIN = 8
#: Sequences remembered per place in a message type (the oldest are forgotten all at once).
_MEMO_KEPT = 8


def _remember(memo: dict, sequence, data: bytearray, start: int) -> None:
    """Keep the bytes ``data[start:]`` packed from ``sequence``, and the sequence (its id).

    Holding the sequence keeps its id from being given to another object while remembered.
    """
    if len(memo) >= _MEMO_KEPT:
        memo.clear()
    memo[id(sequence)] = (sequence, bytes(data[start:]))


def _remember_strings(memo: dict, count: int, data: bytes, strings: list[str]) -> None:
    """Keep a sequence of ``count`` strings decoded from ``data`` (see ``_string_sequence``)."""
    if len(memo) >= _MEMO_KEPT:
        memo.clear()
    memo[count] = (data, len(data), tuple(strings))


def _compile(writer: _CodeWriter, name: str, args: str, result: str) -> Callable:
    source = '\n'.join([f'def {name}({args}):', *writer.lines, f'    return {result}'])
    namespace = dict(writer.constants)
    namespace.update(
        PAD=[bytes(i) for i in range(8)], U32=struct.Struct('<I'),
        pack=struct.pack, unpack_from=struct.unpack_from,
        STRINGS=_STRING_SEQUENCES, string_sequence=_string_sequence,
        MEMO_MIN=_MEMO_MIN, remember=_remember, remember_strings=_remember_strings,
    )
    exec(compile(source, f'<cdr {name}>', 'exec'), namespace)  # noqa: S102 - generated above
    function = namespace[name]
    function.__source__ = source
    return function


def make_serializer(msgdef: MsgDef, definitions: dict[str, MsgDef]) -> Callable:
    """Function ``(message, published=False) -> bytes``: the CDR (with header) of one message.

    ``published``: the message and everything in it stay as they are from now on (see
    ``serialize_published`` of the message classes).
    """
    writer = _CodeWriter()
    builder = _SerializerBuilder(definitions, writer)
    writer.emit(1, f'b = bytearray({_HEADER_LE!r})')
    builder.struct(1, msgdef, 'm', _Alignment())
    builder.flush()
    return _compile(writer, 'serialize', 'm, published=False', 'bytes(b)')


def make_deserializer(msgdef: MsgDef, definitions: dict[str, MsgDef],
                      classes: dict[str, type], order: str) -> Callable:
    """Function ``(data, p) -> (message, end)`` reading CDR data at offset ``p``."""
    writer = _CodeWriter()
    builder = _DeserializerBuilder(definitions, classes, writer, order)
    builder.struct(1, msgdef, 'o', _Alignment())
    builder.flush()
    return _compile(writer, 'deserialize', 'd, p', '(o, p)')


def _field_annotation(field: FieldDef, classes: dict[str, type]):
    if field.is_primitive:
        base = _IDL_PRIMITIVES[field.base_type]
    elif field.is_string:
        base = idl_types.bounded_str[field.string_bound] if field.string_bound else str
    else:
        base = classes[field.base_type]
    if field.container == 'array':
        return idl_types.array[base, field.size]
    if field.container == 'sequence':
        return idl_types.sequence[base, field.size] if field.size else idl_types.sequence[base]
    return base


def _scalar_default(field: FieldDef, classes: dict[str, type]):
    if field.default is not None:
        return field.default
    if field.is_string:
        return ''
    if field.is_primitive:
        return _ZERO.get(field.base_type, 0)
    return classes[field.base_type]


def _field_default(field: FieldDef, classes: dict[str, type]) -> dataclasses.Field:
    if field.container is None:
        value = _scalar_default(field, classes)
        if isinstance(value, type):
            return dataclasses.field(default_factory=value)
        return dataclasses.field(default=value)
    if field.container == 'array':
        if field.default is not None:
            values = list(field.default)
            return dataclasses.field(default_factory=lambda: list(values))
        element = _scalar_default(field, classes)
        if isinstance(element, type):
            size = field.size
            return dataclasses.field(default_factory=lambda: [element() for _ in range(size)])
        return dataclasses.field(default_factory=lambda: [element] * field.size)
    if field.base_type == 'uint8':
        initial = bytes(field.default or b'')
        return dataclasses.field(default_factory=lambda: initial)
    values = list(field.default or [])
    return dataclasses.field(default_factory=lambda: list(values))


def make_class(msgdef: MsgDef, definitions: dict[str, MsgDef], classes: dict[str, type]) -> type:
    """Create the message class of ``msgdef``; its dependencies must be in ``classes``.

    The class is registered in ``classes`` before its CDR functions are generated.
    """
    package, _, name = msgdef.type_name.split('/')
    bases = (IdlStruct,)
    namespace = IdlMeta.__prepare__(name, bases, typename=dds_type_name(msgdef.type_name))
    for field in msgdef.fields:
        namespace['__annotations__'][field.name] = _field_annotation(field, classes)
        namespace[field.name] = _field_default(field, classes)
    for constant in msgdef.constants:
        namespace[constant.name] = constant.value
    namespace['__module__'] = f'gait_nodes.interfaces.{package}.msg'
    namespace['__qualname__'] = name
    namespace['__ros_type__'] = msgdef.type_name
    namespace['__msgdef__'] = msgdef
    cls = dataclasses.dataclass(final(IdlMeta(name, bases, namespace)))
    classes[msgdef.type_name] = cls

    serialize_fn = make_serializer(msgdef, definitions)
    readers = {
        b'\x01': make_deserializer(msgdef, definitions, classes, '<'),
        b'\x00': make_deserializer(msgdef, definitions, classes, '>'),
    }

    errors = (struct.error, ValueError, TypeError, AttributeError, UnicodeError, OverflowError)

    def serialize(self, buffer=None, endianness=None, use_version_2=None) -> bytes:
        """CDR bytes of this message with the 4-byte encapsulation header."""
        try:
            return serialize_fn(self)
        except errors as exc:
            raise SerializationError(f'cannot serialize {msgdef.type_name}: {exc}') from exc

    def serialize_published(self) -> bytes:
        """:meth:`serialize` of a message published under the inproc runtime's rule.

        The rule (a published message and its parts are never edited again, see
        :mod:`gait_nodes.runtime.inproc`) lets a sequence of flat structs that was packed for
        an earlier published message, the very same object, be copied from then rather than
        packed again. The bytes are those of :meth:`serialize` as long as the rule holds.
        """
        try:
            return serialize_fn(self, True)
        except errors as exc:
            raise SerializationError(f'cannot serialize {msgdef.type_name}: {exc}') from exc

    @classmethod
    def deserialize(cls_, data, has_header=True, use_version_2=None):
        """Message from CDR bytes (with the encapsulation header)."""
        view = memoryview(data)
        if len(view) < 4 or view[0] != 0 or bytes(view[1:2]) not in readers:
            raise SerializationError(
                f'cannot deserialize {msgdef.type_name}: not plain CDR '
                f'(header {bytes(view[:4]).hex() or "missing"}, expected 0001 or 0000)')
        try:
            message, end = readers[bytes(view[1:2])](view, 4)
        except (struct.error, ValueError, UnicodeError, IndexError) as exc:
            raise SerializationError(
                f'cannot deserialize {msgdef.type_name} from {len(view)} bytes: {exc}') from exc
        if end > len(view):
            raise SerializationError(
                f'cannot deserialize {msgdef.type_name}: data ends at byte {len(view)}, '
                f'message needs {end}')
        return message

    cls.serialize = serialize
    cls.serialize_published = serialize_published
    cls.deserialize = deserialize
    return cls
