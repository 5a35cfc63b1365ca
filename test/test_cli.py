"""Command lines: ``python -m gait_nodes run`` and node entry points built with ``run_node``.

Bad input must end with exit status 2 and one line on stderr, never a traceback.
"""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

#: A node entry point as every gait node writes one: a class and ``run_node``.
GAIN_NODE = """\
    import sys

    from gait_nodes import runtime
    from gait_nodes.cli import run_node


    class GainNode(runtime.Node):
        \"\"\"Declares one float parameter and prints it.\"\"\"

        def __init__(self):
            super().__init__('gain_node')
            gain = self.declare_parameter('gain', 1.0).value
            print(f'gain={gain!r}', flush=True)


    if __name__ == '__main__':
        sys.exit(run_node(lambda options: GainNode(), prog='gain_node',
                          description='A node with one float parameter, gain.'))
    """


def env_with(**values: str) -> dict[str, str]:
    env = dict(os.environ)
    env.pop('GAIT_NODES_RUNTIME', None)
    env['PYTHONPATH'] = str(REPO)
    env.update(values)
    return env


def run(args: list[str], *, cwd: Path, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env_with(**env),
                          capture_output=True, text=True, timeout=60)


def assert_bad_input(result: subprocess.CompletedProcess, *words: str) -> None:
    """Exit 2, exactly one line on stderr naming the problem, no traceback."""
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert 'Traceback' not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert 'error' in lines[0]
    for word in words:
        assert word in lines[0]


@pytest.fixture
def gain_node(tmp_path) -> Path:
    path = tmp_path / 'gain_node.py'
    path.write_text(textwrap.dedent(GAIN_NODE))
    return path


def test_run_inproc_prints_a_summary(tmp_path):
    result = run(['-m', 'gait_nodes', 'run', '--fast', '--duration', '2'], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr
    assert 'runtime inproc' in result.stdout
    assert 'simulated 2.00 s' in result.stdout


def test_run_inproc_json_summary(tmp_path):
    import json

    result = run(['-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--duration', '1.5',
                  '--json'], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary['runtime'] == 'inproc'
    assert summary['simulated_s'] == 1.5
    assert summary['exit_codes'] == {}


def test_run_inproc_records_inspects_and_plots(tmp_path):
    """The main job's shape: the graph recorded, the gait summary printed, the PNGs written."""
    result = run(['-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--duration', '3',
                  '--scenario', 'robosimian_crawl_polynomial', '--record', 'bags/r1'],
                 cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    bag = tmp_path / 'bags' / 'r1'
    assert (bag / 'metadata.yaml').is_file()
    assert 'metadata.yaml matches' in result.stdout
    assert 'ZMP margin' in result.stdout
    plots = sorted((tmp_path / 'bags' / 'r1_plots').glob('*.png'))
    assert {p.name for p in plots} >= {'top_view.png', 'com_zmp_time.png',
                                       'joint_velocities.png'}
    for plot in plots:
        assert plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
        assert str(plot) in result.stdout

    result = run(['-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--duration', '0.5',
                  '--record', 'bags/r2', '--no-plot'], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert not (tmp_path / 'bags' / 'r2_plots').exists()


@pytest.mark.parametrize(('args', 'env', 'words'), [
    (['--runtime', 'bogus'], {}, ['bogus']),
    ([], {'GAIT_NODES_RUNTIME': 'bogus'}, ['bogus', 'inproc']),
    (['--runtime', 'inproc', '--duration', '-1'], {}, ['-1']),
    (['--runtime', 'inproc', '--duration', 'soon'], {}, ['soon']),
    (['--runtime', 'inproc', '--duration', 'nan'], {}, ['nan']),
    (['--runtime', 'inproc', '--nodes', 'teleporter'], {}, ['teleporter']),
    (['--fast', '--runtime', 'dds'], {}, ['--fast', 'dds']),
    (['--fast', '--record', 'bad.yaml'], {}, ['bad.yaml', 'exists']),
    (['--fast', '--plot', 'p'], {}, ['--plot', '--record']),
    (['--fast', '--record', 'r', '--plot', 'p', '--no-plot'], {}, ['--plot', '--no-plot']),
    (['--runtime', 'inproc', '--ros-args', '--bogus'], {}, ['--bogus']),
    (['--runtime', 'inproc', '--ros-args', '-p', 'gain'], {}, ['gain']),
    (['--runtime', 'inproc', '--ros-args', '--params-file', 'missing.yaml'], {},
     ['missing.yaml']),
    (['--runtime', 'inproc', '--ros-args', '--params-file', 'bad.yaml'], {}, ['bad.yaml']),
    (['--runtime', 'inproc', '--ros-args', '--params-file', 'list.yaml'], {}, ['list.yaml']),
    (['--runtime', 'inproc', '--ros-args', '--params-file', 'binary.yaml'], {},
     ['binary.yaml']),
    (['--runtime', 'inproc', '--ros-args', '-p', 'robot:=[biped,'], {}, ['robot', 'line 1']),
    (['--runtime', 'rclpy'], {}, ['rclpy']),
    (['--no-such-option'], {}, ['--no-such-option']),
    (['--runtime', 'inproc', '--nodes', 'robot_state_publisher', '--no-state-publisher'], {},
     ['--no-state-publisher']),
], ids=['runtime-flag', 'runtime-env', 'negative-duration', 'word-duration', 'nan-duration',
        'unknown-node', 'fast-with-dds', 'record-exists', 'plot-without-record',
        'plot-and-no-plot', 'unknown-ros-flag',
        'param-without-value', 'missing-params-file',
        'bad-yaml-params-file', 'list-params-file', 'binary-params-file', 'bad-yaml-value',
        'rclpy-without-ros', 'unknown-option', 'state-publisher-and-not'])
def test_run_refuses_bad_input_on_one_line(tmp_path, args, env, words):
    (tmp_path / 'bad.yaml').write_text('/**: {ros__parameters: {robot: [biped}}\n')
    (tmp_path / 'list.yaml').write_text('- robot\n- biped\n')
    (tmp_path / 'binary.yaml').write_bytes(b'\xff\xfe\x00r\x00o\x00b\x00o\x00t')
    result = run(['-m', 'gait_nodes', 'run', *args], cwd=tmp_path, **env)
    assert_bad_input(result, *words)


def test_run_overrides_do_not_address_the_internal_monitor(tmp_path):
    # Only the monitor runs here; a graph-wide override is not its unknown parameter.
    result = run(['-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--nodes', '',
                  '--duration', '1', '--ros-args', '-p', 'robot:=biped'], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert 'runtime inproc' in result.stdout


def test_run_without_command_is_refused(tmp_path):
    assert_bad_input(run(['-m', 'gait_nodes'], cwd=tmp_path))


def test_node_entry_point_takes_a_parameter(tmp_path, gain_node):
    result = run([str(gain_node), '--ros-args', '-p', 'gain:=2.5'], cwd=tmp_path,
                 GAIT_NODES_RUNTIME='inproc')
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ['gain=2.5']


def test_node_entry_point_takes_a_params_file(tmp_path, gain_node):
    (tmp_path / 'gain.yaml').write_text('gain_node:\n  ros__parameters:\n    gain: 0.75\n')
    result = run([str(gain_node), '--runtime', 'inproc', '--ros-args', '--params-file',
                  'gain.yaml'], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ['gain=0.75']


@pytest.mark.parametrize(('ros_args', 'words'), [
    (['-p', 'gain:=abc'], ['gain', 'Wrong parameter type']),
    (['-p', 'nope:=1'], ['nope', 'gain']),
    (['--bogus'], ['--bogus']),
    (['--params-file', 'missing.yaml'], ['missing.yaml']),
    (['-p', 'gain:=[1.0,'], ['gain', 'line 1']),
], ids=['wrong-type', 'unknown-parameter', 'unknown-ros-flag', 'missing-params-file',
        'bad-yaml-value'])
def test_node_entry_point_refuses_bad_input_on_one_line(tmp_path, gain_node, ros_args, words):
    result = run([str(gain_node), '--ros-args', *ros_args], cwd=tmp_path,
                 GAIT_NODES_RUNTIME='inproc')
    assert_bad_input(result, 'gain_node', *words)


def test_node_entry_point_refuses_unknown_runtime(tmp_path, gain_node):
    assert_bad_input(run([str(gain_node), '--runtime', 'bogus'], cwd=tmp_path), 'bogus')
    assert_bad_input(run([str(gain_node)], cwd=tmp_path, GAIT_NODES_RUNTIME='bogus'), 'bogus')


def test_node_entry_point_help(tmp_path, gain_node):
    result = run([str(gain_node), '--help'], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert 'one float parameter' in result.stdout
    assert '--ros-args' in result.stdout or '-p name:=value' in result.stdout
    assert '--runtime' in result.stdout
    assert result.stderr == ''


def test_run_help(tmp_path):
    result = run(['-m', 'gait_nodes', 'run', '--help'], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert '--duration' in result.stdout and '--runtime' in result.stdout


def test_node_processes_get_one_blas_thread_unless_the_environment_says_otherwise():
    from gait_nodes.cli import NODE_ENVIRONMENT_DEFAULTS, node_environment

    environment = node_environment({'OMP_NUM_THREADS': '4', 'PATH': '/bin'}, EXTRA='x')
    assert environment['OPENBLAS_NUM_THREADS'] == environment['MKL_NUM_THREADS'] == '1'
    assert environment['OMP_NUM_THREADS'] == '4'  # the user's setting wins
    assert environment['PATH'] == '/bin' and environment['EXTRA'] == 'x'
    assert set(NODE_ENVIRONMENT_DEFAULTS) <= set(environment)


def test_run_refuses_a_record_directory_it_cannot_create_at_once(tmp_path):
    (tmp_path / 'a_file').write_text('not a directory\n')
    result = run(['-m', 'gait_nodes', 'run', '--fast', '--record', 'a_file/bag'], cwd=tmp_path)
    assert_bad_input(result, '--record a_file/bag', 'not a directory')
    assert 'gait_nodes run:' not in result.stdout  # refused before the graph started
    assert sorted(p.name for p in tmp_path.iterdir()) == ['a_file']


@pytest.mark.skipif(os.geteuid() == 0, reason='root writes in a read-only directory')
def test_run_refuses_a_record_directory_without_write_permission(tmp_path):
    locked = tmp_path / 'locked'
    locked.mkdir(mode=0o555)
    result = run(['-m', 'gait_nodes', 'run', '--fast', '--record', 'locked/bag'], cwd=tmp_path)
    assert_bad_input(result, '--record locked/bag', 'Permission denied')
    assert list(locked.iterdir()) == []


def test_run_with_plots_it_cannot_write_says_so_on_one_line_and_prints_the_summary(tmp_path):
    (tmp_path / 'a_file').write_text('not a directory\n')
    result = run(['-m', 'gait_nodes', 'run', '--fast', '--duration', '1', '--record', 'bag',
                  '--plot', 'a_file/plots'], cwd=tmp_path)
    assert result.returncode == 1, result.stderr
    assert 'Traceback' not in result.stderr
    errors = [line for line in result.stderr.splitlines() if 'error' in line]
    assert len(errors) == 1 and 'a_file/plots' in errors[0], result.stderr
    assert 'gait_nodes run:' in result.stdout and 'metadata.yaml matches' in result.stdout


def test_run_on_a_full_disk_keeps_what_was_recorded_and_prints_the_summary(tmp_path):
    """The run's files are limited to 100 kB (RLIMIT_FSIZE: writes past it fail, EFBIG)."""
    import resource

    def limit_file_size():
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    result = subprocess.run(
        [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--duration', '6',
         '--scenario', 'robosimian_crawl_polynomial', '--record', 'bag', '--no-plot'],
        cwd=tmp_path, env=env_with(), capture_output=True, text=True, timeout=120,
        preexec_fn=limit_file_size)
    assert result.returncode == 1, result.stderr
    assert 'Traceback' not in result.stderr
    assert 'File too large' in result.stderr  # the recorder's ERROR
    assert 'RECORDING STOPPED EARLY' in result.stdout and 'File too large' in result.stdout
    assert 'simulated 6.00 s' in result.stdout  # the walk went on to the end
    assert 'metadata.yaml matches' in result.stdout
    assert (tmp_path / 'bag' / 'metadata.yaml').is_file()
