"""Where the shipped data lives: installed inside the package, or in the source tree."""

from __future__ import annotations

from pathlib import Path

from gait_nodes.errors import ConfigError

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """``msgs_schema`` or ``config``: the installed copy first, then the repository's."""
    for candidate in (_PACKAGE / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise ConfigError(f'{name}/ not found: looked in {_PACKAGE / name} and '
                      f'{_PACKAGE.parent / name}; reinstall gait_nodes')


def config_file(relative: str) -> Path:
    """A file under ``config/``; refused with its path when missing."""
    path = data_dir('config') / relative
    if not path.is_file():
        raise ConfigError(f'config file {path} not found')
    return path


def node_defaults(node_name: str) -> dict:
    """The ``ros__parameters`` of ``config/<node_name>.yaml``; refused with its path if bad."""
    import yaml

    path = config_file(f'{node_name}.yaml')
    try:
        return dict(yaml.safe_load(path.read_text())[node_name]['ros__parameters'])
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise ConfigError(f'{path}: cannot read the node defaults: {exc}') from exc
