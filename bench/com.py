#!/usr/bin/env python3
"""COM generator benchmark: online preview tick, batch preview, against a per-sample peer.

    python bench/com.py [--ticks 4000] [--reps 5]

Standard setting (zc 0.814 m, dt 5 ms, preview 1.6 s = 320 samples, Q 1, R 1e-6) on a 20 s
straight biped walk (ZMP at the stance ankle in single support, linear in double support):

1. online update, :meth:`OnlinePreviewController.step`, reference set once (the window is a
   slice of the resampled reference): median and p99 per tick (target <= 20 us median);
2. the same with a new 1.6 s ZmpReference window (10 ms samples) given every tick, so each tick
   also resamples the window;
3. batch, :func:`preview_batch` on 20 s at 200 Hz (4000 samples; target <= 10 ms), median of
   ``--reps``;
4. the peer: the same equations written out per sample (``x = A x + B u`` with
   ``u = -Gi sum(e) - Gx x - Gd . p_ref[k+1..k+NL]`` in a Python loop over numpy), per tick and
   for the 20 s batch, and the ratios peer / ours.

Figures only: no thresholds are asserted.
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gait_nodes.com.preview import (  # noqa: E402
    OnlinePreviewController,
    PreviewSettings,
    preview_batch,
    preview_gains,
)
from gait_nodes.contract import ZmpReference  # noqa: E402

STANDARD = PreviewSettings(com_height_m=0.814, dt_s=0.005, preview_s=1.6, q_weight=1.0,
                           r_weight=1e-6)


def walk_reference(duration_s: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(times, zmp (N, 2)) of a straight walk: 0.3 m steps, 0.6 s single, 0.2 s double."""
    vertices_t, vertices_p = [0.0, 1.5], [(0.0, 0.0), (0.0, 0.0)]
    t, x, side = 1.5, 0.0, -1
    stance = (0.0, -0.1)
    t += 0.2
    vertices_t.append(t)
    vertices_p.append(stance)
    while t < duration_s - 2.0:
        t += 0.6
        vertices_t.append(t)
        vertices_p.append(stance)
        x += 0.3
        side = -side
        stance = (x, 0.1 * side * -1)
        t += 0.2
        vertices_t.append(t)
        vertices_p.append(stance)
    vertices_t.append(duration_s)
    vertices_p.append(stance)
    times = dt_s * np.arange(int(round(duration_s / dt_s)))
    points = np.array(vertices_p)
    return times, np.stack([np.interp(times, vertices_t, points[:, i]) for i in range(2)], 1)


def per_sample_peer(gains, reference):
    """Kajita eq. (13) sample by sample; returns the positions and the per-tick times [s]."""
    steps = len(gains.preview_gain)
    padded = np.concatenate([reference, np.repeat(reference[-1:], steps, axis=0)])
    x = np.zeros((3, 2))
    x[0] = reference[0]
    error_sum = np.zeros(2)
    positions, ticks = np.empty_like(reference), []
    for k in range(len(reference)):
        start = time.perf_counter()
        positions[k] = x[0]
        error_sum += gains.C @ x - padded[k]
        u = -gains.integral_gain * error_sum - gains.state_gain @ x \
            - gains.preview_gain @ padded[k + 1:k + 1 + steps]
        x = gains.A @ x + np.outer(gains.B, u)
        ticks.append(time.perf_counter() - start)
    return positions, ticks


def percentile(values, q):
    """The q-th percentile of values."""
    return float(np.percentile(np.asarray(values), q))


def main() -> int:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--ticks', type=int, default=4000, help='online ticks per run')
    parser.add_argument('--reps', type=int, default=5, help='batch repetitions')
    options = parser.parse_args()
    gains = preview_gains(STANDARD)
    times, reference = walk_reference(20.0, STANDARD.dt_s)
    print(f'setting: zc {STANDARD.com_height_m} m, dt {STANDARD.dt_s * 1e3:.0f} ms, preview '
          f'{STANDARD.preview_s} s ({STANDARD.preview_steps} samples), Q {STANDARD.q_weight}, '
          f'R {STANDARD.r_weight}')

    # 1. online, reference set once.
    stamps = np.round(times * 1e9).astype(np.int64)
    whole = ZmpReference(stamps, reference)
    controller = OnlinePreviewController(STANDARD, reference[0], stamp_ns=0)
    controller.set_reference(whole)
    ticks = []
    for _ in range(min(options.ticks, len(times))):
        start = time.perf_counter()
        controller.step()
        ticks.append(time.perf_counter() - start)
    print(f'online step, reference set once:       median {statistics.median(ticks) * 1e6:7.1f}'
          f' us  p99 {percentile(ticks, 99) * 1e6:7.1f} us')
    online_median = statistics.median(ticks)

    # 2. online, a new window every tick.
    controller = OnlinePreviewController(STANDARD, reference[0], stamp_ns=0)
    window_times = np.arange(0.0, 1.6 + 1e-9, 0.01)
    windows = []
    for k in range(min(options.ticks, len(times) - 400)):
        t = times[k] + window_times
        windows.append(ZmpReference(np.round(t * 1e9).astype(np.int64), np.stack(
            [np.interp(t, times, reference[:, i]) for i in range(2)], 1)))
    ticks = []
    for window in windows:
        start = time.perf_counter()
        controller.set_reference(window)
        controller.step()
        ticks.append(time.perf_counter() - start)
    print(f'online step, new window every tick:    median {statistics.median(ticks) * 1e6:7.1f}'
          f' us  p99 {percentile(ticks, 99) * 1e6:7.1f} us')

    # 3. batch.
    batch = []
    for _ in range(options.reps):
        start = time.perf_counter()
        com = preview_batch(reference, gains)
        batch.append(time.perf_counter() - start)
    batch_median = statistics.median(batch)
    print(f'batch 20 s at 200 Hz ({len(reference)} samples):  median {batch_median * 1e3:7.2f} ms')

    # 4. peer.
    peer_batch = []
    for _ in range(max(1, options.reps // 2)):
        start = time.perf_counter()
        positions, peer_ticks = per_sample_peer(gains, reference)
        peer_batch.append(time.perf_counter() - start)
    peer_tick = statistics.median(peer_ticks)
    print(f'peer per-sample loop:                  median {peer_tick * 1e6:7.1f} us per tick, '
          f'{statistics.median(peer_batch) * 1e3:7.2f} ms for the 20 s batch')
    print(f'ratios peer / ours: tick {peer_tick / online_median:5.2f}x, '
          f'batch {statistics.median(peer_batch) / batch_median:5.1f}x; same COM to '
          f'{np.max(np.abs(positions - com.positions_in_world)):.1e} m')
    return 0


if __name__ == '__main__':
    sys.exit(main())
