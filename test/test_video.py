"""Videos of recorded walks (issue 27): ``inspect BAG --video`` and ``run ... --video``.

A short walk is recorded once (go2's trot, 3 s, inproc, ``run --video`` rendering it at the
default size); the videos are read back with imageio: as many frames as the range and the rate
ask for, of the size asked for, none blank, and the robot's walk changing the picture.
"""

import math
import sys

import numpy as np
import pytest

from gait_nodes.bag.video import (
    VideoError,
    VideoSettings,
    frame_times_s,
    parse_size,
    read_walk,
)

mujoco = pytest.importorskip('mujoco')
imageio = pytest.importorskip('imageio.v2')
pytest.importorskip('imageio_ffmpeg')

SECONDS = 3.0


def _can_render() -> str | None:
    """Why MuJoCo cannot render here (no OpenGL), or None."""
    try:
        model = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size="1"/>'
                                               '</worldbody></mujoco>')
        mujoco.Renderer(model, 16, 16).close()
    except Exception as exc:  # the GL backends raise their own
        return f'{type(exc).__name__}: {exc}'
    return None


@pytest.fixture(scope='module')
def walk(tmp_path_factory):
    """A 3 s trot, recorded, and the video ``run --video`` made of it."""
    reason = _can_render()
    if reason:
        pytest.skip(f'MuJoCo cannot render on this machine (MUJOCO_GL='
                    f'{__import__("os").environ.get("MUJOCO_GL")}): {reason}')
    from gait_nodes.__main__ import main

    folder = tmp_path_factory.mktemp('video')
    bag, video = folder / 'bag', folder / 'run.mp4'
    assert main(['run', '--fast', '--scenario', 'go2_trot', '--duration', str(SECONDS),
                 '--record', str(bag), '--no-plot', '--video', str(video)]) == 0
    return bag, video


def _frames(path) -> list[np.ndarray]:
    with imageio.get_reader(path) as reader:
        return [np.asarray(frame) for frame in reader]


def _check_walk_frames(frames, width, height):
    assert all(frame.shape == (height, width, 3) for frame in frames)
    # Not blank: every frame has the floor, the robot and its footholds in it.
    assert min(float(frame.std()) for frame in frames) > 5.0
    # The robot walks (the camera follows it: its legs move, the floor slides under it): more
    # than 1 % of the pixels change clearly.
    change = np.abs(frames[0].astype(float) - frames[-1].astype(float)).max(axis=2)
    assert np.mean(change > 25) > 0.01


def test_run_writes_the_recorded_walk_as_a_video(walk):
    bag, video = walk
    recorded = read_walk(bag)
    assert recorded.robot == 'go2'
    # 15 frames a second of the whole walk, first and last base poses included.
    expected = math.floor(recorded.duration_s * 15 + 1e-9) + 1
    frames = _frames(video)
    assert len(frames) == expected
    _check_walk_frames(frames, 640, 480)
    base = recorded.base
    assert base[-1, 1] - base[0, 1] > 0.05  # it walked forward, so the video shows a walk


def test_inspect_renders_a_tiny_mp4_of_a_time_range(walk, tmp_path, capsys):
    from gait_nodes.inspect import main

    bag, _ = walk
    video = tmp_path / 'tiny.mp4'
    assert main([str(bag), '--video', str(video), '--size', '64x48', '--fps', '10',
                 '--from', '0.5', '--to', '2.5']) == 0
    assert 'video:' in capsys.readouterr().out
    frames = _frames(video)
    assert len(frames) == 21  # 0.5 s to 2.5 s, 0.1 s apart
    _check_walk_frames(frames, 64, 48)
    with imageio.get_reader(video) as reader:
        assert reader.get_meta_data()['fps'] == pytest.approx(10.0)


def test_inspect_renders_a_gif_played_faster(walk, tmp_path):
    from PIL import Image, ImageSequence

    from gait_nodes.inspect import main

    bag, _ = walk
    video = tmp_path / 'tiny.gif'
    assert main([str(bag), '--video', str(video), '--size', '64x48', '--fps', '10',
                 '--to', '2', '--speed', '2']) == 0
    with Image.open(video) as image:
        assert image.size == (64, 48)
        durations = [frame.info['duration'] for frame in ImageSequence.Iterator(image)]
    # 2 s of walk, 0.2 s apart: 11 frames of 100 ms (Pillow merges identical neighbours into
    # one frame of their summed duration).
    assert sum(durations) == 1100 and set(durations) <= {100 * k for k in range(1, 12)}
    frames = [np.asarray(frame)[..., :3] for frame in imageio.mimread(video)]
    _check_walk_frames(frames, 64, 48)


def test_a_png_is_the_still_at_the_start_of_the_range(walk, tmp_path):
    from gait_nodes.inspect import main

    bag, _ = walk
    still = tmp_path / 'still.png'
    assert main([str(bag), '--video', str(still), '--size', '64x48', '--from', '1.5']) == 0
    image = np.asarray(imageio.imread(still))[..., :3]
    assert image.shape == (48, 64, 3) and image.std() > 5.0
    # The 1.5 s frame of a video of the walk.
    video = tmp_path / 'around.mp4'
    assert main([str(bag), '--video', str(video), '--size', '64x48', '--fps', '2',
                 '--from', '1.5', '--to', '1.5']) == 0
    (frame,) = _frames(video)
    assert np.abs(frame.astype(float) - image).mean() < 5.0  # H.264 is lossy


def test_frame_times_cover_the_range_at_the_rate_and_speed(walk):
    recorded = read_walk(walk[0])
    times = frame_times_s(recorded, VideoSettings(fps=4, start_s=1.0, end_s=2.0, speed=2.0))
    assert times.tolist() == pytest.approx([1.0, 1.5, 2.0])
    whole = frame_times_s(recorded, VideoSettings(fps=10))
    assert whole[0] == 0.0 and recorded.duration_s - 0.1 < whole[-1] <= recorded.duration_s
    with pytest.raises(VideoError, match='after the walk'):
        frame_times_s(recorded, VideoSettings(start_s=100.0))


def test_bad_video_settings_are_refused_with_the_range():
    with pytest.raises(VideoError, match='even'):
        VideoSettings(width=63, height=48)
    with pytest.raises(VideoError, match=r'fps must be a number in \[0.1, 240\]'):
        VideoSettings(fps=0)
    with pytest.raises(VideoError, match='before its start'):
        VideoSettings(start_s=2.0, end_s=1.0)
    with pytest.raises(VideoError, match='WIDTHxHEIGHT'):
        parse_size('64')
    assert parse_size('64x48') == (64, 48)


def test_a_missing_dependency_says_how_to_install_it(tmp_path, monkeypatch, capsys):
    from gait_nodes.__main__ import main as run
    from gait_nodes.inspect import main as inspect

    bag = tmp_path / 'not_read'
    monkeypatch.setitem(sys.modules, 'imageio_ffmpeg', None)
    assert inspect([str(bag), '--video', str(tmp_path / 'walk.mp4')]) == 2
    assert 'imageio-ffmpeg' in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, 'imageio', None)
    monkeypatch.setitem(sys.modules, 'imageio.v2', None)
    assert inspect([str(bag), '--video', str(tmp_path / 'walk.gif')]) == 2
    assert 'pip install "imageio[ffmpeg]"' in capsys.readouterr().err
    # The run refuses before it walks.
    assert run(['run', '--fast', '--duration', '1', '--record', str(tmp_path / 'bag'),
                '--video', str(tmp_path / 'walk.mp4')]) == 2
    assert 'pip install "imageio[ffmpeg]"' in capsys.readouterr().err
    assert not (tmp_path / 'bag').exists()
    monkeypatch.undo()
    monkeypatch.setitem(sys.modules, 'mujoco', None)
    assert inspect([str(bag), '--video', str(tmp_path / 'walk.mp4')]) == 2
    assert 'pip install mujoco' in capsys.readouterr().err


def test_a_video_needs_a_recording_and_a_known_format(tmp_path, capsys):
    from gait_nodes.__main__ import main as run
    from gait_nodes.inspect import main as inspect

    assert run(['run', '--fast', '--duration', '1', '--video', str(tmp_path / 'w.mp4')]) == 2
    assert 'add --record' in capsys.readouterr().err
    assert inspect([str(tmp_path), '--video', str(tmp_path / 'walk.avi')]) == 2
    assert '.mp4 or .gif' in capsys.readouterr().err


def test_a_broken_opengl_backend_is_named(monkeypatch):
    """MuJoCo fails at import (not with ImportError) when MUJOCO_GL's library is missing."""
    import builtins

    from gait_nodes.bag.video import VideoUnavailableError, check_dependencies

    real_import = builtins.__import__

    def failing(name, *args, **kwargs):
        if name == 'mujoco':
            raise AttributeError("'NoneType' object has no attribute 'glGetError'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, '__import__', failing)
    monkeypatch.setenv('MUJOCO_GL', 'osmesa')
    with pytest.raises(VideoUnavailableError, match='MUJOCO_GL=osmesa .*libosmesa6'):
        check_dependencies('walk.mp4')
