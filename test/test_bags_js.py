"""An MCAP reader from another language: the Foxglove TypeScript libraries decode our bags.

Needs Node.js and npm (present on the Debian machines this project targets); the packages named
in test/js/package.json are installed once into a cache folder keyed by that file's hash.
Without node/npm, or without access to the npm registry, the test is skipped and says why.
"""

import hashlib
import json
import os
import shutil
import subprocess
from pathlib import Path

import gait_bag
import pytest

from gait_nodes.graph import TOPICS
from gait_nodes.interfaces import type_hash

JS = Path(__file__).parent / 'js'


def js_environment() -> Path:
    node, npm = shutil.which('node'), shutil.which('npm')
    if node is None or npm is None:
        pytest.skip('node and npm are not installed: the TypeScript reader cannot run')
    manifest = (JS / 'package.json').read_bytes()
    cache = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache')) / 'gait_nodes' / (
        'js-' + hashlib.sha256(manifest).hexdigest()[:16])
    if not (cache / 'node_modules' / '@mcap' / 'core').is_dir():
        cache.mkdir(parents=True, exist_ok=True)
        shutil.copy(JS / 'package.json', cache / 'package.json')
        result = subprocess.run([npm, 'install', '--no-audit', '--no-fund', '--silent'],
                                cwd=cache, capture_output=True, text=True, timeout=300)
        if result.returncode != 0:
            pytest.skip(f'npm install failed (no registry access?): {result.stderr[-300:]}')
    shutil.copy(JS / 'read_mcap.mjs', cache / 'read_mcap.mjs')
    return cache


def test_typescript_reader_decodes_every_message(tmp_path):
    bag = gait_bag.write_gait_bag(tmp_path / 'gait', chunk_size=8192)
    cache = js_environment()
    result = subprocess.run(['node', str(cache / 'read_mcap.mjs'), str(next(bag.glob('*.mcap')))],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    expected = {}
    for topic, _, _ in gait_bag.messages():
        expected[topic] = expected.get(topic, 0) + 1
    assert summary['profile'] == 'ros2'
    assert summary['decoded'] == sum(expected.values())
    for topic, channel in summary['channels'].items():
        assert channel['count'] == expected.get(topic, 0)
        assert (channel['schema'], channel['schemaEncoding'], channel['encoding']) == (
            TOPICS[topic], 'ros2msg', 'cdr')
        assert channel['metadata']['topic_type_hash'] == type_hash(TOPICS[topic])
    first = summary['first']
    assert first['/joint_states']['name'] == gait_bag.JOINTS
    assert first['/gait/support_polygon']['polygon']['points'][1]['x'] == pytest.approx(1.2)
    assert first['/gait/footsteps']['joint_names'][0] == 'front_left'
    transforms = first['/gait/footsteps']['points'][2]['transforms']
    assert transforms[0]['translation']['x'] == pytest.approx(0.8)
    assert first['/diagnostics']['status'][0]['hardware_id'] == 'test_quadruped'
