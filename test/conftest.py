"""Test-wide settings."""

import os

import pytest

# Every message published under inproc is checked as rclpy's setters would check it, so that node
# code passing here also runs on a real ROS 2 install (see gait_nodes.interfaces.validate_message).
os.environ.setdefault('GAIT_NODES_STRICT_MESSAGES', '1')
# One BLAS thread per process (this one and the node processes the tests start). The matrices
# are small; on two cores shared with a dds graph's processes, the OpenBLAS of Jazzy's numpy
# 1.26 (0.3.23) spends its extra threads spinning: a fifth more CPU for the same results.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
# MuJoCo renders the walks' videos offscreen: EGL (or OSMesa) on a machine without a display,
# where its library is installed (MuJoCo reads this once, when first imported by any test).
from gait_nodes.bag.video import prefer_headless_gl  # noqa: E402

prefer_headless_gl()


@pytest.fixture(scope='session')
def tiny_crossover(tmp_path_factory):
    """(folder, rows): every RoboSimian gait walked at 2.5 rad/s for 16 s, bags kept.

    The walked crossover (gait_nodes.walked_crossover) on a tiny setting: one limit, short
    walks, the polynomial swing (no value table to build); about 15 s.
    """
    from gait_nodes.walked_crossover import WALKED_WITH, walked_crossover

    folder = tmp_path_factory.mktemp('walked_crossover')
    settings = {**WALKED_WITH, 'swing': 'polynomial', 'step_height_m': 0.1}
    return folder, walked_crossover((2.5,), duration_at_1_rad_s=40.0, bags_dir=folder,
                                    settings=settings)


# -- running the suite on several workers (pytest-xdist, `-n auto --dist loadgroup`) ----------

#: Modules whose tests start node processes that walk in real time over DDS (or rclpy): one
#: worker runs them, one after the other, so that two graphs never share the cores; the other
#: workers' tests (inproc walks, unit tests) are the competing load they meet on a robot's
#: computer.
BETWEEN_PROCESSES = {
    'test_bags', 'test_command_cli', 'test_faults_dds', 'test_main_job_dds',
    'test_namespaces_dds', 'test_node_parameters', 'test_online_commands_dds', 'test_physics_dds',
    'test_rclpy_runtime', 'test_robot_state_publisher', 'test_runtime_dds', 'test_view',
}
#: Modules that share a session fixture (``tiny_crossover``): one worker computes it once.
SHARING = {'test_thesis': 'walked_crossover', 'test_walked_crossover': 'walked_crossover'}


def pytest_configure(config):
    config.addinivalue_line('markers', 'xdist_group(name): run on one pytest-xdist worker')
    config.addinivalue_line('markers', 'between_processes: starts node processes that walk in '
                            'real time (BETWEEN_PROCESSES)')


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Group the tests for ``--dist loadgroup``.

    A module's tests stay on one worker (its module-scoped fixtures are made once), and the
    real-time graphs all run on one. (First: pytest-xdist's worker reads the groups in its own
    hook, which would otherwise run before this one and find none.)
    """
    for item in items:
        module = item.module.__name__.rpartition('.')[2] if item.module else item.nodeid
        if module in BETWEEN_PROCESSES:
            item.add_marker(pytest.mark.between_processes)
            group = 'between_processes'
        else:
            group = SHARING.get(module, module)
        item.add_marker(pytest.mark.xdist_group(group))



def pytest_sessionstart(session):
    """Refuse to run ungrouped under a pytest that drops ``--dist loadgroup``'s groups.

    pytest-xdist up to 3.8 marks a test's group in its node id, which pytest 9.2 no longer
    reads (pytest-xdist issue #1386): the groups are dropped without a word, and two real-time
    graphs then share the cores. (The test extra keeps pytest below 9.2.)
    """
    from importlib.metadata import version

    config = session.config
    if (getattr(config, 'workerinput', None) is not None
            or config.getoption('dist', default=None) != 'loadgroup'):
        return
    pytest_version = tuple(int(part) for part in pytest.__version__.split('.')[:2])
    xdist_version = tuple(int(part) for part in version('pytest-xdist').split('.')[:2])
    if pytest_version >= (9, 2) and xdist_version <= (3, 8):
        raise pytest.UsageError(
            f'pytest {pytest.__version__} with pytest-xdist {version("pytest-xdist")} ignores '
            f'--dist loadgroup (pytest-xdist issue #1386): install the test extra again '
            f'(it keeps pytest below 9.2), e.g. sh tools/venv.sh')
