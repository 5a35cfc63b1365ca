"""Packaging: the ament_python metadata, and what an installed gait_nodes carries with it."""

import ast
import configparser
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

#: Message packages of the public topic contract, each a ROS exec_depend.
MESSAGE_PACKAGES = (
    'builtin_interfaces',
    'diagnostic_msgs',
    'geometry_msgs',
    'nav_msgs',
    'rosgraph_msgs',
    'sensor_msgs',
    'std_msgs',
    'tf2_msgs',
    'trajectory_msgs',
    'visualization_msgs',
)
#: Programs that get a console script (and a `ros2 run` executable) once their module exists.
PROGRAMS = (
    'footstep_planner',
    'com_preview_controller',
    'whole_body_ik',
    'swing_leg_policy',
    'kinematic_simulator',
    'physics_simulator',
    'robot_state_publisher',
    'recorder',
    'command',
    'inspect',
    'replay',
    'swing_table',
)

# Run in a fresh interpreter outside the repository, so that `import gait_nodes` finds the
# installed package and not the source tree that pytest puts on sys.path.
_PROBE = """
import importlib.metadata as md, json, sys
from pathlib import Path
import gait_nodes
from gait_nodes.interfaces.msgdef import schema_dir
dist = md.distribution('gait_nodes')
direct_url = json.loads(dist.read_text('direct_url.json') or '{}')
json.dump({
    'package_dir': str(Path(gait_nodes.__file__).resolve().parent),
    'schema_dir': str(schema_dir().resolve()),
    'version': dist.version,
    'editable': direct_url.get('dir_info', {}).get('editable', False),
    'files': {
        str(f).replace('\\\\', '/'): str(Path(f.locate()).resolve()) for f in dist.files or []
    },
    'console_scripts': {
        e.name: e.value for e in dist.entry_points if e.group == 'console_scripts'
    },
}, sys.stdout)
"""


@pytest.fixture(scope='module')
def package_xml():
    """Root element of package.xml."""
    return ET.parse(REPO / 'package.xml').getroot()


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """Facts about the gait_nodes installed in this interpreter, probed from outside the repo."""
    env = {key: value for key, value in os.environ.items() if key != 'PYTHONPATH'}
    probe = subprocess.run(
        [sys.executable, '-c', _PROBE],
        cwd=tmp_path_factory.mktemp('probe'),
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    if probe.returncode != 0:
        pytest.fail(
            f'gait_nodes is not importable as an installed package in {sys.executable} '
            f'(install it with `sh tools/venv.sh`):\n{probe.stderr}'
        )
    return json.loads(probe.stdout)


def _source_files(folder):
    """Files below the repository folder ``folder``, relative to it, as in setup.py."""
    root = REPO / folder
    return sorted(
        path.relative_to(root).as_posix()
        for path in root.rglob('*')
        if path.is_file()
        and '__pycache__' not in path.parts
        and not any(part.startswith('.') for part in path.relative_to(root).parts)
        and path.suffix not in ('.pyc', '.pyo')
    )


def _source_programs():
    """Programs whose module exists in the source tree."""
    source = REPO / 'gait_nodes'
    return sorted(
        name
        for name in PROGRAMS
        if (source / f'{name}.py').is_file() or (source / name / '__main__.py').is_file()
    )


def test_package_xml_is_format_3_ament_python(package_xml):
    assert package_xml.tag == 'package'
    assert package_xml.get('format') == '3'
    assert package_xml.findtext('name') == 'gait_nodes'
    assert package_xml.findtext('license') == 'Apache-2.0'
    assert package_xml.find('maintainer').get('email')
    assert package_xml.findtext('export/build_type') == 'ament_python'


def test_package_xml_depends_on_every_message_package(package_xml):
    exec_depends = {element.text for element in package_xml.findall('exec_depend')}
    shipped = {path.name for path in (REPO / 'msgs_schema' / 'msg').iterdir() if path.is_dir()}
    expected = set(MESSAGE_PACKAGES) | shipped | {'rclpy', 'launch', 'launch_ros', 'ros2launch'}
    assert expected - exec_depends == set()


def test_package_xml_and_installed_versions_agree(package_xml, installed):
    assert installed['version'] == package_xml.findtext('version')


def test_setup_cfg_puts_scripts_where_ros2_run_looks():
    config = configparser.ConfigParser(interpolation=None)
    config.read(REPO / 'setup.cfg', encoding='utf-8')
    assert config.get('develop', 'script_dir') == '$base/lib/gait_nodes'
    assert config.get('install', 'install_scripts') == '$base/lib/gait_nodes'


def test_launch_file_compiles_and_declares_its_arguments():
    path = REPO / 'launch' / 'gait.launch.py'
    tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
    compile(tree, str(path), 'exec')
    defaults = {
        call.args[0].value: next(
            ast.literal_eval(keyword.value)
            for keyword in call.keywords
            if keyword.arg == 'default_value'
        )
        for call in ast.walk(tree)
        if isinstance(call, ast.Call) and getattr(call.func, 'id', '') == 'DeclareLaunchArgument'
    }
    assert defaults == {
        'robot': 'robosimian',
        'gait': 'crawl',
        'swing': 'value_table',
        'simulator': 'kinematic',
        'use_sim_time': 'true',
        'record': '',
        'namespace': '',
        'state_publisher': 'true',
    }
    assert 'generate_launch_description' in {
        node.name for node in tree.body if isinstance(node, ast.FunctionDef)
    }


def test_source_tree_finds_message_definitions():
    from gait_nodes.interfaces.msgdef import schema_dir

    assert (schema_dir() / 'msg' / 'std_msgs' / 'String.msg').is_file()


def test_installed_package_finds_message_definitions(installed):
    schema = Path(installed['schema_dir'])
    assert (schema / 'msg' / 'std_msgs' / 'String.msg').is_file()
    missing = [name for name in _source_files('msgs_schema') if not (schema / name).is_file()]
    assert missing == []
    if not installed['editable']:
        # A regular install must use its own copy, not a source tree that happens to be nearby.
        assert schema == Path(installed['package_dir']) / 'msgs_schema'


def _skip_if_editable(installed):
    """Skip: editable installs run from the sources and setuptools gives them no share/ files."""
    if installed['editable']:
        pytest.skip('editable install: setuptools installs no share/ files; use `pip install .`')


@pytest.mark.parametrize('folder', ['msgs_schema', 'config'])
def test_data_folders_are_installed_in_the_package_and_in_share(installed, folder):
    _skip_if_editable(installed)
    missing_share = [
        name
        for name in _source_files(folder)
        if not any(key.endswith(f'share/gait_nodes/{folder}/{name}') for key in installed['files'])
    ]
    assert missing_share == []
    missing_package = [
        name
        for name in _source_files(folder)
        if not (Path(installed['package_dir']) / folder / name).is_file()
    ]
    assert missing_package == []


def test_ament_index_marker_package_xml_and_launch_files_are_installed(installed):
    _skip_if_editable(installed)
    files = installed['files']
    expected = [
        'share/ament_index/resource_index/packages/gait_nodes',
        'share/gait_nodes/package.xml',
        *(
            f'share/gait_nodes/launch/{name}'
            for name in _source_files('launch')
            if name.endswith('.launch.py')
        ),
    ]
    for suffix in expected:
        located = [path for key, path in files.items() if key.endswith(suffix)]
        assert located, f'{suffix} is not in the installed distribution'
        assert Path(located[0]).is_file()
    installed_xml = next(
        path for key, path in files.items() if key.endswith('share/gait_nodes/package.xml')
    )
    assert Path(installed_xml).read_bytes() == (REPO / 'package.xml').read_bytes()


def test_console_scripts_exist_exactly_for_the_modules_present(installed):
    scripts = installed['console_scripts']
    expected = set(_source_programs())
    if (REPO / 'gait_nodes' / '__main__.py').is_file():
        expected.add('gait_nodes')
    assert set(scripts) == expected
