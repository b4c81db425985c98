"""Analytic truth trajectory.

The motion is described by three smoothed, piecewise-constant rates -- the
longitudinal acceleration ``a`` [m/s^2], the turn rate ``r`` [rad/s] and the
flight-path-angle rate ``q`` [rad/s] -- whose integrals give the speed ``V``,
the track heading ``psi`` and the flight-path angle ``gamma``:

    v_n = V [cos(gamma) cos(psi), cos(gamma) sin(psi), -sin(gamma)]

Each step of a rate is replaced by a quintic smoothstep
``S(x) = 10x^3 - 15x^4 + 6x^5`` of width ``transition_s`` centred on the
segment boundary (one-sided at the start and the end of the scenario).  Because
``S(x) + S(1 - x) = 1`` the smoothed rate has the same integral as the step
once the transition is over, so commanded changes (``heading_change_deg``,
``target_speed_mps`` ...) are reached exactly.  Rates are C2, so velocity and
attitude are C3; speed, heading and path angle are closed-form polynomials in
``t`` (no numerical integration).

Attitude (3-2-1 Euler, NED / forward-right-down):

    roll  = roll_offset + bank + sum(roll oscillations)
    pitch = gamma + pitch_offset + sum(pitch oscillations)
    yaw   = psi + yaw_offset + sum(yaw oscillations)

with ``bank = atan(V r / g_ref)`` for coordinated turns (else 0) and each
oscillation ``A E(t) sin(2 pi (t - start) / T + phase)`` under a C2 envelope
``E`` (smoothstep in and out over ``transition_s``).  Euler-angle rates are
analytic too.

Position (latitude, longitude, height) is the only integrated quantity:
``h' = -v_D``, ``lat' = v_N / (R_M + h)``, ``lon' = v_E / ((R_N + h) cos lat)``.
It is integrated on a 0.05 s grid that contains every transition breakpoint
(so the integrand is C-infinity inside each grid interval) with 3-node
Gauss-Legendre quadrature (local error ~ h^7 f^(6) / 2e6 < 1e-12 m); the weak dependence of the radii on latitude is resolved by a
fixed-point iteration, latitude inside an interval by cubic Hermite
interpolation.  The position error is below 1e-9 m over an hour (see
``tests/test_sim_truth.py``).  The grid is built and integrated in chunks
of 600 s on demand, carrying each running sum into the next chunk, and only
a few chunks are kept: memory does not grow with the scenario's length, and
the numbers are those of one pass over the whole grid, bit for bit.

Specific force and angular rate (Groves 2013, eqs. (5.44), (5.19)):

    omega_ib_b = omega_nb_b + C_bn (omega_ie_n + omega_en_n)
    f_ib_b = C_bn (dv_n/dt + (2 omega_ie_n + omega_en_n) x v_n - g_n),  g_n = [0, 0, g(lat, h)]
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import earth
from .scenario import Scenario

_GL_POS_NODES = 3
#: IMU intervals integrated at a time by :meth:`Trajectory.imu_increments` (its temporaries: ~11 MB)
IMU_CHUNK = 4096
#: times computed at a time by :meth:`Trajectory.state` (its temporaries: a few MB)
STATE_CHUNK = 8192


def _S(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


def _dS(x):
    x = np.clip(x, 0.0, 1.0)
    return 30.0 * x * x * (1.0 - x) ** 2


def _I(x):
    """Integral of S from 0 to x, for x in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return x ** 4 * (2.5 + x * (-3.0 + x))


class _SmoothRate:
    """A piecewise-constant rate with C2 smoothstep transitions, its integral and derivative."""

    def __init__(self, t0, durations, rates, w):
        n = len(durations)
        bounds = t0 + np.concatenate([[0.0], np.cumsum(durations)])
        starts = np.empty(n + 1)
        starts[0] = bounds[0]
        starts[1:n] = bounds[1:n] - w / 2
        starts[n] = bounds[n] - w
        r = np.concatenate([[0.0], np.asarray(rates, float), [0.0]])  # r[j] = rate before ramp j
        self.s = starts
        self.w = w
        self.r_before = r[:-1]
        self.delta = np.diff(r)
        q = np.zeros(n + 1)
        for j in range(n):
            q[j + 1] = (q[j] + self.r_before[j] * w + self.delta[j] * w / 2
                        + r[j + 1] * (starts[j + 1] - starts[j] - w))
        self.q_start = q
        self.breakpoints = np.concatenate([starts, starts + w])

    def eval(self, t):
        """Return integral Q(t) (from t0), rate(t) and d rate/dt at times ``t``."""
        j = np.clip(np.searchsorted(self.s, t, side="right") - 1, 0, len(self.s) - 1)
        dt = t - self.s[j]
        x = dt / self.w
        rb, d = self.r_before[j], self.delta[j]
        ramp = x <= 1.0
        x_c = np.where(ramp, x, 1.0)
        Q = self.q_start[j] + rb * np.minimum(dt, self.w) + d * self.w * _I(x_c) \
            + np.where(ramp, 0.0, (rb + d) * (dt - self.w))
        Q = np.where(dt < 0, 0.0, Q)
        rate = rb + d * _S(x)
        drate = np.where((x > 0) & ramp, d * _dS(x) / self.w, 0.0)
        return Q, rate, drate


@dataclass
class Kinematics:
    """Analytic kinematics at a set of times (no position).

    ``v_n``, ``a_n`` (N, 3) [m/s, m/s^2]; ``euler`` (N, 3) roll, pitch, yaw
    [rad] (yaw not wrapped); ``euler_rate`` (N, 3) [rad/s].
    """

    v_n: np.ndarray
    a_n: np.ndarray
    euler: np.ndarray
    euler_rate: np.ndarray


def _trig(euler):
    return (np.sin(euler[:, 0]), np.cos(euler[:, 0]), np.sin(euler[:, 1]), np.cos(euler[:, 1]),
            np.sin(euler[:, 2]), np.cos(euler[:, 2]))


def rotate_n_to_b(euler, x_n, trig=None):
    """``C_bn x_n`` for 3-2-1 Euler angles ``euler`` (N, 3) [rad], without forming matrices."""
    sr, cr, sp, cp, sy, cy = _trig(euler) if trig is None else trig
    x, y, z = x_n[:, 0], x_n[:, 1], x_n[:, 2]
    x1 = cy * x + sy * y
    y1 = cy * y - sy * x
    out = np.empty(x_n.shape)
    out[:, 0] = cp * x1 - sp * z
    z2 = sp * x1 + cp * z
    out[:, 1] = cr * y1 + sr * z2
    out[:, 2] = cr * z2 - sr * y1
    return out


def rotate_b_to_n(euler, x_b):
    """``C_nb x_b`` for 3-2-1 Euler angles ``euler`` (N, 3) [rad]."""
    sr, cr = np.sin(euler[:, 0]), np.cos(euler[:, 0])
    sp, cp = np.sin(euler[:, 1]), np.cos(euler[:, 1])
    sy, cy = np.sin(euler[:, 2]), np.cos(euler[:, 2])
    x, y, z = x_b[:, 0], x_b[:, 1], x_b[:, 2]
    y1 = cr * y - sr * z
    z1 = sr * y + cr * z
    x2 = cp * x + sp * z1
    z2 = -sp * x + cp * z1
    return np.stack([cy * x2 - sy * y1, sy * x2 + cy * y1, z2], axis=-1)


def euler_rate_to_omega_nb_b(euler, euler_rate, trig=None):
    """Body angular rate relative to NED from 3-2-1 Euler rates (Titterton & Weston, eq. 3.52)."""
    sr, cr, sp, cp, _, _ = _trig(euler) if trig is None else trig
    dr, dp, dy = euler_rate[:, 0], euler_rate[:, 1], euler_rate[:, 2]
    out = np.empty(euler.shape)
    out[:, 0] = dr - dy * sp
    out[:, 1] = dp * cr + dy * sr * cp
    out[:, 2] = dy * cr * cp - dp * sr
    return out


def _cross(a, b):
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


class _VehicleMotion:
    """Lateral slip and vertical bounce of a road vehicle, body axes.

    ``v_b = q(V) [0, sum_i A_i sin(w_i t + phi_i), sum_i B_i sin(u_i t + chi_i)]``:
    four sinusoids per axis with fixed periods (slip 1.5-6.3 s, bounce
    0.35-1.3 s) and phases drawn from the scenario seed, amplitudes giving
    the configured RMS at speed; ``q(V) = V^2 / (V^2 + 25 m^2/s^2)`` fades
    both out at standstill (a parked car neither slips nor bounces).  Smooth
    and analytic, so the IMU increments stay exact.
    """

    SLIP_PERIODS_S = np.array([1.5, 2.7, 4.1, 6.3])
    BOUNCE_PERIODS_S = np.array([0.35, 0.55, 0.8, 1.3])
    V0_MPS = 5.0

    def __init__(self, sc):
        rng = np.random.default_rng([int(sc.seed), 0x5A1B])
        self.w = np.concatenate([2 * np.pi / self.SLIP_PERIODS_S, 2 * np.pi / self.BOUNCE_PERIODS_S])
        self.phi = rng.uniform(0.0, 2 * np.pi, self.w.size)
        k = self.SLIP_PERIODS_S.size
        # RMS of a sum of k unit sinusoids is sqrt(k / 2)
        self.amp = np.concatenate([np.full(k, sc.lateral_slip / np.sqrt(k / 2)),
                                   np.full(self.BOUNCE_PERIODS_S.size, sc.vertical_bounce / np.sqrt(k / 2))])
        self.k = k

    def eval(self, t, V, a):
        """``v_b`` (N, 3) [m/s] and ``dv_b/dt`` (N, 3) [m/s^2] at ``t`` for speed ``V`` and its rate ``a``."""
        arg = t[:, None] * self.w[None, :] + self.phi[None, :]
        s, c = np.sin(arg) * self.amp, np.cos(arg) * self.amp * self.w
        k = self.k
        v0 = self.V0_MPS ** 2
        q = V * V / (V * V + v0)
        dq = 2 * V * a * v0 / (V * V + v0) ** 2
        v_b = np.zeros((t.size, 3))
        dv_b = np.zeros((t.size, 3))
        ys, zs = s[:, :k].sum(axis=1), s[:, k:].sum(axis=1)
        v_b[:, 1], v_b[:, 2] = q * ys, q * zs
        dv_b[:, 1] = dq * ys + q * c[:, :k].sum(axis=1)
        dv_b[:, 2] = dq * zs + q * c[:, k:].sum(axis=1)
        return v_b, dv_b


class Trajectory:
    """Exact truth for a :class:`~insnav.sim.scenario.Scenario`.

    Parameters
    ----------
    scenario : Scenario
        Validated scenario (SI units).
    grid_step : float, optional
        Nominal step of the position integration grid [s]; every transition
        breakpoint is added to the grid.
    chunk_steps : int, optional
        Grid steps integrated at a time, on demand (600 s at 0.05 s): memory
        holds a few chunks, not the scenario's grid; any value gives the same
        numbers, bit for bit.
    """

    def __init__(self, scenario: Scenario, grid_step: float = 0.05, chunk_steps: int = 12_000):
        sc = scenario
        self.sc = sc
        self.t0, self.t_end = sc.t0, sc.t_end
        d = [s.duration for s in sc.segments]
        w = sc.transition
        self._acc = _SmoothRate(sc.t0, d, [s.accel for s in sc.segments], w)
        self._turn = _SmoothRate(sc.t0, d, [s.turn_rate for s in sc.segments], w)
        self._climb = _SmoothRate(sc.t0, d, [s.path_angle_rate for s in sc.segments], w)
        osc = sc.oscillations
        self._osc_axis = np.array([{"roll": 0, "pitch": 1, "yaw": 2}[o.axis] for o in osc], int)
        self._osc = np.array([[o.amp, 2 * np.pi / o.period, o.start, o.end, o.phase] for o in osc],
                             float).reshape(-1, 5)
        bps = [self._acc.breakpoints, self._turn.breakpoints, self._climb.breakpoints]
        for o in osc:
            bps.append(np.array([o.start, o.start + w, o.end - w, o.end]))
        self._vehicle = _VehicleMotion(sc) if (sc.lateral_slip > 0 or sc.vertical_bounce > 0) else None
        # The grid: np.linspace(t0, t_end, n_uniform + 1) and every breakpoint in [t0, t_end], sorted, points
        # closer than 1 us to the previous one merged (rounding of breakpoints), the last one set to t_end.
        # It is made and integrated chunk by chunk, on demand (a day's grid and its values would take
        # ~160 MB); chunk c holds the uniform points cK .. (c+1)K - 1 and the breakpoints between them.
        self._n_uniform = max(1, int(np.ceil((self.t_end - self.t0) / grid_step - 1e-9)))
        bps = np.unique(np.concatenate(bps))
        self._bps = bps[(bps >= self.t0) & (bps <= self.t_end)]
        self._chunk_k = int(chunk_steps)
        self._n_chunks = max(1, -(-self._n_uniform // self._chunk_k))
        self._chunk_first = np.array([self._grid_chunk(c)[0] for c in range(self._n_chunks)])
        # carried sums at the start of each chunk (height, the four latitude iterations, longitude), filled
        # as the chunks are first integrated; a few integrated chunks are kept (most recently used)
        self._carry = {0: (0.0, (0.0,) * 4, 0.0)}
        self._cache: dict[int, tuple] = {}
        self._cache_size = 3

    # -- the position grid, chunk by chunk -------------------------------------
    def _uniform(self, k0: int, k1: int) -> np.ndarray:
        """Points k0..k1-1 of ``np.linspace(t0, t_end, n_uniform + 1)``, bit for bit (its arithmetic)."""
        n, t0, t_end = self._n_uniform, self.t0, self.t_end
        k = np.arange(k0, k1, dtype=float)
        step = (t_end - t0) / n
        y = (k / n) * (t_end - t0) if step == 0 else k * step
        y += t0
        if k1 > n:
            y[-1] = t_end
        return y

    def _grid_chunk(self, c: int) -> np.ndarray:
        """The grid points of chunk ``c`` (half open: without the next chunk's first point)."""
        K, n = self._chunk_k, self._n_uniform
        last = c == self._n_chunks - 1
        k0, k1 = c * K, (n + 1 if last else (c + 1) * K)
        u = self._uniform(k0, k1)
        lo = u[0]
        bps = self._bps[(self._bps >= lo) & (self._bps <= self.t_end)] if last else \
            self._bps[(self._bps >= lo) & (self._bps < self._uniform(k1, k1 + 1)[0])]
        cand = np.unique(np.concatenate([u, bps]))
        if c == 0:
            prev = -np.inf
        else:  # the last candidate of the chunk before: its last uniform point or a breakpoint after it
            prev = self._uniform(k0 - 1, k0)[0]
            before = self._bps[self._bps < lo]
            if before.size:
                prev = max(prev, before[-1])
        g = cand[np.diff(np.concatenate([[prev], cand])) > 1e-6]
        if last:
            g[-1] = self.t_end
        return g

    def _chunk(self, c: int) -> tuple:
        """Chunk ``c`` of the grid, closed by the next chunk's first point, and its integrated values:
        ``(g, h, h_dot, lat, lat_dot, lon, lon_dot)``."""
        hit = self._cache.pop(c, None)
        if hit is None:
            for j in range(max(k for k in self._carry if k <= c), c):  # the carried sums up to chunk c
                self._chunk(j)
            g = self._grid_chunk(c)
            if c + 1 < self._n_chunks:
                g = np.concatenate([g, [self._chunk_first[c + 1]]])
            hit, carry = self._integrate_position(g, self._carry[c])
            if c + 1 < self._n_chunks:
                self._carry[c + 1] = carry
            if len(self._cache) >= self._cache_size:
                self._cache.pop(next(iter(self._cache)))
        self._cache[c] = hit
        return hit

    def _chunk_of(self, t) -> np.ndarray:
        """The chunk holding the grid interval of each time ``t``."""
        return np.clip(np.searchsorted(self._chunk_first, t, side="right") - 1, 0, self._n_chunks - 1)

    def grid(self) -> np.ndarray:
        """The whole position-integration grid [s] (built chunk by chunk; for tests and plots)."""
        return np.concatenate([self._grid_chunk(c) for c in range(self._n_chunks)])

    # -- kinematics ---------------------------------------------------------
    def kinematics(self, t, sorted_t: bool = False) -> Kinematics:
        """Velocity, acceleration, Euler angles and their rates at times ``t`` [s].

        ``sorted_t=True`` promises that ``t`` is non-decreasing (faster).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        sc = self.sc
        n = t.size
        Qa, a, da = self._acc.eval(t)
        Qr, r, dr = self._turn.eval(t)
        Qq, q, _ = self._climb.eval(t)
        V = Qa + sc.speed0
        psi = Qr + sc.heading0
        gam = Qq + sc.path_angle0
        cg, sg = np.cos(gam), np.sin(gam)
        cp, sp = np.cos(psi), np.sin(psi)
        v_n = np.empty((n, 3))
        a_n = np.empty((n, 3))
        Vcg = V * cg
        v_n[:, 0] = Vcg * cp
        v_n[:, 1] = Vcg * sp
        v_n[:, 2] = -V * sg
        # d/dt of V [cg cp, cg sp, -sg]
        Vq_sg = V * q * sg
        Vr_cg = Vcg * r
        a_n[:, 0] = a * cg * cp - Vq_sg * cp - Vr_cg * sp
        a_n[:, 1] = a * cg * sp - Vq_sg * sp + Vr_cg * cp
        a_n[:, 2] = -a * sg - V * q * cg

        euler = np.empty((n, 3))
        rate = np.empty((n, 3))
        if sc.coordinated_turns:
            x = V * r / sc.g_ref
            euler[:, 0] = np.arctan(x) + sc.roll_offset
            rate[:, 0] = (a * r + V * dr) / sc.g_ref / (1.0 + x * x)
        else:
            euler[:, 0] = sc.roll_offset
            rate[:, 0] = 0.0
        euler[:, 1] = gam + sc.pitch_offset
        rate[:, 1] = q
        euler[:, 2] = psi + sc.yaw_offset
        rate[:, 2] = r
        w = sc.transition
        for k in range(self._osc.shape[0]):
            A, om, st, en, ph = self._osc[k]
            if sorted_t:
                i0, i1 = np.searchsorted(t, [st, en])
                sel = slice(i0, i1)
            else:
                sel = np.nonzero((t > st) & (t < en))[0]
            ts = t[sel]
            if ts.size == 0:
                continue
            x1, x2 = (ts - st) / w, (en - ts) / w
            S1, S2 = _S(x1), _S(x2)
            E = S1 * S2
            dE = (_dS(x1) * S2 - S1 * _dS(x2)) / w
            arg = om * (ts - st) + ph
            s_a, c_a = np.sin(arg), np.cos(arg)
            ax = self._osc_axis[k]
            euler[sel, ax] += A * E * s_a
            rate[sel, ax] += A * (dE * s_a + E * om * c_a)
        if self._vehicle is not None:
            # body-frame lateral / vertical velocity v_b: v_n += C_nb v_b,
            # a_n += C_nb (omega_nb_b x v_b + dv_b/dt)
            v_b, dv_b = self._vehicle.eval(t, V, a)
            trig = _trig(euler)
            w_nb_b = euler_rate_to_omega_nb_b(euler, rate, trig)
            v_n += rotate_b_to_n(euler, v_b)
            a_n += rotate_b_to_n(euler, _cross(w_nb_b, v_b) + dv_b)
        return Kinematics(v_n, a_n, euler, rate)

    def _velocity(self, t):
        t = np.asarray(t, dtype=float)
        if self._vehicle is not None:
            return self.kinematics(t.ravel()).v_n.reshape(t.shape + (3,))
        sc = self.sc
        V = sc.speed0 + self._acc.eval(t)[0]
        psi = sc.heading0 + self._turn.eval(t)[0]
        gam = sc.path_angle0 + self._climb.eval(t)[0]
        cg = np.cos(gam)
        return np.stack([V * cg * np.cos(psi), V * cg * np.sin(psi), -V * np.sin(gam)], axis=-1)

    # -- position -------------------------------------------------------------
    def _integrate_position(self, g: np.ndarray, carry: tuple) -> tuple:
        """Height, latitude and longitude on the grid points ``g`` by Gauss-Legendre quadrature of the velocity.

        ``carry``: the running sums from the grid's start at ``g[0]`` (of dh, of dlat in each of the four
        latitude iterations -- a fixed point: the radii depend on the latitude --, of dlon); the sums at
        ``g[-1]`` are returned with the values, so chunks integrated in turn give one pass over the whole
        grid, bit for bit (``np.cumsum`` continued from the carried value).

        Returns
        -------
        values : tuple
            ``(g, h, h_dot, lat, lat_dot, lon, lon_dot)`` at the points [s, m, m/s, rad, rad/s, rad, rad/s].
        carry : tuple
            The running sums at ``g[-1]``.
        """
        sc = self.sc
        s_h, s_lat, s_lon = carry[0], list(carry[1]), carry[2]
        xg, wg = np.polynomial.legendre.leggauss(_GL_POS_NODES)
        vg = self._velocity(g)
        n = len(g)

        def run_on(carry: float, steps):
            """carry, carry + steps[0], ...: the whole grid's np.cumsum, continued over a chunk."""
            return np.cumsum(np.concatenate([[carry], steps]))

        if n == 1:
            hg, latg, long = np.array([sc.h0]), np.array([sc.lat0]), np.array([sc.lon0])
            lat_dot_g = vg[:, 0] / (earth.radii(latg)[0] + hg)
        else:
            h_int = g[1:] - g[:-1]
            mid = 0.5 * (g[1:] + g[:-1])
            tn = mid[:, None] + 0.5 * h_int[:, None] * xg[None, :]  # (K, m)
            wn = 0.5 * h_int[:, None] * wg[None, :]
            vn = self._velocity(tn.ravel()).reshape(tn.shape + (3,))
            basis = self._hermite_basis(tn, g)
            # height: exact quadrature of -v_D
            S = run_on(s_h, -(wn * vn[..., 2]).sum(axis=1))
            s_h = S[-1]
            hg = sc.h0 + S
            h_nodes = self._hermite(hg, -vg[:, 2], tn, basis)
            lat_c = np.full(n, sc.lat0)
            for it in range(4):
                R_M, _ = earth.radii(lat_c)
                lat_nodes = self._hermite(lat_c, vg[:, 0] / (R_M + hg), tn, basis)
                R_Mn, _ = earth.radii(lat_nodes)
                S = run_on(s_lat[it], (wn * vn[..., 0] / (R_Mn + h_nodes)).sum(axis=1))
                s_lat[it] = S[-1]
                lat_c = sc.lat0 + S
            R_M, _ = earth.radii(lat_c)
            latg = lat_c
            lat_dot_g = vg[:, 0] / (R_M + hg)
            lat_nodes = self._hermite(latg, lat_dot_g, tn, basis)
            _, R_Nn = earth.radii(lat_nodes)
            S = run_on(s_lon, (wn * vn[..., 1] / ((R_Nn + h_nodes) * np.cos(lat_nodes))).sum(axis=1))
            s_lon = S[-1]
            long = sc.lon0 + S
        _, R_N = earth.radii(latg)
        values = (g, hg, -vg[:, 2], latg, lat_dot_g, long, vg[:, 1] / ((R_N + hg) * np.cos(latg)))
        return values, (s_h, tuple(s_lat), s_lon)

    @staticmethod
    def _hermite_basis(t, g):
        k = np.clip(np.searchsorted(g, t, side="right") - 1, 0, len(g) - 2)
        hk = g[k + 1] - g[k]
        s = (t - g[k]) / hk
        s2 = s * s
        s3 = s2 * s
        return k, (2 * s3 - 3 * s2 + 1, (s3 - 2 * s2 + s) * hk, 3 * s2 - 2 * s3, (s3 - s2) * hk)

    @staticmethod
    def _hermite(yg, dyg, t, basis):
        """Cubic Hermite interpolation of grid values ``yg`` with slopes ``dyg`` at ``t``."""
        k, (b0, b1, b2, b3) = basis
        return b0 * yg[k] + b1 * dyg[k] + b2 * yg[k + 1] + b3 * dyg[k + 1]

    def position(self, t, exact: bool = True):
        """Geodetic position of the IMU at times ``t`` [s].

        Parameters
        ----------
        t : array_like
            Times in ``[t0, t_end]`` [s].
        exact : bool
            ``True``: integrate from the nearest grid point with Gauss-Legendre
            quadrature (error < 1e-9 m).  ``False``: cubic Hermite
            interpolation of the grid (error ~1e-8 m; used for the gravity and
            Earth-rate terms inside the IMU quadrature, where it is ample).

        Returns
        -------
        lat, lon, h : ndarray
            [rad], [rad], [m].
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if np.any(t < self.t0 - 1e-9) or np.any(t > self.t_end + 1e-9):
            raise ValueError(f"times outside the trajectory [{self.t0}, {self.t_end}]")
        if t.size == 0:
            return self._position_in_chunk(t, 0, exact)
        c = self._chunk_of(t)
        if c[0] == c[-1] and np.all(c == c[0]):
            return self._position_in_chunk(t, int(c[0]), exact)
        out = np.empty((3,) + t.shape)
        if np.all(c[1:] >= c[:-1]):  # times in order (the usual case): a slice per chunk
            cuts = np.flatnonzero(np.diff(c)) + 1
            for i0, i1 in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [t.size]])):
                out[:, i0:i1] = self._position_in_chunk(t[i0:i1], int(c[i0]), exact)
        else:
            for cc in np.unique(c):  # each chunk integrated once per call
                sel = c == cc
                out[:, sel] = self._position_in_chunk(t[sel], int(cc), exact)
        return out[0], out[1], out[2]

    def _position_in_chunk(self, t, c: int, exact: bool):
        g, hg, h_dot_g, latg, lat_dot_g, long, lon_dot_g = self._chunk(c)
        if not exact:
            basis = self._hermite_basis(t, g)
            return (self._hermite(latg, lat_dot_g, t, basis), self._hermite(long, lon_dot_g, t, basis),
                    self._hermite(hg, h_dot_g, t, basis))
        k = np.clip(np.searchsorted(g, t, side="right") - 1, 0, len(g) - 2) if len(g) > 1 else np.zeros(t.shape, int)
        dt = t - g[k]
        xg, wg = np.polynomial.legendre.leggauss(_GL_POS_NODES)
        tn = g[k][:, None] + 0.5 * dt[:, None] * (xg[None, :] + 1.0)
        wn = 0.5 * dt[:, None] * wg[None, :]
        vn = self._velocity(tn.ravel()).reshape(tn.shape + (3,))
        basis = self._hermite_basis(tn, g)
        lat_n = self._hermite(latg, lat_dot_g, tn, basis)
        h_n = self._hermite(hg, h_dot_g, tn, basis)
        R_M, R_N = earth.radii(lat_n)
        h = hg[k] - (wn * vn[..., 2]).sum(axis=1)
        lat = latg[k] + (wn * vn[..., 0] / (R_M + h_n)).sum(axis=1)
        lon = long[k] + (wn * vn[..., 1] / ((R_N + h_n) * np.cos(lat_n))).sum(axis=1)
        return lat, lon, h

    # -- full state -----------------------------------------------------------
    def state(self, t, exact_position: bool = True, chunk: int | None = None):
        """Full truth at ``t``: position, kinematics, ``f_ib_b`` and ``omega_ib_b``.

        Parameters
        ----------
        t : array_like
            Times in ``[t0, t_end]`` [s].
        exact_position : bool
            As ``exact`` of :meth:`position`.
        chunk : int, optional
            Non-decreasing times are computed ``chunk`` at a time (default
            :data:`STATE_CHUNK`) into the output arrays; every value depends
            on its own time only, so the numbers do not depend on it.  The
            temporaries, about 40 ``(chunk, 3)`` arrays, stay bounded by the
            chunk, not by ``t`` (unsorted times: one piece, so that each
            position-grid chunk is integrated once).

        Returns
        -------
        dict
            ``t``, ``lat``, ``lon`` [rad], ``h`` [m], ``v_n`` (N, 3) [m/s],
            ``a_n`` (N, 3) [m/s^2], ``euler`` (N, 3) [rad], ``euler_rate``
            (N, 3) [rad/s], ``f_ib_b`` (N, 3) [m/s^2], ``omega_ib_b`` (N, 3)
            [rad/s], ``omega_nb_b`` (N, 3) [rad/s].
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        chunk = STATE_CHUNK if chunk is None else int(chunk)
        if t.size <= chunk or t.ndim != 1 or not np.all(t[1:] >= t[:-1]):
            return self._state(t, exact_position)
        out = None
        for s in range(0, t.size, chunk):
            part = self._state(t[s:s + chunk], exact_position)
            if out is None:
                out = {k: np.empty(t.shape + v.shape[1:]) for k, v in part.items() if k != "t"}
            for k, v in out.items():
                v[s:s + chunk] = part[k]
        out["t"] = t
        return out

    def _state(self, t, exact_position: bool):
        """:meth:`state` of the times ``t`` (a float array) in one piece."""
        lat, lon, h = self.position(t, exact=exact_position)
        kin = self.kinematics(t)
        f_ib_b, omega_ib_b, omega_nb_b = self._imu_quantities(lat, h, kin)
        return dict(t=t, lat=lat, lon=lon, h=h, v_n=kin.v_n, a_n=kin.a_n, euler=kin.euler,
                    euler_rate=kin.euler_rate, f_ib_b=f_ib_b, omega_ib_b=omega_ib_b,
                    omega_nb_b=omega_nb_b)

    @staticmethod
    def _imu_quantities(lat, h, kin: Kinematics):
        v_n = kin.v_n
        sl, cl = np.sin(lat), np.cos(lat)
        R_M, R_N = earth.radii(lat)
        w_ie = np.zeros(v_n.shape)
        w_ie[:, 0] = earth.OMEGA_IE * cl
        w_ie[:, 2] = -earth.OMEGA_IE * sl
        w_en = np.empty(v_n.shape)
        w_en[:, 0] = v_n[:, 1] / (R_N + h)
        w_en[:, 1] = -v_n[:, 0] / (R_M + h)
        w_en[:, 2] = -v_n[:, 1] * sl / cl / (R_N + h)
        w_in = w_ie + w_en
        f_n = kin.a_n + _cross(w_in + w_ie, v_n)
        f_n[:, 2] -= earth.gravity(lat, h)
        trig = _trig(kin.euler)
        omega_nb_b = euler_rate_to_omega_nb_b(kin.euler, kin.euler_rate, trig)
        return (rotate_n_to_b(kin.euler, f_n, trig),
                omega_nb_b + rotate_n_to_b(kin.euler, w_in, trig), omega_nb_b)

    def imu_increments(self, t_imu, nodes: int = 3, chunk: int | None = None):
        """Ideal IMU increments over ``(t_imu[k-1], t_imu[k]]`` by Gauss-Legendre quadrature.

        Parameters
        ----------
        t_imu : ndarray, shape (N + 1,)
            Sample times [s], the first being the start of the first interval.
        nodes : int
            Gauss-Legendre nodes per interval (exact for polynomials of degree
            ``2 nodes - 1``).
        chunk : int, optional
            Intervals computed at a time (default :data:`IMU_CHUNK`); each
            interval on its own, so the numbers do not depend on it.  The
            temporaries, about 60 arrays of ``chunk * nodes`` values, are
            bounded by it: 150 MB for 120,000 intervals (600 s at 200 Hz) in
            one piece, 11 MB in chunks of 4096.

        Returns
        -------
        dtheta_b, dv_b : ndarray, shape (N, 3)
            Integrals of ``omega_ib_b`` [rad] and ``f_ib_b`` [m/s] over each
            interval.
        """
        xg, wg = np.polynomial.legendre.leggauss(nodes)
        chunk = IMU_CHUNK if chunk is None else int(chunk)
        n = len(t_imu) - 1
        dtheta = np.empty((n, 3))
        dv = np.empty((n, 3))
        for s in range(0, n, chunk):
            e = min(n, s + chunk)
            a, b = t_imu[s:e], t_imu[s + 1:e + 1]
            half = 0.5 * (b - a)
            tn = (0.5 * (a + b))[:, None] + half[:, None] * xg[None, :]
            tf = tn.ravel()
            lat, _, h = self.position(tf, exact=False)
            kin = self.kinematics(tf, sorted_t=True)
            f, om, _ = self._imu_quantities(lat, h, kin)
            wn = (half[:, None] * wg[None, :])[..., None]
            dtheta[s:e] = (om.reshape(tn.shape + (3,)) * wn).sum(axis=1)
            dv[s:e] = (f.reshape(tn.shape + (3,)) * wn).sum(axis=1)
        return dtheta, dv
