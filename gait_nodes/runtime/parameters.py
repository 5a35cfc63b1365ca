"""ROS parameters as rclpy (jazzy) models them: typed at declaration, validated on every change."""

from __future__ import annotations

import dataclasses
import enum

from gait_nodes.errors import (
    InvalidParameterTypeError,
    ParameterError,
    ParameterNotDeclaredError,
)


class ParameterValueError(ParameterError):
    """An on-set callback rejected a value at declaration (InvalidParameterValueException)."""


class ParameterAlreadyDeclaredError(ParameterError):
    """A parameter was declared twice."""


@dataclasses.dataclass
class SetParametersResult:
    """Outcome of a parameter change, as ``rcl_interfaces/msg/SetParametersResult``."""

    successful: bool = False
    reason: str = ''


class Parameter:
    """A named, typed parameter value (mirrors ``rclpy.parameter.Parameter``)."""

    class Type(enum.IntEnum):
        """Parameter types, numbered as ``rcl_interfaces/msg/ParameterType``."""

        NOT_SET = 0
        BOOL = 1
        INTEGER = 2
        DOUBLE = 3
        STRING = 4
        BYTE_ARRAY = 5
        BOOL_ARRAY = 6
        INTEGER_ARRAY = 7
        DOUBLE_ARRAY = 8
        STRING_ARRAY = 9

        def __str__(self) -> str:
            # As rclpy's (an Enum there): 'Type.DOUBLE', not IntEnum's bare number.
            return f'Type.{self.name}'

        @classmethod
        def from_parameter_value(cls, value) -> Parameter.Type:
            """Type of a Python value; raise TypeError when no parameter type fits."""
            if value is None:
                return cls.NOT_SET
            if isinstance(value, bool):
                return cls.BOOL
            if isinstance(value, int):
                return cls.INTEGER
            if isinstance(value, float):
                return cls.DOUBLE
            if isinstance(value, str):
                return cls.STRING
            if isinstance(value, (bytes, bytearray)):
                return cls.BYTE_ARRAY
            if isinstance(value, (list, tuple)):
                if not value:
                    raise TypeError('an empty list has no parameter type: give the default a '
                                    'typed element or use a typed descriptor')
                for element_type, array_type in (
                    (bool, cls.BOOL_ARRAY), (int, cls.INTEGER_ARRAY),
                    (float, cls.DOUBLE_ARRAY), (str, cls.STRING_ARRAY),
                ):
                    if all(type(v) is element_type for v in value):
                        return array_type
                raise TypeError(f'list elements must all be bool, int, float or str: {value!r}')
            raise TypeError(f'value {value!r} of type {type(value).__name__} is not a valid '
                            'parameter value')

    def __init__(self, name: str, type_: Parameter.Type | None = None, value=None):
        if type_ is None:
            type_ = Parameter.Type.from_parameter_value(value)
        self._name = name
        self._type_ = Parameter.Type(type_)
        self._value = list(value) if isinstance(value, tuple) else value

    @property
    def name(self) -> str:
        """Parameter name."""
        return self._name

    @property
    def type_(self) -> Parameter.Type:
        """Parameter type."""
        return self._type_

    @property
    def value(self):
        """Parameter value."""
        return self._value

    def __repr__(self) -> str:
        return f'Parameter({self._name!r}, {self._type_.name}, {self._value!r})'

    def __eq__(self, other) -> bool:
        return (isinstance(other, Parameter) and self._name == other._name
                and self._type_ == other._type_ and self._value == other._value)


@dataclasses.dataclass
class ParameterDescriptor:
    """Subset of ``rcl_interfaces/msg/ParameterDescriptor`` used by gait_nodes."""

    name: str = ''
    type: int = 0
    description: str = ''
    additional_constraints: str = ''
    read_only: bool = False
    dynamic_typing: bool = False


class ParameterStore:
    """Declared parameters of one node, with overrides and on-set callbacks (dds/inproc)."""

    def __init__(self, node_name: str, overrides: dict[str, object],
                 allow_undeclared: bool = False, addressed: set[str] | None = None):
        self.node_name = node_name
        self.overrides = dict(overrides)
        self.addressed = set(overrides if addressed is None else addressed)
        self.allow_undeclared = allow_undeclared
        self.parameters: dict[str, Parameter] = {}
        self.descriptors: dict[str, ParameterDescriptor] = {}
        self.callbacks: list = []
        self.post_callbacks: list = []

    def declare(self, name: str, value=None, descriptor: ParameterDescriptor | None = None,
                ignore_override: bool = False) -> Parameter:
        """Declare a parameter (see ``Node.declare_parameter``)."""
        if name in self.parameters:
            raise ParameterAlreadyDeclaredError(
                f'{self.node_name}: parameter {name!r} is already declared')
        if isinstance(value, Parameter.Type):
            declared_type, value = value, None
        else:
            try:
                declared_type = Parameter.Type.from_parameter_value(value)
            except TypeError as exc:
                raise InvalidParameterTypeError(
                    f'{self.node_name}: parameter {name!r}: {exc}') from exc
        descriptor = dataclasses.replace(descriptor or ParameterDescriptor(), name=name)
        if not descriptor.dynamic_typing:
            descriptor.type = int(declared_type)
        if not ignore_override and name in self.overrides:
            value = self.overrides[name]
        try:
            parameter = Parameter(name, value=value)
        except TypeError as exc:
            raise InvalidParameterTypeError(
                f'{self.node_name}: parameter {name!r}: {exc}') from exc
        result = self._check([parameter], {name: descriptor})
        if not result.successful:
            if result.reason.startswith('Wrong parameter type'):
                raise InvalidParameterTypeError(
                    f'{self.node_name}: parameter {name!r} = {value!r}: {result.reason}')
            raise ParameterValueError(
                f'{self.node_name}: parameter {name!r} = {value!r} rejected: {result.reason}')
        self.descriptors[name] = descriptor
        self.parameters[name] = parameter
        for callback in self.post_callbacks:
            callback([parameter])
        return parameter

    def _check(self, parameters: list[Parameter],
               descriptors: dict[str, ParameterDescriptor]) -> SetParametersResult:
        for parameter in parameters:
            descriptor = descriptors[parameter.name]
            if descriptor.read_only and parameter.name in self.parameters:
                return SetParametersResult(
                    False, f'Trying to set a read-only parameter: {parameter.name}.')
            if (not descriptor.dynamic_typing and parameter.type_ != Parameter.Type.NOT_SET
                    and int(parameter.type_) != descriptor.type):
                return SetParametersResult(
                    False, f"Wrong parameter type, expected '{Parameter.Type(descriptor.type)}'"
                           f" got '{parameter.type_}'")
        for callback in self.callbacks:
            result = callback(parameters)
            if not result.successful:
                return result
        return SetParametersResult(True)

    def get(self, name: str) -> Parameter:
        """A declared parameter; raise when undeclared."""
        if name not in self.parameters:
            if self.allow_undeclared:
                return Parameter(name, Parameter.Type.NOT_SET, None)
            raise ParameterNotDeclaredError(
                f'{self.node_name}: parameter {name!r} is not declared; declared: '
                f'{", ".join(sorted(self.parameters)) or "none"}')
        return self.parameters[name]

    def set_atomically(self, parameters: list[Parameter]) -> SetParametersResult:
        """Apply all parameters or none; the result says why not."""
        for parameter in parameters:
            if parameter.name not in self.parameters and not self.allow_undeclared:
                raise ParameterNotDeclaredError(
                    f'{self.node_name}: parameter {parameter.name!r} is not declared; declared: '
                    f'{", ".join(sorted(self.parameters)) or "none"}')
        descriptors = {
            p.name: self.descriptors.get(p.name, ParameterDescriptor(name=p.name,
                                                                     dynamic_typing=True))
            for p in parameters
        }
        result = self._check(parameters, descriptors)
        if result.successful:
            for parameter in parameters:
                self.parameters[parameter.name] = parameter
                self.descriptors.setdefault(parameter.name, descriptors[parameter.name])
            for callback in self.post_callbacks:
                callback(parameters)
        return result

    def unused_overrides(self) -> list[str]:
        """Overrides addressed to this node that no declaration consumed."""
        return sorted(self.addressed - set(self.parameters))
