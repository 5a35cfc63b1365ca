"""Preview control of the ZMP on the cart-table model (Kajita et al. 2003; thesis II.A, III.B).

Per horizontal axis the COM state ``x = (c, c_d, c_dd)`` is driven by its jerk ``u`` with a
sample time ``dt``; the output is the cart-table ZMP::

    x[k+1] = A x[k] + B u[k],    p[k] = C x[k],    C = (1, 0, -zc / g)       (Kajita eq. (7))

The servo with integral action is designed on the Katayama augmented system
``X = (e[k], x[k] - x[k-1])``, ``e = p - p_ref`` (Kajita eq. (9)-(12)): the discrete algebraic
Riccati equation of ``(A~, B~, Q~ = diag(Q, 0, 0, 0), R)`` is solved with
:func:`scipy.linalg.solve_discrete_are`, which gives the gains of::

    u[k] = -Gi sum_{i<=k} e[i] - Gx x[k] - sum_{j=1..NL} Gd[j] p_ref[k+j]    (Kajita eq. (13))

with ``NL = preview_s / dt`` preview samples.

Two forms share these gains:

* :func:`preview_batch` for a whole plan (the reference held at its last value beyond its end),
  simulated block-wise with the lifted closed loop, so that 20 s at 200 Hz takes about a
  millisecond;
* :class:`OnlinePreviewController`, which keeps the state and the error sum across ticks and
  plan changes and consumes a :class:`gait_nodes.contract.ZmpReference` window each tick
  (linear between samples, resampled on the controller's own time grid).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from gait_nodes.com.trajectory import GRAVITY_M_S2, ComTrajectory, check_positive
from gait_nodes.errors import ComPlanningError

NS_PER_S = 1_000_000_000
#: Longest accepted preview [s] (a 60 s horizon at 1 kHz is already 60 000 gains).
MAX_PREVIEW_S = 60.0
#: Largest accepted sample time [s].
MAX_DT_S = 1.0
#: Ticks of reference resampled beyond the preview window (OnlinePreviewController): a new
#: reference comes every 4 ticks (50 Hz); the window is resampled when these run out.
WINDOW_LEAD_TICKS = 10


@dataclass(frozen=True)
class PreviewSettings:
    """Settings of the ZMP preview controller, validated.

    Attributes:
        com_height_m: COM height above the ground ``zc`` [m].
        dt_s: Controller sample time [s].
        preview_s: Preview horizon [s]; at least one sample.
        q_weight: Weight ``Q`` of the squared ZMP error (> 0).
        r_weight: Weight ``R`` of the squared jerk (> 0).
        gravity_m_s2: Gravity [m/s^2].
    """

    com_height_m: float
    dt_s: float = 0.005
    preview_s: float = 1.6
    q_weight: float = 1.0
    r_weight: float = 1e-6
    gravity_m_s2: float = GRAVITY_M_S2

    def __post_init__(self):
        check_positive('com_height_m', self.com_height_m, 100.0)
        check_positive('dt_s', self.dt_s, MAX_DT_S)
        check_positive('preview_s', self.preview_s, MAX_PREVIEW_S)
        check_positive('Q (q_weight)', self.q_weight, 1e12)
        check_positive('R (r_weight)', self.r_weight, 1e12)
        check_positive('gravity_m_s2', self.gravity_m_s2, 100.0)
        if self.preview_s < self.dt_s * (1.0 - 1e-9):
            raise ComPlanningError(f'preview_s = {self.preview_s} s is shorter than one step '
                                   f'dt_s = {self.dt_s} s; allowed: preview_s >= dt_s')
        if abs(self.dt_s * NS_PER_S - round(self.dt_s * NS_PER_S)) > 1e-3:
            raise ComPlanningError(f'dt_s = {self.dt_s} s is not a whole number of nanoseconds')

    @property
    def preview_steps(self) -> int:
        """Number of preview samples ``NL`` (at least 1)."""
        return max(int(round(self.preview_s / self.dt_s)), 1)

    @property
    def dt_ns(self) -> int:
        """Sample time [ns]."""
        return int(round(self.dt_s * NS_PER_S))


def cart_table_model(com_height_m: float, dt_s: float,
                     gravity_m_s2: float = GRAVITY_M_S2) -> tuple[np.ndarray, ...]:
    """Discrete cart-table model ``(A, B, C)`` with the jerk as input (Kajita 2003, eq. (7)).

    Args:
        com_height_m: COM height ``zc`` [m].
        dt_s: Sample time [s].
        gravity_m_s2: Gravity [m/s^2].

    Returns:
        ``A`` (3, 3), ``B`` (3,), ``C`` (3,).
    """
    dt = dt_s
    A = np.array([[1.0, dt, dt * dt / 2.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    B = np.array([dt ** 3 / 6.0, dt * dt / 2.0, dt])
    C = np.array([1.0, 0.0, -com_height_m / gravity_m_s2])
    return A, B, C


@dataclass(frozen=True)
class PreviewGains:
    """Gains of the preview servo for one setting (Kajita 2003, eq. (13)).

    Attributes:
        settings: The settings they were computed for.
        A: (3, 3) state matrix.
        B: (3,) input vector.
        C: (3,) ZMP output row.
        integral_gain: ``Gi``.
        state_gain: (3,) ``Gx``.
        preview_gain: (NL,) ``Gd[1..NL]`` applied to ``p_ref[k+1..k+NL]``.
        riccati: (4, 4) solution of the augmented DARE.
    """

    settings: PreviewSettings
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    integral_gain: float
    state_gain: np.ndarray
    preview_gain: np.ndarray
    riccati: np.ndarray = field(repr=False)

    def closed_loop(self) -> tuple[np.ndarray, np.ndarray]:
        """Lifted closed loop ``z[k+1] = M z[k] + N w[k]`` of ``z = (x[k], sum_{i<k} e[i])``.

        ``w[k] = (Gi p_ref[k] - f[k], p_ref[k])`` with ``f[k]`` the preview term.
        """
        A, B, C, Gi, Gx = self.A, self.B, self.C, self.integral_gain, self.state_gain
        M = np.zeros((4, 4))
        M[:3, :3] = A - np.outer(B, Gi * C + Gx)
        M[:3, 3] = -B * Gi
        M[3, :3] = C
        M[3, 3] = 1.0
        N = np.zeros((4, 2))
        N[:3, 0] = B
        N[3, 1] = -1.0
        return M, N

    def lifted(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        """Block of ``size`` steps of the closed loop: ``z[0..size] = F z[0] + T w[0..size-1]``.

        Returns:
            ``F`` ((size + 1) * 4, 4) and ``T`` ((size + 1) * 4, size * 2), cached per size.
        """
        cache = self.__dict__.setdefault('_lifted', {})
        if size not in cache:
            M, N = self.closed_loop()
            powers = np.empty((size + 1, 4, 4))
            powers[0] = np.eye(4)
            for i in range(1, size + 1):
                powers[i] = M @ powers[i - 1]
            impulse = powers[:size] @ N
            rows, cols = np.meshgrid(np.arange(size + 1), np.arange(size), indexing='ij')
            lag = rows - 1 - cols
            blocks = impulse[np.clip(lag, 0, None)] * (lag >= 0)[..., None, None]
            toeplitz = blocks.transpose(0, 2, 1, 3).reshape((size + 1) * 4, size * 2)
            cache[size] = (powers.reshape((size + 1) * 4, 4), toeplitz)
        return cache[size]


def preview_gains(settings: PreviewSettings) -> PreviewGains:
    """Solve the augmented DARE and the preview gains (Katayama 1985 form, Kajita 2003 eq. (13)).

    Raises:
        ComPlanningError: No stabilizing solution (the message gives the settings).
    """
    A, B, C = cart_table_model(settings.com_height_m, settings.dt_s, settings.gravity_m_s2)
    # Augmented error system, state (e[k], dx[k]) (Kajita eq. (11)).
    At = np.zeros((4, 4))
    At[0, 0] = 1.0
    At[0, 1:] = C @ A
    At[1:, 1:] = A
    Bt = np.concatenate([[C @ B], B]).reshape(4, 1)
    Qt = np.zeros((4, 4))
    Qt[0, 0] = settings.q_weight
    Rt = np.array([[settings.r_weight]])
    try:
        P = scipy.linalg.solve_discrete_are(At, Bt, Qt, Rt)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ComPlanningError(f'the preview Riccati equation has no solution for {settings}: '
                               f'{exc}') from exc
    if not np.all(np.isfinite(P)):
        raise ComPlanningError(f'the preview Riccati solution is not finite for {settings}')
    denominator = float(Rt[0, 0] + (Bt.T @ P @ Bt)[0, 0])
    K = (Bt.T @ P @ At).ravel() / denominator
    closed = At - Bt @ K.reshape(1, 4)
    radius = float(np.max(np.abs(np.linalg.eigvals(closed))))
    if not radius < 1.0:
        raise ComPlanningError(f'the preview servo is not stable (spectral radius {radius:.6g}'
                               f' >= 1) for {settings}')
    # Preview gains Gd[j] = (R + B~' P B~)^-1 B~' X[j-1], X[j] = Ac' X[j-1] (Kajita eq. (13)).
    steps = settings.preview_steps
    gains = np.empty(steps)
    gains[0] = -K[0]
    X = -closed.T @ P[:, 0]
    Bv = Bt.ravel()
    for j in range(1, steps):
        gains[j] = Bv @ X / denominator
        X = closed.T @ X
    for array in (A, B, C, P, gains):
        array.setflags(write=False)
    state_gain = K[1:].copy()
    state_gain.setflags(write=False)
    return PreviewGains(settings, A, B, C, float(K[0]), state_gain, gains, P)


def _initial_state(zmp_reference: np.ndarray, initial_state) -> np.ndarray:
    if initial_state is None:
        state = np.zeros((3, 2))
        state[0] = zmp_reference[0]
        return state
    state = np.array(initial_state, dtype=float)
    if state.shape != (3, 2) or not np.all(np.isfinite(state)):
        raise ComPlanningError(f'the initial state must be finite (3, 2) rows (position, '
                               f'velocity, acceleration), got shape {state.shape}')
    return state


def preview_batch(zmp_reference: np.ndarray, settings: PreviewSettings | PreviewGains,
                  initial_state: np.ndarray | None = None,
                  block_size: int = 128) -> ComTrajectory:
    """COM for a whole ZMP reference sampled at ``settings.dt_s`` (the batch form).

    Args:
        zmp_reference: (N, 2) ZMP reference in odom [m], sample ``k`` at ``k * dt``; held at
            its last value for the preview beyond its end.
        settings: Preview settings, or gains already computed for them.
        initial_state: (3, 2) rows COM position [m], velocity [m/s], acceleration [m/s^2];
            default at rest over the first reference sample.
        block_size: Samples simulated per lifted block (speed only; any value >= 1 gives the
            same result to rounding).

    Returns:
        The COM trajectory, sample ``k`` at ``k * dt``.
    """
    gains = settings if isinstance(settings, PreviewGains) else preview_gains(settings)
    reference = np.asarray(zmp_reference, dtype=float)
    if reference.ndim != 2 or reference.shape[1] != 2 or len(reference) < 1:
        raise ComPlanningError(f'the ZMP reference must be (N >= 1, 2), got {reference.shape}')
    if not np.all(np.isfinite(reference)):
        raise ComPlanningError('the ZMP reference holds a NaN or infinite value')
    count = len(reference)
    steps = len(gains.preview_gain)
    padded = np.concatenate([reference, np.repeat(reference[-1:], steps, axis=0)])
    # f[k] = sum_j Gd[j] p_ref[k+j], j = 1..NL, for every k at once.
    windows = np.lib.stride_tricks.sliding_window_view(padded[1:], steps, axis=0)[:count]
    feedforward = windows @ gains.preview_gain
    inputs = np.stack([gains.integral_gain * reference - feedforward, reference], axis=1)
    size = max(1, min(int(block_size), count))
    free, toeplitz = gains.lifted(size)
    states = np.empty((count, 4, 2))
    z = np.zeros((4, 2))
    z[:3] = _initial_state(reference, initial_state)
    for start in range(0, count, size):
        length = min(size, count - start)
        w = np.zeros((size, 2, 2))
        w[:length] = inputs[start:start + length]
        block = (free @ z + toeplitz @ w.reshape(size * 2, 2)).reshape(size + 1, 4, 2)
        states[start:start + length] = block[:length]
        z = block[length]
    return ComTrajectory(settings.dt_s if isinstance(settings, PreviewSettings)
                         else gains.settings.dt_s,
                         states[:, 0], states[:, 1], states[:, 2])


@dataclass(frozen=True)
class ComSample:
    """COM state of the online controller at one instant.

    Attributes:
        stamp_ns: Time [ns].
        position_in_world: (2,) horizontal COM position [m].
        velocity_in_world: (2,) horizontal COM velocity [m/s].
        acceleration_in_world: (2,) horizontal COM acceleration [m/s^2].
    """

    stamp_ns: int
    position_in_world: np.ndarray
    velocity_in_world: np.ndarray
    acceleration_in_world: np.ndarray


class OnlinePreviewController:
    """The preview servo run tick by tick on a changing ZMP reference window.

    The state (COM position, velocity, acceleration per axis) and the ZMP error sum persist
    across ticks, reference changes and :meth:`retune`. Each :meth:`step` returns the state at
    the controller's current time ``t_k`` and advances it to ``t_k + dt``. The reference is the
    last one given to :meth:`set_reference` (sampled linearly, held beyond its ends), resampled
    once per reference on the controller's time grid so that a tick costs a slice and a dot
    product.

    Args:
        settings: Preview settings.
        position_in_world: (2,) initial COM position [m]; at rest.
        stamp_ns: Time of the initial state [ns].
    """

    def __init__(self, settings: PreviewSettings, position_in_world=(0.0, 0.0),
                 stamp_ns: int = 0):
        self._gains = preview_gains(settings)
        self._cache_gains()
        # The state (cx, cy, vx, vy, ax, ay) and the error sum (sx, sy) are kept in plain
        # floats (step runs at 200 Hz; the arrays of _state and _error_sum are made on demand).
        self._x = (0.0,) * 6
        self._e = (0.0, 0.0)
        self._stamp_ns = int(stamp_ns)
        self._reference = None
        self._window = None
        self._window_origin_ns = 0
        self.reset(position_in_world, stamp_ns=stamp_ns)

    @property
    def settings(self) -> PreviewSettings:
        """Current settings."""
        return self._gains.settings

    @property
    def gains(self) -> PreviewGains:
        """Current gains."""
        return self._gains

    @property
    def stamp_ns(self) -> int:
        """Time of the current state [ns]."""
        return self._stamp_ns

    @property
    def _state(self) -> np.ndarray:
        """(3, 2) rows position, velocity, acceleration (a new array of the kept floats)."""
        cx, cy, vx, vy, ax, ay = self._x
        return np.array(((cx, cy), (vx, vy), (ax, ay)))

    @_state.setter
    def _state(self, state: np.ndarray) -> None:
        (cx, cy), (vx, vy), (ax, ay) = np.asarray(state, dtype=float).tolist()
        self._x = (cx, cy, vx, vy, ax, ay)

    @property
    def _error_sum(self) -> np.ndarray:
        """(2,) ZMP error sum (a new array of the kept floats)."""
        return np.array(self._e)

    @_error_sum.setter
    def _error_sum(self, error_sum: np.ndarray) -> None:
        sx, sy = np.asarray(error_sum, dtype=float).tolist()
        self._e = (sx, sy)

    @property
    def reference(self):
        """The ZmpReference in use, or None."""
        return self._reference

    def state(self) -> ComSample:
        """The current state, without advancing."""
        state = self._state
        return ComSample(self._stamp_ns, state[0], state[1], state[2])

    def reset(self, position_in_world, velocity_in_world=(0.0, 0.0),
              acceleration_in_world=(0.0, 0.0), stamp_ns: int | None = None) -> None:
        """Re-initialize the state (e.g. from another COM generator); clears the error sum."""
        state = np.array([position_in_world, velocity_in_world, acceleration_in_world],
                         dtype=float)
        if state.shape != (3, 2) or not np.all(np.isfinite(state)):
            raise ComPlanningError(f'a COM state must be three finite (x, y) pairs, got {state}')
        self._state = state
        self._error_sum = np.zeros(2)
        if stamp_ns is not None:
            self._stamp_ns = int(stamp_ns)
        self._window = None

    def retune(self, settings: PreviewSettings) -> None:
        """New settings; the COM state and the current jerk are kept (bumpless transfer).

        Raises:
            ComPlanningError: The settings have no stabilizing solution; nothing changes.
        """
        gains = preview_gains(settings)
        jerk = self.jerk() if self._reference is not None else None
        self._gains = gains
        self._cache_gains()
        self._error_sum = np.zeros(2)
        self._window = None
        if jerk is not None:
            self.match_jerk(jerk)

    def jerk(self) -> np.ndarray:
        """(2,) jerk the next :meth:`step` applies [m/s^3]."""
        window = self.window()
        g = self._gains
        error_sum = self._error_sum + g.C @ self._state - window[0]
        return -g.integral_gain * error_sum - g.state_gain @ self._state \
            - g.preview_gain @ window[1:]

    def match_jerk(self, jerk_xy=(0.0, 0.0)) -> None:
        """Set the error sum so that the next step applies ``jerk_xy`` (bumpless start).

        A controller started from another generator's state would otherwise answer the
        mismatch with a burst of jerk; this way the acceleration stays smooth too.
        """
        window = self.window()
        g = self._gains
        feedforward = g.state_gain @ self._state + g.preview_gain @ window[1:]
        error_now = g.C @ self._state - window[0]
        self._error_sum = -(np.asarray(jerk_xy, dtype=float) + feedforward) \
            / g.integral_gain - error_now

    def set_reference(self, reference) -> None:
        """Use ``reference`` (a :class:`gait_nodes.contract.ZmpReference`) from now on."""
        self._reference = reference
        self._window = None

    def _resample(self) -> None:
        settings = self._gains.settings
        steps = settings.preview_steps
        dt_ns = settings.dt_ns
        end_ns = int(self._reference.stamps_ns[-1])
        # The ticks up to the reference's end, but at most WINDOW_LEAD_TICKS: a new reference
        # comes every few ticks, and each sample is interpolated on its own (np.interp works
        # point by point), so a shorter grid gives the same values where both reach.
        extra = min(max(0, -(-(end_ns - self._stamp_ns) // dt_ns)), WINDOW_LEAD_TICKS)
        grid = self._stamp_ns + dt_ns * np.arange(steps + 1 + extra, dtype=np.int64)
        self._window = self._reference.sample(grid)
        self._window_origin_ns = self._stamp_ns

    def window(self) -> np.ndarray:
        """(NL + 1, 2) reference at ``t_k, t_k + dt, ..., t_k + NL dt``."""
        if self._reference is None:
            raise ComPlanningError('the preview controller has no ZMP reference yet')
        settings = self._gains.settings
        steps = settings.preview_steps
        if self._window is not None:
            offset, remainder = divmod(self._stamp_ns - self._window_origin_ns, settings.dt_ns)
            if remainder == 0 and 0 <= offset <= len(self._window) - steps - 1:
                return self._window[offset:offset + steps + 1]
        self._resample()
        return self._window[:steps + 1]

    def _cache_gains(self) -> None:
        g = self._gains
        # The per-tick products in plain floats (step): A is the cart-table's integrator chain
        # (1, dt, dt^2/2 / 0, 1, dt / 0, 0, 1) and C = (1, 0, -zc/g).
        # (Python floats, not numpy scalars: the same doubles, cheaper arithmetic.)
        self._fast = (float(g.A[0, 1]), float(g.A[0, 2]), float(g.A[1, 2]),
                      tuple(g.B.tolist()), float(g.C[2]), float(g.integral_gain),
                      tuple(g.state_gain.tolist()), g.preview_gain,
                      g.settings.dt_ns, g.settings.preview_steps)

    def step(self) -> ComSample:
        """Return the state at ``t_k`` and advance the controller to ``t_k + dt``.

        The values of :meth:`step_values`, as arrays.
        """
        stamp_ns, cx, cy, vx, vy, ax, ay = self.step_values()
        return ComSample(stamp_ns, np.array((cx, cy)), np.array((vx, vy)), np.array((ax, ay)))

    def step_values(self) -> tuple[int, float, float, float, float, float, float]:
        """:meth:`step` in plain floats: ``(stamp_ns, cx, cy, vx, vy, ax, ay)`` at ``t_k``.

        The 3 x 2 state products are written out in plain floats (a numpy call on arrays this
        small costs ten times the arithmetic); they equal the matrix form
        :meth:`step_reference` up to rounding (the BLAS kernels may fuse multiply-adds), and
        only the preview sum over the window is a numpy dot.
        """
        a01, a02, a12, (b0, b1, b2), c2, Gi, (g0, g1, g2), Gd, dt_ns, steps = self._fast
        window = self._window
        offset = (self._stamp_ns - self._window_origin_ns) // dt_ns
        if window is None or offset < 0 or offset > len(window) - steps - 1 \
                or (self._stamp_ns - self._window_origin_ns) % dt_ns:
            window = self.window()
        else:
            window = window[offset:offset + steps + 1]
        stamp_ns = self._stamp_ns
        current = self._x
        cx, cy, vx, vy, ax, ay = current
        rx, ry = window[0].tolist()
        fx, fy = Gd.dot(window[1:]).tolist()
        sx, sy = self._e
        sx += cx + c2 * ax - rx
        sy += cy + c2 * ay - ry
        ux = -Gi * sx - (g0 * cx + g1 * vx + g2 * ax) - fx
        uy = -Gi * sy - (g0 * cy + g1 * vy + g2 * ay) - fy
        self._e = (sx, sy)
        self._x = (cx + a01 * vx + a02 * ax + b0 * ux, cy + a01 * vy + a02 * ay + b0 * uy,
                   vx + a12 * ax + b1 * ux, vy + a12 * ay + b1 * uy,
                   ax + b2 * ux, ay + b2 * uy)
        self._stamp_ns = stamp_ns + dt_ns
        return (stamp_ns, *current)

    def step_reference(self) -> ComSample:
        """:meth:`step` in the matrix form of Kajita eq. (13) (the reference for its tests)."""
        g = self._gains
        window = self.window()
        x = self._state
        current = ComSample(self._stamp_ns, x[0], x[1], x[2])
        self._error_sum = self._error_sum + g.C @ x - window[0]
        self._state = g.A @ x + g.B.reshape(3, 1) * (
            -g.integral_gain * self._error_sum - g.state_gain @ x
            - g.preview_gain @ window[1:])
        self._stamp_ns += g.settings.dt_ns
        return current

    def zmp(self) -> np.ndarray:
        """(2,) cart-table ZMP of the current state [m]."""
        return self._gains.C @ self._state
