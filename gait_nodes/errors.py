"""The one exception hierarchy of gait_nodes.

Every error raised on bad input derives from :class:`GaitNodesError` and says what was wrong and,
where there is one, the allowed range, so that a command-line entry point can print it on one line
and exit with status 2.
"""


class GaitNodesError(Exception):
    """Base class of every error gait_nodes raises on purpose."""


class InterfaceError(GaitNodesError):
    """A message definition could not be parsed, or a message type is unknown."""


class SerializationError(GaitNodesError):
    """A message could not be converted to or from CDR bytes."""


class ArgumentError(GaitNodesError):
    """Command-line arguments (including ``--ros-args``) are malformed."""


class RuntimeSelectionError(GaitNodesError):
    """The requested runtime does not exist or cannot run on this machine."""


class ParameterError(GaitNodesError):
    """A ROS parameter declaration, override or params file is invalid."""


class ParameterNotDeclaredError(ParameterError):
    """A parameter was used or overridden without having been declared."""


class InvalidParameterTypeError(ParameterError):
    """A parameter value does not have the type fixed by its declaration."""


class ConfigError(GaitNodesError):
    """A configuration file (YAML, URDF, params file) was refused at load."""


class ComPlanningError(GaitNodesError):
    """A COM generator refused its settings or its input (e.g. no stabilizing Riccati solution).

    The message names the offending value and the allowed range.
    """


class GaitParameterError(ParameterError):
    """A gait parameter (command, ROS parameter or setting) is invalid or beyond the robot."""


class GaitCommandError(GaitParameterError):
    """A /gait/command message is not a valid command (JSON, schema, unknown key, type)."""


class SwingTableError(GaitNodesError):
    """A swing-leg value table was refused: corrupt file, another robot or joint limit, bad grid.

    The message names the file and what differs.
    """


class SwingPolicyError(GaitNodesError):
    """The swing-leg policy found no feasible swing (start or goal outside the table's region)."""


class TerrainError(ParameterError):
    """The footstep planner's terrain (a staircase) is invalid or does not suit the walk.

    Out of range, too short a tread for the foot and its swing, a swing method or COM method
    that cannot walk it, or ground moved under the feet; the message says which and the range.
    """


class LiveViewError(GaitNodesError):
    """The live view cannot serve: its port is taken, its host unknown, the Foxglove SDK missing.

    The message says what was wrong and what to do.
    """


def os_error_text(error: OSError) -> str:
    """An OSError on one line without the file name: ``[Errno 28] No space left on device``."""
    if error.errno is not None and error.strerror:
        return f'[Errno {error.errno}] {error.strerror}'
    return str(error) or type(error).__name__
