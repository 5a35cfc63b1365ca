"""A Foxglove WebSocket server that relays ROS 2 messages as the CDR bytes they travel as.

No ROS import here: the live view node (:mod:`gait_nodes.view`) hands over the serialized
messages it takes from the graph. Each topic is a Foxglove channel with message encoding
``cdr`` and a ``ros2msg`` schema named ``pkg/msg/Name`` whose text is the one rosbag2 writes in
MCAP (the definition, then each dependency after a line of 80 ``=``), so that Foxglove decodes
the live stream as it decodes our bags. The server is the ``foxglove-sdk`` package's: it speaks
the Foxglove WebSocket protocol under the subprotocol name ``foxglove.sdk.v1``.
"""

from __future__ import annotations

import errno
import socket

from gait_nodes.errors import LiveViewError, os_error_text

#: Foxglove's own default port.
DEFAULT_PORT = 8765
#: This machine only; ``--host 0.0.0.0`` serves every interface.
DEFAULT_HOST = '127.0.0.1'
MESSAGE_ENCODING = 'cdr'
SCHEMA_ENCODING = 'ros2msg'
_PORT_RANGE = (0, 65535)


def import_sdk():
    """The foxglove-sdk package's ``foxglove`` module; a LiveViewError says how to install it."""
    try:
        import foxglove
        import foxglove.websocket  # noqa: F401  (the server's listener protocol)
    except ImportError as exc:
        raise LiveViewError(
            f'the live view needs the Foxglove SDK ({exc}): pip install "foxglove-sdk" '
            f'(or the extra: pip install "gait_nodes[view]")') from None
    return foxglove


def check_port(port: int, option: str = '--port') -> int:
    """``port`` if it is a TCP port number (0: any free port), else LiveViewError."""
    low, high = _PORT_RANGE
    if isinstance(port, bool) or not isinstance(port, int) or not low <= port <= high:
        raise LiveViewError(f'{option} must be a TCP port in [{low}, {high}] (0: any free '
                            f'port), got {port!r}')
    return port


def parse_address(text: str, option: str = '--view') -> tuple[str, int]:
    """``'8765'`` -> ``(DEFAULT_HOST, 8765)``; ``'0.0.0.0:8765'`` -> ``('0.0.0.0', 8765)``.

    Args:
        text: ``PORT`` or ``HOST:PORT``.
        option: The option that gave it, for the error message.
    """
    host, _, port_text = text.rpartition(':')
    try:
        port = int(port_text)
    except ValueError:
        raise LiveViewError(f'{option} takes PORT or HOST:PORT (e.g. 8765 or 0.0.0.0:8765), '
                            f'got {text!r}') from None
    return host or DEFAULT_HOST, check_port(port, option)


def probe_port(host: str, port: int) -> OSError | None:
    """Why a TCP server cannot listen on ``host:port`` now (an OSError), or None if it can.

    The test is the real thing: a socket is bound there (with SO_REUSEADDR, as the SDK's
    server binds) and closed at once.
    """
    try:
        addresses = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except OSError as exc:  # socket.gaierror: an unknown host name
        return exc
    family, kind, protocol, _, address = addresses[0]
    try:
        with socket.socket(family, kind, protocol) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            probe.bind(address)
            probe.listen()
    except OSError as exc:
        return exc
    return None


def serve_error(host: str, port: int, reason: OSError | str,
                port_option: str = '--port') -> LiveViewError:
    """The error of a server that cannot listen on ``host:port``: what is wrong, what to do.

    Args:
        host: The host asked for.
        port: The port asked for.
        reason: The OSError of :func:`probe_port`, or the server's own error text.
        port_option: The option that chooses the port, named in the advice.
    """
    if isinstance(reason, socket.gaierror) or (
            isinstance(reason, OSError) and reason.errno == errno.EADDRNOTAVAIL):
        advice = ('the host is not a name or address of this machine: give one of its '
                  'addresses with --host (0.0.0.0 serves every interface)')
    elif isinstance(reason, OSError) and reason.errno == errno.EADDRINUSE:
        advice = (f'another program listens on port {port} (another live view, or a '
                  f'foxglove_bridge): stop it, or choose another port with {port_option} '
                  f'(0 picks a free one)')
    elif isinstance(reason, OSError) and reason.errno == errno.EACCES:
        advice = f'this user may not listen on port {port}: choose a port >= 1024'
    else:
        advice = f'choose another host or port ({port_option})'
    text = os_error_text(reason) if isinstance(reason, OSError) else reason
    return LiveViewError(f'cannot serve the live view on {host}:{port}: {text}; {advice}')


class FoxgloveRelay:
    """A Foxglove WebSocket server with one channel per ROS topic, fed serialized messages.

    Every channel is made before the server starts, so that a client gets them all when it
    connects. (The SDK advertises a channel added later to connected clients before it knows
    the channel itself: a client that subscribes at once is told ``Unknown channel ID``, as a
    quick one was in 2 of 6 tries on a busy machine with foxglove-sdk 0.30.) :meth:`forward`
    sends a message to the clients subscribed to its channel. The server runs on threads of
    the SDK; the methods may be called from one other thread (the node's executor).

    Args:
        topics: ``{topic: pkg/msg/Type}`` of the channels.
        host: Interface to listen on (a name or an address).
        port: TCP port (0: any free port; :attr:`port` is the one chosen).
        name: Server name shown by Foxglove.
        on_subscribe: ``f(topic)``, called on a server thread whenever a client subscribes to
            the channel of ``topic``; keep it short.
        port_option: The command-line option that chooses the port, for error messages.

    Raises:
        LiveViewError: The SDK is missing, the port is out of range, or the server cannot
            listen there (the port taken, an unknown host).
        InterfaceError: A type of ``topics`` is not known.
    """

    def __init__(self, topics: dict[str, str], host: str = DEFAULT_HOST,
                 port: int = DEFAULT_PORT, *, name: str = 'gait_nodes', on_subscribe=None,
                 port_option: str = '--port'):
        foxglove = import_sdk()
        check_port(port, port_option)
        self._server = None
        self._context = foxglove.Context()
        schemas = {type_name: ros2msg_schema(foxglove, type_name)
                   for type_name in set(topics.values())}
        self._channels = {
            topic: foxglove.Channel(topic, schema=schemas[type_name],
                                    message_encoding=MESSAGE_ENCODING, context=self._context)
            for topic, type_name in topics.items()}

        class Listener(foxglove.websocket.ServerListener):
            def on_subscribe(self, client, channel) -> None:
                if on_subscribe is not None:
                    on_subscribe(channel.topic)

        try:
            self._server = foxglove.start_server(name=name, host=host, port=port,
                                                 context=self._context,
                                                 server_listener=Listener())
        except RuntimeError as exc:  # the SDK's FoxgloveError text
            self.close()
            reason = probe_port(host, port) or str(exc).removeprefix('FoxgloveError: ')
            raise serve_error(host, port, reason, port_option) from None
        self.host = host
        #: The port listened on.
        self.port: int = self._server.port

    @property
    def url(self) -> str:
        """``ws://host:port`` as a Foxglove client opens it (localhost for every interface)."""
        host = 'localhost' if self.host in ('0.0.0.0', '::', '') else self.host
        if ':' in host:
            host = f'[{host}]'
        return f'ws://{host}:{self.port}'

    @property
    def topics(self) -> list[str]:
        """The topics of the channels."""
        return list(self._channels)

    def is_subscribed(self, topic: str) -> bool:
        """Whether a client subscribes to ``topic`` now."""
        channel = self._channels.get(topic)
        return channel is not None and channel.has_sinks()

    def forward(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send one serialized message (CDR with its 4-byte header) to ``topic``'s subscribers.

        Args:
            topic: One of :attr:`topics` (others are ignored, as everything once closed).
            data: The message's CDR bytes as they travel on DDS.
            log_time_ns: Receive time [ns], the message's time on Foxglove's timeline.
        """
        channel = self._channels.get(topic)
        if channel is not None:
            channel.log(bytes(data), log_time=log_time_ns)

    def close(self) -> None:
        """Stop the server (clients are disconnected) and close the channels. Safe twice."""
        server, self._server = self._server, None
        if server is not None:
            server.stop()
        channels, self._channels = self._channels, {}
        for channel in channels.values():
            channel.close()


def ros2msg_schema(foxglove, type_name: str):
    """The Foxglove ``Schema`` of ``pkg/msg/Name``: rosbag2's MCAP schema of that type.

    Args:
        foxglove: The SDK's module (:func:`import_sdk`).
        type_name: A message type of ``msgs_schema/``.
    """
    from gait_nodes.interfaces import definition_text

    return foxglove.Schema(name=type_name, encoding=SCHEMA_ENCODING,
                           data=definition_text(type_name).encode())
