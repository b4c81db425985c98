"""IMU simulation: ideal increments from the analytic truth, then the error model.

Ideal increments are Gauss-Legendre integrals of ``omega_ib_b`` and
``f_ib_b`` over each sample interval ``(t - dt, t]`` (see
:meth:`insnav.sim.trajectory.Trajectory.imu_increments`): a real gyro outputs
exactly the integral of the angular rate, so no mechanization is run
backwards and the simulator can test the mechanization.

Error model, per sensor triad (gyro: rad/s, accelerometer: m/s^2), applied to
the rate ``x`` (Groves 2013, eqs. (4.16)-(4.18)):

    x_meas = (I + diag(s) + M) x + b(t) + w(t)
    b(t) = b_const + b_turn_on + b_GM(t) + b_RW(t)

* ``b_const`` deterministic, ``b_turn_on ~ N(0, bias_sigma^2)`` once per run;
* ``b_GM``: first-order Gauss-Markov, ``db = -b/tau dt + sigma sqrt(2/tau) dW``,
  discretised exactly (``phi = exp(-dt/tau)``), started stationary;
* ``b_RW``: random walk, ``db = q dW``, starting at 0;
* ``w``: white noise of density ``N`` (ARW rad/sqrt(s), VRW (m/s)/sqrt(s)); the
  increment noise is ``N(0, N^2 dt)``;
* ``s`` scale-factor errors, ``M`` misalignment (zero diagonal).

For increments: ``dx_meas = (I + diag(s) + M) dx + b(t_k) dt + n_k``, the bias
being held at its value at the end of the interval.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scenario import SensorErrors


@dataclass
class SensorRealisation:
    """The injected errors of one triad (SI): ``bias`` (N, 3) at the IMU sample times."""

    bias: np.ndarray
    scale: np.ndarray
    misalignment: np.ndarray
    turn_on_bias: np.ndarray


def _ar1(phi: float, x0: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``x_k = phi x_{k-1} + e_k`` for k = 1..N (rows of ``e``), vectorised by blocks.

    Within a block of length L, ``x_j = phi^j (x_0 + sum_{i<=j} phi^-i e_i)``;
    L is chosen so that ``phi^-L <= e^8`` which keeps the rounding error at
    the 1e-12 level.
    """
    n = e.shape[0]
    out = np.empty_like(e)
    if phi <= 0.0:
        return e.copy()
    lam = -np.log(phi)
    L = n if lam == 0.0 else max(1, min(n, int(8.0 / lam)))
    j = np.arange(1, L + 1, dtype=float)
    pw_pos = np.exp(-lam * j)[:, None]  # phi^j
    pw_neg = np.exp(lam * j)[:, None]  # phi^-j
    state = np.asarray(x0, dtype=float)
    for s in range(0, n, L):
        m = min(L, n - s)
        acc = np.cumsum(e[s:s + m] * pw_neg[:m], axis=0)
        out[s:s + m] = pw_pos[:m] * (state[None, :] + acc)
        state = out[s + m - 1]
    return out


_SKIP_BLOCK = 1 << 20  # normals drawn at a time while skipping a stream
#: rows of a Gauss-Markov bias computed at a time by :class:`SensorErrorStream` (its memory: a few MB, not
#: ``8 tau / dt`` rows, which for tau = 1 h at 200 Hz would be 46 MB per axis)
GM_CHUNK = 1 << 16


class _GmChunks:
    """Rows of one axis's Gauss-Markov bias, ``GM_CHUNK`` at a time, equal bit
    for bit to :func:`_ar1` over the whole record: its blocks of ``L`` rows
    (``x_j = phi^j (x_0 + sum_{i<=j} phi^-i e_i)``) are cut into chunks, the
    running sum carried from one chunk to the next (``np.cumsum`` adds in
    order, so the carried sum is the one the whole block's cumsum reaches).

    Parameters
    ----------
    phi : float
        AR(1) coefficient ``exp(-dt / tau)`` (> 0).
    L : int
        Rows per :func:`_ar1` block.
    sd : float
        Driving-noise sigma [the bias' unit].
    gen : numpy.random.Generator
        At the start of this axis's driving noise.
    x0 : ndarray (1,)
        Row 0 of the bias.
    n : int
        Rows of the record.
    """

    def __init__(self, phi: float, L: int, sd: float, gen, x0: np.ndarray, n: int):
        self.phi, self.L, self.sd, self.gen, self.n = phi, int(L), sd, gen, int(n)
        self.lam = -np.log(phi)
        self.start, self.vals = 0, x0.copy()  # the cached rows [start, start + len(vals))
        self.block_len = self.p = 0  # the current _ar1 block's rows and those computed (p == block_len: next)
        self.state = x0.copy()  # the block's x_0 (the row before it)
        self.carry = np.zeros(1)  # the block's running sum up to row p

    def next_chunk(self) -> None:
        """The rows after the cached ones (at most ``GM_CHUNK``, within one :func:`_ar1` block)."""
        first = self.start + len(self.vals)
        if self.p == self.block_len:  # a new block of rows first .. (x_j, j >= 1, driven by e_{j-1})
            self.state = self.vals[-1:].copy()
            self.block_len, self.p = min(self.L, self.n - first), 0
        c = min(GM_CHUNK, self.block_len - self.p)
        e = self.sd * self.gen.standard_normal((c, 1))
        if self.phi <= 0.0:  # no memory (as _ar1): the driving noise itself
            self.vals, self.start, self.p = e[:, 0].copy(), first, self.p + c
            return
        j = np.arange(self.p + 1, self.p + c + 1, dtype=float)
        terms = e * np.exp(self.lam * j)[:, None]  # phi^-j e_j
        if self.p:
            terms[0] = self.carry + terms[0]
        acc = np.cumsum(terms, axis=0)
        self.carry = acc[-1].copy()
        self.vals = (np.exp(-self.lam * j)[:, None] * (self.state[None, :] + acc))[:, 0]
        self.start, self.p = first, self.p + c



def _skip_normals(rng: np.random.Generator, count: int) -> None:
    """Advance ``rng`` past ``count`` standard normals (drawn in blocks and dropped)."""
    while count > 0:
        k = min(count, _SKIP_BLOCK)
        rng.standard_normal(k)
        count -= k


def _generator_at(state: dict) -> np.random.Generator:
    """A generator of the same bit generator type, set to ``state``."""
    bg = getattr(np.random, state["bit_generator"])()
    bg.state = state
    return np.random.Generator(bg)


class SensorErrorStream:
    """One realisation of a triad's errors, served by row ranges in increasing order.

    The numbers are those of one whole-array draw, bit for bit, whatever the
    ranges: the draw order of the seed is fixed (turn-on bias, scale,
    misalignment, then per axis the Gauss-Markov start and its ``n - 1``
    driving noises, then the ``n x 3`` random-walk steps, then the ``n x 3``
    white noises).  The constructor records the generator's state at the start
    of each of those streams and skips past it, so ``rng`` ends where the
    whole-array draw leaves it; each stream is then drawn again from its
    recorded state as rows are asked for.  The Gauss-Markov recursion runs in
    the blocks of :func:`_ar1` (``8 tau / dt`` samples), each computed
    :data:`GM_CHUNK` rows at a time (:class:`_GmChunks`), one chunk per axis in
    memory, so that memory is bounded by neither the correlation time nor ``n``.

    Parameters
    ----------
    err : SensorErrors
        Error model (SI).
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    rng : numpy.random.Generator
        Advanced past the whole realisation.
    """

    def __init__(self, err: SensorErrors, n: int, dt: float, rng: np.random.Generator):
        self.n, self.dt = int(n), float(dt)
        self.turn_on = err.bias_sigma * rng.standard_normal(3)
        self.scale = err.scale + err.scale_sigma * rng.standard_normal(3)
        M = err.misalignment.copy()
        M[~np.eye(3, dtype=bool)] += err.misalignment_sigma * rng.standard_normal(6)
        self.misalignment = M
        self._base = err.bias + self.turn_on
        self._gm = []  # per axis: its Gauss-Markov rows (_GmChunks), or None
        for ax in range(3):
            sig, tau = err.gm_sigma[ax], err.gm_tau[ax]
            if not (sig > 0 and np.isfinite(tau)):
                self._gm.append(None)
                continue
            phi = np.exp(-dt / tau)
            x0 = sig * rng.standard_normal(1)
            lam = -np.log(phi)
            L = max(1, self.n - 1) if lam == 0.0 else max(1, min(max(1, self.n - 1), int(8.0 / lam)))
            gen = _generator_at(rng.bit_generator.state)
            _skip_normals(rng, self.n - 1)
            # the block cache: rows [start, start + len(vals)) of this axis's Gauss-Markov bias
            self._gm.append(_GmChunks(phi, L, sig * np.sqrt(1.0 - phi * phi), gen, x0, self.n))
        self._rw = None
        if np.any(err.bias_rw > 0):
            self._rw = [err.bias_rw * np.sqrt(dt), _generator_at(rng.bit_generator.state), np.zeros(3), 0]
            _skip_normals(rng, 3 * self.n)
        self._noise = None
        if np.any(err.noise_density > 0):
            self._noise = [err.noise_density * np.sqrt(dt), _generator_at(rng.bit_generator.state), 0]
            _skip_normals(rng, 3 * self.n)
        self._next = 0  # the first row not served yet

    def _gm_rows(self, ax: int, k0: int, k1: int) -> np.ndarray:
        """Rows [k0, k1) of axis ``ax``'s Gauss-Markov bias (k0 not below the cached chunk's start)."""
        g = self._gm[ax]
        out = np.empty(k1 - k0)
        k = k0
        while k < k1:
            if k >= g.start + len(g.vals):
                g.next_chunk()
            j = min(k1, g.start + len(g.vals))
            out[k - k0:j - k0] = g.vals[k - g.start:j - g.start]
            k = j
        return out

    def rows(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray]:
        """The bias (k1 - k0, 3) and white-noise increments (k1 - k0, 3) of rows [k0, k1).

        Rows are served once, in order: ``k0`` is the end of the previous call.
        """
        if k0 != self._next or not (k0 <= k1 <= self.n):
            raise ValueError(f"SensorErrorStream.rows({k0}, {k1}): expected rows from {self._next} up to {self.n}")
        m = k1 - k0
        bias = np.empty((m, 3))
        bias[:] = self._base
        for ax in range(3):
            if self._gm[ax] is not None:
                bias[:, ax] += self._gm_rows(ax, k0, k1)
        if self._rw is not None:
            q, gen, carry, _ = self._rw
            steps = np.empty((m + 1, 3))
            steps[0] = carry
            steps[1:] = q * gen.standard_normal((m, 3))
            if k0 == 0 and m > 0:
                steps[1] = 0.0  # the walk starts at 0
            walk = np.cumsum(steps, axis=0)[1:]  # the carry first: the whole-array sums, bit for bit
            if m > 0:
                self._rw[2] = walk[-1].copy()
            bias += walk
        if self._noise is not None:
            nd, gen, _ = self._noise
            noise = nd * gen.standard_normal((m, 3))
        else:
            noise = np.zeros((m, 3))
        self._next = k1
        return bias, noise

    def realisation(self, bias: np.ndarray) -> SensorRealisation:
        """The :class:`SensorRealisation` with the given bias rows and this triad's constants."""
        return SensorRealisation(bias, self.scale, self.misalignment, self.turn_on)


def simulate_sensor_errors(err: SensorErrors, n: int, dt: float,
                           rng: np.random.Generator) -> tuple[SensorRealisation, np.ndarray]:
    """Draw one realisation of a triad's errors (all rows of a :class:`SensorErrorStream`).

    Parameters
    ----------
    err : SensorErrors
        Error model (SI).
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    rng : numpy.random.Generator

    Returns
    -------
    realisation : SensorRealisation
        Bias at the ``n`` sample times, scale factors, misalignment.
    noise : ndarray, shape (n, 3)
        White-noise increments [rad or m/s] (``N(0, N^2 dt)``).
    """
    stream = SensorErrorStream(err, n, dt, rng)
    bias, noise = stream.rows(0, n)
    return stream.realisation(bias), noise


def apply_errors(dx: np.ndarray, real: SensorRealisation, noise: np.ndarray,
                 dt: float) -> np.ndarray:
    """Corrupt ideal increments ``dx`` (N, 3): ``(I + diag(s) + M) dx + b dt + n``."""
    T = np.eye(3) + np.diag(real.scale) + real.misalignment
    out = real.bias * dt
    out += noise
    for i in range(3):  # column-wise: (N,3) @ (3,3) is slow in NumPy for tiny inner sizes
        for j in range(3):
            if T[i, j] != 0.0:
                out[:, i] += T[i, j] * dx[:, j]
    return out


def imu_model_dict(gyro: SensorErrors, accel: SensorErrors, imu_rate: float) -> dict:
    """The IMU noise/bias model in SI, for deriving a filter configuration.

    Keys (each a list of 3 floats, one per body axis, unless noted):

    ``rate_hz``
        IMU sample rate [Hz] (float).
    ``gyro_arw``
        Angle random walk [rad/sqrt(s)] (white rate noise density).
    ``accel_vrw``
        Velocity random walk [(m/s)/sqrt(s)].
    ``gyro_bias``, ``accel_bias``
        Deterministic constant bias [rad/s], [m/s^2].
    ``gyro_bias_sigma``, ``accel_bias_sigma``
        1-sigma of the random constant (turn-on) bias [rad/s], [m/s^2].
    ``gyro_gm_sigma``, ``accel_gm_sigma``
        Steady-state 1-sigma of the Gauss-Markov bias [rad/s], [m/s^2].
    ``gyro_gm_tau``, ``accel_gm_tau``
        Its correlation time [s] (``inf`` when there is none).
    ``gyro_bias_rw``, ``accel_bias_rw``
        Bias random walk [rad/s/sqrt(s)], [m/s^2/sqrt(s)].
    ``gyro_scale_sigma``, ``accel_scale_sigma``
        1-sigma of the random scale-factor error [-]; ``gyro_scale`` /
        ``accel_scale`` the deterministic part.
    ``gyro_misalignment_sigma``, ``accel_misalignment_sigma``
        1-sigma of each random off-diagonal misalignment [rad] (float).
    ``gyro_bias_total_sigma``, ``accel_bias_total_sigma``
        ``sqrt(bias^2 + bias_sigma^2 + gm_sigma^2)``: a sensible initial
        1-sigma of a filter's bias states [rad/s], [m/s^2].
    """
    def tri(p, e: SensorErrors):
        return {
            f"{p}_bias": e.bias.tolist(), f"{p}_bias_sigma": e.bias_sigma.tolist(),
            f"{p}_gm_sigma": e.gm_sigma.tolist(), f"{p}_gm_tau": e.gm_tau.tolist(),
            f"{p}_bias_rw": e.bias_rw.tolist(), f"{p}_scale": e.scale.tolist(),
            f"{p}_scale_sigma": e.scale_sigma.tolist(),
            f"{p}_misalignment_sigma": float(e.misalignment_sigma),
            f"{p}_bias_total_sigma": np.sqrt(e.bias ** 2 + e.bias_sigma ** 2
                                             + e.gm_sigma ** 2).tolist(),
        }
    d = {"rate_hz": float(imu_rate), "gyro_arw": gyro.noise_density.tolist(),
         "accel_vrw": accel.noise_density.tolist()}
    d.update(tri("gyro", gyro))
    d.update(tri("accel", accel))
    return d
