"""ROS 2 names as rcl expands and checks them: topics, namespaces, fully qualified node names.

``expand_topic_name('gait/footsteps', 'whole_body_ik', '/robot1')`` is
``'/robot1/gait/footsteps'``: a relative name goes under the node's namespace, an absolute one
(``/tf``) stays, ``~`` is the node's own fully qualified name (``~/state`` is
``/robot1/whole_body_ik/state``), and ``{node}``, ``{ns}``/``{namespace}`` are substituted
(rcl_expand_topic_name, rmw_validate_full_topic_name, jazzy). Remapping comes after expansion
and is the node's (:class:`gait_nodes.runtime.node.Node`).
"""

from __future__ import annotations

import re

from gait_nodes.errors import GaitNodesError

_TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')
#: What rcl_validate_topic_name lets through before expansion.
_TOPIC_CHARACTERS = re.compile(r'[A-Za-z0-9_/~{}]+')
_SUBSTITUTION = re.compile(r'\{([^{}]*)\}')


class InvalidTopicNameError(GaitNodesError):
    """A topic name that rcl would refuse (rclpy raises InvalidTopicNameException)."""


def fully_qualified_node_name(node_name: str, namespace: str) -> str:
    """``/namespace/node_name`` (``/node_name`` in the root namespace)."""
    return namespace.rstrip('/') + '/' + node_name


def validate_full_topic_name(name: str) -> str:
    """Return ``name`` if it is a valid fully qualified topic name; raise with the reason."""
    if not name.startswith('/'):
        raise InvalidTopicNameError(f'topic name {name!r} is not absolute')
    if name == '/' or name.endswith('/'):
        raise InvalidTopicNameError(f'topic name {name!r} must not end with "/"')
    for token in name[1:].split('/'):
        if not token:
            raise InvalidTopicNameError(f'topic name {name!r} must not contain "//"')
        if not _TOKEN.fullmatch(token):
            raise InvalidTopicNameError(
                f'topic name {name!r}: {token!r} is not a name token (letters, digits and '
                f'underscores, not starting with a digit)')
    return name


def expand_topic_name(topic: str, node_name: str, namespace: str) -> str:
    """The fully qualified name of ``topic`` for a node ``node_name`` in ``namespace``.

    Raises:
        InvalidTopicNameError: ``topic`` is empty, malformed (``~`` not followed by ``/``, an
            unknown substitution, a token starting with a digit...) or expands to an invalid
            name.
    """
    if not topic:
        raise InvalidTopicNameError('topic name must not be empty')
    if not _TOPIC_CHARACTERS.fullmatch(topic):
        raise InvalidTopicNameError(
            f'topic name {topic!r} has characters other than letters, digits, "_", "/", "~" '
            f'and substitutions')
    if '~' in topic[1:] or topic.startswith('~') and topic != '~' \
            and not topic.startswith('~/'):
        raise InvalidTopicNameError(f'topic name {topic!r}: "~" may only start the name, '
                                    f'alone or followed by "/"')
    values = {'node': node_name, 'ns': namespace, 'namespace': namespace}

    def substitute(match: re.Match) -> str:
        if match.group(1) not in values:
            raise InvalidTopicNameError(f'topic name {topic!r}: unknown substitution '
                                        f'{match.group(0)!r} (known: {{node}}, {{ns}}, '
                                        f'{{namespace}})')
        return values[match.group(1)]

    name = _SUBSTITUTION.sub(substitute, topic)
    if '{' in name or '}' in name:
        raise InvalidTopicNameError(f'topic name {topic!r}: unbalanced braces')
    if name.startswith('~'):
        name = fully_qualified_node_name(node_name, namespace) + name[1:]
    elif not name.startswith('/'):
        name = namespace.rstrip('/') + '/' + name
    if name.startswith('//'):  # '{ns}/x' in the root namespace
        name = name[1:]
    return validate_full_topic_name(name)
