"""ROS 2 command-line arguments (``--ros-args ... [--]``) and params files, parsed as rcl does.

Supported inside ``--ros-args``: ``-p/--param [node:]name:=value``, ``--params-file FILE``,
``-r/--remap [node:]from:=to`` (topics and ``__node``/``__ns``), ``--log-level [logger:=]LEVEL``,
and the flags rcl accepts without effect here (``--enclave``, ``--disable-*-logs``).
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import yaml

from gait_nodes.errors import ArgumentError, ParameterError

LOG_LEVELS = ('debug', 'info', 'warn', 'error', 'fatal')
#: rcl's name rules: a node name is one token; a namespace or topic name is tokens joined by '/'
#: (a topic may start with '~/', a namespace or topic with '/'); a token is letters, digits and
#: underscores, not starting with a digit, and no '/' repeats or ends a name but the root.
_TOKEN = r'[A-Za-z_][A-Za-z0-9_]*'
_NODE_NAME = re.compile(_TOKEN)
_NAMESPACE = re.compile(rf'/|/?{_TOKEN}(/{_TOKEN})*')
_TOPIC_NAME = re.compile(rf'(/|~/)?{_TOKEN}(/{_TOKEN})*|~')


class _RclYamlLoader(yaml.SafeLoader):
    """YAML as rcl reads parameter values (``rcl_yaml_param_parser``'s ``get_value``).

    An unquoted scalar is a bool if it is one of rcl's words (``y``, ``yes``, ``true``, ``on``
    and their capitalized forms, and their negatives), else an integer if C's ``strtol`` (base
    0: ``0x1f``, ``017``) reads all of it without overflow, else a double if ``strtod`` does
    (``1e-8``, ``1.``, ``inf``, ``nan``, ``0x1p3``, and YAML's ``.inf``/``.nan``), else a string:
    no timestamps (``2024-01-01`` stays a string), no YAML 1.1 floats that need a dot
    (``1e-8`` is a double, as under rclpy), no ``1_000`` or ``1:30`` numbers.
    """


_RCL_TRUE = ('Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on', 'On', 'ON')
_RCL_FALSE = ('N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE', 'off', 'Off', 'OFF')
_RCL_INT = re.compile(r'[-+]?(?:0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)\Z')
_RCL_FLOAT = re.compile(
    r'[-+]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?'
    r'|0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][-+]?[0-9]+)?'
    r'|(?i:inf|infinity|nan))\Z'
    r'|\.(?:nan|NaN|NAN)\Z|[-+]?\.(?:inf|Inf|INF)\Z')
_RCL_TYPED = {'tag:yaml.org,2002:bool', 'tag:yaml.org,2002:int', 'tag:yaml.org,2002:float',
              'tag:yaml.org,2002:timestamp'}
_RclYamlLoader.yaml_implicit_resolvers = {
    first: [(tag, regex) for tag, regex in resolvers if tag not in _RCL_TYPED]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_RclYamlLoader.add_implicit_resolver(
    'tag:yaml.org,2002:bool', re.compile('|'.join(f'{w}\\Z' for w in _RCL_TRUE + _RCL_FALSE)),
    list('YyNnTtFfOo'))
_RclYamlLoader.add_implicit_resolver('tag:yaml.org,2002:int', _RCL_INT, list('-+0123456789'))
_RclYamlLoader.add_implicit_resolver('tag:yaml.org,2002:float', _RCL_FLOAT,
                                     list('-+.0123456789iInN'))


def _rcl_bool(loader, node) -> bool:
    return loader.construct_scalar(node) in _RCL_TRUE


def _rcl_int(loader, node) -> int | float:
    """The value C's strtol reads; out of int64's range it fails, and strtod reads it."""
    text = loader.construct_scalar(node)
    digits = text.lstrip('+-')
    value = int(digits, 8) if len(digits) > 1 and digits[0] == '0' and digits[1] in '01234567' \
        else int(digits, 0)
    value = -value if text.startswith('-') else value
    return value if -2**63 <= value < 2**63 else float(value)


def _rcl_float(loader, node) -> float | str:
    """The value C's strtod reads; a literal beyond a double's range (ERANGE) stays a string."""
    text = loader.construct_scalar(node)
    bare = text.lstrip('+-')
    if bare.startswith('.') and bare[1:].lower() in ('inf', 'nan'):
        value = float(bare[1:])
    elif bare[:2] in ('0x', '0X'):
        value = float.fromhex(bare)
    else:
        value = float(bare)
    if math.isinf(value) and 'inf' not in bare.lower():
        return text
    return -value if text.startswith('-') else value


_RclYamlLoader.add_constructor('tag:yaml.org,2002:bool', _rcl_bool)
_RclYamlLoader.add_constructor('tag:yaml.org,2002:int', _rcl_int)
_RclYamlLoader.add_constructor('tag:yaml.org,2002:float', _rcl_float)


def _yaml_problem(exc: yaml.YAMLError) -> str:
    """One line saying what is wrong with a YAML text and where."""
    mark = getattr(exc, 'problem_mark', None)
    at = f' at line {mark.line + 1}, column {mark.column + 1}' if mark is not None else ''
    return f'{getattr(exc, "problem", None) or exc}{at}'


@dataclasses.dataclass
class RosArguments:
    """What ``--ros-args`` sections said, in command-line order."""

    params: list[tuple[str | None, str, object]] = dataclasses.field(default_factory=list)
    params_files: list[Path] = dataclasses.field(default_factory=list)
    remaps: list[tuple[str | None, str, str]] = dataclasses.field(default_factory=list)
    log_level: str | None = None
    #: ``(node pattern, parameters, params file)`` for each section of the params files.
    file_params: list[tuple[str, dict[str, object], Path]] = dataclasses.field(
        default_factory=list)

    def node_name(self, default: str) -> str:
        """Node name after ``__node:=`` remapping."""
        for node, source, target in self.remaps:
            if source in ('__node', '__name') and node in (None, default):
                return target
        return default

    def namespace(self, default: str | None, node_name: str | None = None) -> str:
        """Namespace after ``__ns:=`` (or ``node_name:__ns:=``) remapping, always absolute."""
        namespace = default or '/'
        for node, source, target in self.remaps:
            if source == '__ns' and node in (None, node_name):
                namespace = target
        return namespace if namespace.startswith('/') else '/' + namespace

    def topic_remaps(self, node_name: str) -> dict[str, str]:
        """Topic remapping rules that apply to ``node_name``."""
        rules = {}
        for node, source, target in self.remaps:
            if source.startswith('__') or node not in (None, node_name):
                continue
            rules[source] = target
        return rules

    def overrides_for(self, node_name: str, namespace: str = '/'
                      ) -> tuple[dict[str, object], set[str]]:
        """Parameter overrides of one node: params files in order, then ``-p`` values.

        Returns:
            The overrides, and the names among them that were addressed to this node in
            particular (``-p`` and params-file sections without wildcards): those must be
            declared by the node, while wildcard sections may hold other nodes' parameters.
        """
        overrides: dict[str, object] = {}
        addressed: set[str] = set()
        for pattern, values, _ in self._sections_for(node_name, namespace):
            overrides.update(values)
            if '*' not in pattern:
                addressed.update(values)
        for node, name, value in self.params:
            if node in (None, node_name):
                overrides[name] = value
                addressed.add(name)
        return overrides, addressed

    def override_sources(self, node_name: str, namespace: str = '/') -> dict[str, str]:
        """Where each override of one node comes from: ``params file PATH`` or ``-p``."""
        sources = {}
        for _, values, path in self._sections_for(node_name, namespace):
            sources.update(dict.fromkeys(values, f'params file {path}'))
        for node, name, _ in self.params:
            if node in (None, node_name):
                sources[name] = f'-p {name}:=...'
        return sources

    def _sections_for(self, node_name: str, namespace: str):
        full_name = (namespace.rstrip('/') + '/' + node_name) if namespace != '/' else (
            '/' + node_name)
        return [section for section in self.file_params
                if node_pattern_matches(section[0], full_name)]


def unknown_parameters_message(node: str, unknown: list[str], sources: dict[str, str],
                               accepted: list[str]) -> str:
    """One line refusing the ``unknown`` overrides of ``node``, with their sources.

    Args:
        node: The node's fully qualified name.
        unknown: The names it does not declare.
        sources: Where each override comes from (:meth:`RosArguments.override_sources`).
        accepted: The names it declares.
    """
    names = ', '.join(f'{name!r} ({sources[name]})' if name in sources else repr(name)
                      for name in unknown)
    return (f'{node}: unknown parameter{"s" if len(unknown) > 1 else ""} {names}; {node} '
            f'accepts: {", ".join(accepted) or "none"}')


def parse_value(text: str) -> object:
    """A parameter value from its command-line text, read as YAML the way rcl reads it."""
    try:
        value = yaml.load(text, Loader=_RclYamlLoader) if text.strip() else ''
    except yaml.YAMLError as exc:
        raise ArgumentError(
            f'cannot parse parameter value {text!r}: {_yaml_problem(exc)}') from exc
    if value is None:
        return text
    return value


def _split_assignment(text: str, flag: str) -> tuple[str | None, str, str]:
    if ':=' not in text:
        raise ArgumentError(f'{flag} expects [node:]name:=value, got {text!r}')
    left, right = text.split(':=', 1)
    node = None
    if ':' in left:
        node, left = left.split(':', 1)
    if not left:
        raise ArgumentError(f'{flag} expects [node:]name:=value, got {text!r}')
    return node, left, right


def _check_remap(flag: str, source: str, target: str) -> None:
    """Refuse a remap whose target rcl would not take as a node name, namespace or topic."""
    if source in ('__node', '__name'):
        rule, what = _NODE_NAME, ('a node name: letters, digits and underscores, not starting '
                                  'with a digit')
    elif source == '__ns':
        rule, what = _NAMESPACE, ("a namespace: '/' or names of letters, digits and "
                                  "underscores joined by '/'")
    else:
        rule, what = _TOPIC_NAME, ("a topic name: names of letters, digits and underscores "
                                   "joined by '/', optionally after '/' or '~/'")
    if not rule.fullmatch(target):
        raise ArgumentError(f'{flag} {source}:={target}: {target!r} is not {what}')


def absolute_namespace(namespace: str, flag: str = '--namespace') -> str:
    """``namespace`` as rcl takes it for ``__ns`` and made absolute; ArgumentError if not one."""
    _check_remap(flag, '__ns', namespace)
    return namespace if namespace.startswith('/') else '/' + namespace


def split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """Separate ROS arguments (``--ros-args`` sections) from the rest, like rcl does."""
    user, ros = [], []
    in_ros = False
    for arg in argv:
        if arg == '--ros-args':
            in_ros = True
            continue
        if in_ros and arg == '--':
            in_ros = False
            continue
        (ros if in_ros else user).append(arg)
    return user, ros


def parse_ros_args(ros: list[str]) -> RosArguments:
    """Parse the contents of ``--ros-args`` sections; raise ArgumentError on anything unknown."""
    parsed = RosArguments()
    i = 0

    def operand(flag: str) -> str:
        nonlocal i
        i += 1
        if i >= len(ros):
            raise ArgumentError(f'{flag} expects an argument')
        return ros[i]

    while i < len(ros):
        arg = ros[i]
        if arg in ('-p', '--param'):
            node, name, text = _split_assignment(operand(arg), arg)
            try:
                value = parse_value(text)
            except ArgumentError as exc:
                raise ArgumentError(f'{arg} {name}: {exc}') from exc
            parsed.params.append((node, name, value))
        elif arg == '--params-file':
            path = Path(operand(arg))
            parsed.params_files.append(path)
            parsed.file_params.extend((pattern, values, path)
                                      for pattern, values in load_params_file(path))
        elif arg in ('-r', '--remap'):
            node, source, target = _split_assignment(operand(arg), arg)
            _check_remap(arg, source, target)
            parsed.remaps.append((node, source, target))
        elif arg == '--log-level':
            level = operand(arg)
            if ':=' in level:
                level = level.split(':=', 1)[1]
            if level.lower() not in LOG_LEVELS:
                raise ArgumentError(
                    f'--log-level {level!r}: choose one of {", ".join(LOG_LEVELS)}')
            parsed.log_level = level.lower()
        elif arg in ('-e', '--enclave'):
            operand(arg)
        elif arg in ('--disable-rosout-logs', '--disable-stdout-logs',
                     '--disable-external-lib-logs', '--enable-rosout-logs',
                     '--enable-stdout-logs', '--enable-external-lib-logs'):
            pass
        else:
            raise ArgumentError(
                f'unknown ROS argument {arg!r}: expected -p, --params-file, -r, --log-level')
        i += 1
    return parsed


def _flatten(prefix: str, values: dict, where: str) -> dict[str, object]:
    flat: dict[str, object] = {}
    for key, value in values.items():
        if not isinstance(key, str) or not re.fullmatch(r'[A-Za-z_][\w]*', key):
            raise ParameterError(f'{where}: invalid parameter name {key!r}')
        name = f'{prefix}.{key}' if prefix else key
        if isinstance(value, dict):
            flat.update(_flatten(name, value, where))
            continue
        _check_value(name, value, where)
        flat[name] = value
    return flat


def _check_value(name: str, value: object, where: str) -> None:
    if value is None:
        raise ParameterError(f'{where}: parameter {name!r} has no value')
    if isinstance(value, list):
        if not value:
            return
        kinds = {type(v) for v in value}
        if len(kinds) != 1 or kinds.pop() not in (bool, int, float, str):
            raise ParameterError(
                f'{where}: parameter {name!r}: a list must hold values of one type '
                f'(bool, int, float or str), got {value!r}')
    elif not isinstance(value, (bool, int, float, str)):
        raise ParameterError(
            f'{where}: parameter {name!r}: unsupported value {value!r} '
            '(bool, int, float, str or a list of one of them)')
    if isinstance(value, float) and math.isnan(value):
        return


def load_params_file(path: Path) -> list[tuple[str, dict[str, object]]]:
    """Read a ROS 2 params file: ``node_name: {ros__parameters: {...}}`` (``/**`` allowed).

    Returns:
        ``(node pattern, flattened parameters)`` in file order.

    Raises:
        ParameterError: With the path and the reason, when the file is unreadable or malformed.
    """
    where = f'params file {path}'
    try:
        text = Path(path).read_text(encoding='utf-8')
    except OSError as exc:
        raise ParameterError(f'{where}: cannot read: {exc.strerror or exc}') from exc
    except UnicodeDecodeError as exc:
        raise ParameterError(
            f'{where}: not UTF-8 text: {exc.reason} at byte {exc.start}') from exc
    try:
        document = yaml.load(text, Loader=_RclYamlLoader)
    except yaml.YAMLError as exc:
        raise ParameterError(f'{where}: not valid YAML: {_yaml_problem(exc)}') from exc
    if not isinstance(document, dict) or not document:
        raise ParameterError(f'{where}: expected a mapping of node names to '
                             "{ros__parameters: {...}}, got " + type(document).__name__)
    sections = []
    for node, body in _node_sections(document, '', where):
        sections.append((node, body))
    return sections


def _node_sections(document: dict, prefix: str, where: str):
    for key, body in document.items():
        if not isinstance(key, str):
            raise ParameterError(f'{where}: node name must be a string, got {key!r}')
        name = f'{prefix}/{key.lstrip("/")}' if prefix else key
        if not isinstance(body, dict):
            raise ParameterError(f'{where}: section {name!r} must be a mapping containing '
                                 f'ros__parameters, got {body!r}')
        if 'ros__parameters' in body:
            params = body['ros__parameters']
            if params is None:
                params = {}
            if not isinstance(params, dict):
                raise ParameterError(
                    f'{where}: {name}.ros__parameters must be a mapping, got {params!r}')
            extra = set(body) - {'ros__parameters'}
            if extra:
                raise ParameterError(
                    f'{where}: section {name!r} has keys {sorted(extra)} beside ros__parameters')
            yield name, _flatten('', params, f'{where}: {name}')
        else:
            # A namespace level: /ns: {node: {ros__parameters: ...}}
            yield from _node_sections(body, name, where)


def node_pattern_matches(pattern: str, full_name: str) -> bool:
    """Whether a params-file key (``/**``, ``node``, ``/ns/node``, ``/*/node``) names a node.

    As rclpy matches them (jazzy, ``_populate_node_parameters_from_rcl_params``): a key is a
    fully qualified name, ``/`` prepended when it has none, so ``node`` names ``/node`` only
    and ``/**/node`` a node of that name in any namespace.
    """
    if not pattern.startswith('/'):
        pattern = '/' + pattern
    regex = ''
    for part in re.split(r'(/\*\*|\*)', pattern):
        if part == '/**':
            regex += r'(/[^/]+)*'
        elif part == '*':
            regex += r'[^/]*'
        else:
            regex += re.escape(part)
    return re.fullmatch(regex, full_name) is not None
