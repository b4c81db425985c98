"""GNSS-only single point positioning (SPP) for any mix of systems, with RAIM FDE.

Input: the per-epoch satellite rows of :class:`insnav.gnss.tight_inputs.TightInputs`
(pseudorange, rate, satellite state at transmission in the ECEF frame at
reception, satellite clock minus modelled atmosphere, sigmas, the row's
system letter), from :func:`spp_inputs_from_rinex` or any other builder: the
solver itself knows nothing about ephemerides, so a system plugs in by
delivering rows.

Model of one epoch (Misra & Enge, *Global Positioning System*, 2nd ed.,
sec. 6.1; Groves 2013, sec. 9.4.1 and eq. (9.141) for several systems)::

    rho_i  = |r_s,i - r| + b + ISB_sys(i) - clk_s,i + e_i,   e_i ~ N(0, sigma_i^2)
    rhod_i = u_i . (v_s,i - v) + d - clkdot_s,i

Unknowns: ECEF position ``r`` [m], the receiver clock ``b`` [m] of the
reference system (GPS when present, else the first of
:data:`insnav.gnss.systems.SYSTEMS` present) and one inter-system bias
``ISB_s = b_s - b`` [m] per further system present at the epoch; velocity
``v`` and one clock drift ``d`` [m/s] from the rates (the systems' clocks
drift together to far below the Doppler noise).  QZSS rows (``[gnss] systems``
with ``"J"``) use the GPS clock, no ISB of their own
(:data:`insnav.gnss.systems.CLOCK_SYSTEM`).  Weighted Gauss-Newton
least squares, ``W = diag(1/sigma^2)``, covariance ``(H^T W H)^-1``.

RAIM fault detection and exclusion (Baarda's data snooping, Baarda 1968; as
a GNSS receiver test: Kuusniemi, *User-level reliability and quality
monitoring in satellite-based personal navigation*, 2005, sec. 4.2,
eqs. (4.7)-(4.12)):

* global test: ``T = v^T W v`` against the ``1 - alpha`` quantile of chi^2
  with ``n - p`` degrees of freedom (``v`` the least-squares residuals,
  ``p`` the unknowns);
* when it fails and ``n - p >= 2``: local test statistics
  ``w_i = |v_i| / sqrt((Q_v)_ii)``, ``Q_v = W^-1 - H (H^T W H)^-1 H^T``; the
  row with the largest ``w_i`` is excluded, the epoch solved again and the
  global test repeated, as long as the redundancy allows (so at least one
  degree of freedom remains to test the result).
* the velocity solution applies the same tests to the rates of the rows
  kept (a linear problem; its exclusions are counted apart).

Statuses per epoch (:data:`RAIM_STATUS`): 0 passed, 1 passed after
excluding rows, 2 failed and no further exclusion possible, 3 not tested
(no redundancy, or RAIM off), 4 no solution.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _core, earth
from ..config import ConfigError, TomlTable
from .rinex import read_nav_multi, read_obs_multi  # noqa: F401 (their home before; __all__ keeps them here)
from .code_fix import _clock, _clock_columns, _design, _position_fit  # noqa: F401 (the solver's kernel)
from .systems import SYSTEMS, clock_system_index

__all__ = ["SppOptions", "SppSolution", "solve_spp", "chi2_quantile", "spp_inputs_from_rinex", "RAIM_STATUS",
           "summary_counts", "read_obs_multi", "read_nav_multi"]

#: per-epoch RAIM status codes
RAIM_STATUS = {0: "passed", 1: "excluded", 2: "failed", 3: "untested", 4: "no solution"}


# --------------------------------------------------------------------------- chi-square quantile


def _gammp(a: float, x: float) -> float:
    """Regularized lower incomplete gamma P(a, x) (series / continued fraction, Press et al.,
    *Numerical Recipes*, 3rd ed., sec. 6.2)."""
    if x <= 0.0:
        return 0.0
    gln = math.lgamma(a)
    if x < a + 1.0:
        ap, s, d = a, 1.0 / a, 1.0 / a
        for _ in range(1000):
            ap += 1.0
            d *= x / ap
            s += d
            if abs(d) < abs(s) * 1e-15:
                break
        return s * math.exp(-x + a * math.log(x) - gln)
    b = x + 1.0 - a
    c = 1.0 / 1e-300
    d = 1.0 / b
    h = d
    for i in range(1, 1000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = 1e-300 if abs(d) < 1e-300 else d
        c = b + an / c
        c = 1e-300 if abs(c) < 1e-300 else c
        d = 1.0 / d
        h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    return 1.0 - math.exp(-x + a * math.log(x) - gln) * h


_CHI2_CACHE: dict = {}


def chi2_quantile(p: float, dof: int) -> float:
    """``x`` with ``P(chi^2_dof <= x) = p`` (bisection on :func:`_gammp`, relative accuracy 1e-12)."""
    key = (float(p), int(dof))
    if key not in _CHI2_CACHE:
        k = 0.5 * dof
        lo, hi = 0.0, max(10.0, 4.0 * dof)
        while _gammp(k, 0.5 * hi) < p:
            hi *= 2.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if _gammp(k, 0.5 * mid) < p:
                lo = mid
            else:
                hi = mid
            if hi - lo < 1e-12 * hi:
                break
        _CHI2_CACHE[key] = 0.5 * (lo + hi)
    return _CHI2_CACHE[key]


# --------------------------------------------------------------------------- options and solution


@dataclass
class SppOptions(TomlTable):
    """Solver options (the ``[spp]`` table of a run TOML).

    Attributes
    ----------
    raim : bool
        Fault detection and exclusion (module docstring).
    raim_alpha : float
        False-alarm probability of the global test (1e-3, as RTKLIB's ``chisqr`` table).
    max_exclusions : int
        Most rows excluded per epoch (-1: as many as the redundancy allows).
    min_sats : int
        Fewer usable rows than ``max(min_sats, unknowns)`` at an epoch: no solution.
    iterations : int
        Gauss-Newton iterations at most (converged at a step below 0.1 mm).
    velocity : bool
        Velocity and clock drift from the rates (Doppler) where there are enough.
    """

    raim: bool = True
    raim_alpha: float = 1e-3
    max_exclusions: int = -1
    min_sats: int = 4
    iterations: int = 10
    velocity: bool = True

    TABLE = "spp"

    def validate(self, source: str = "spp options") -> "SppOptions":
        def bad(key, allowed):
            raise ConfigError(f"{source}: key '{self.TABLE}.{key}': bad value {getattr(self, key)!r}; "
                              f"allowed: {allowed}")

        for key in ("raim", "velocity"):
            if not isinstance(getattr(self, key), bool):
                bad(key, "true or false")
        a = self.raim_alpha
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not (0.0 < a < 0.5):
            bad("raim_alpha", "a probability 0 < alpha < 0.5")
        for key, lo in (("max_exclusions", -1), ("min_sats", 4), ("iterations", 1)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                bad(key, f"an integer >= {lo}")
        return self


@dataclass
class SppSolution:
    """Per-epoch single point solution (NaN where there is none).

    Attributes
    ----------
    t : (E,) epoch time (the inputs' time axis) [s]
    r_e : (E, 3) antenna ECEF position [m]
    clock_bias_m : (E,) receiver clock of the reference system (GPS when present) [m]
    v_e : (E, 3) ECEF velocity [m/s] (NaN: too few rates)
    clock_drift_mps : (E,) [m/s]
    n_sats : (E,) rows with a pseudorange at the epoch (before exclusion)
    sigma_pos_n_m, sigma_vel_n_mps : (E, 3) 1-sigma N, E, D [m], [m/s]
    pdop : (E,) from the unweighted geometry of the rows used
    isb_m : (E, 4) clock of each system of :data:`SYSTEMS` minus the reference clock [m]
        (0 for the reference, NaN for systems not present)
    sigma_isb_m : (E, 4)
    ref_system : (E,) letter of the reference clock ('' without a solution)
    cov_r_e : (E, 3, 3) position covariance, ECEF [m^2]
    cov_v_e : (E, 3, 3) velocity covariance, ECEF [m^2/s^2]
    sigma_clock_m, sigma_drift_mps : (E,)
    gdop, hdop, vdop, tdop : (E,)
    n_used : (E,) pseudoranges in the final solution
    n_excluded : (E,) rows excluded by RAIM
    n_rate_used : (E,) rates in the velocity solution
    chi2 : (E,) final ``v^T W v``; chi2_threshold : (E,) its test bound (NaN: no redundancy)
    raim_status : (E,) int8 (:data:`RAIM_STATUS`)
    row_excluded : (M,) bool over the input rows
    n_rate_excluded : (E,) rates excluded by the velocity solution's own FDE (same tests)
    rate_row_excluded : (M,) bool
    """

    t: np.ndarray
    r_e: np.ndarray
    clock_bias_m: np.ndarray
    v_e: np.ndarray
    clock_drift_mps: np.ndarray
    n_sats: np.ndarray
    sigma_pos_n_m: np.ndarray
    sigma_vel_n_mps: np.ndarray
    pdop: np.ndarray
    isb_m: np.ndarray | None = None
    sigma_isb_m: np.ndarray | None = None
    ref_system: np.ndarray | None = None
    cov_r_e: np.ndarray | None = None
    cov_v_e: np.ndarray | None = None
    sigma_clock_m: np.ndarray | None = None
    sigma_drift_mps: np.ndarray | None = None
    gdop: np.ndarray | None = None
    hdop: np.ndarray | None = None
    vdop: np.ndarray | None = None
    tdop: np.ndarray | None = None
    n_used: np.ndarray | None = None
    n_excluded: np.ndarray | None = None
    n_rate_used: np.ndarray | None = None
    chi2: np.ndarray | None = None
    chi2_threshold: np.ndarray | None = None
    raim_status: np.ndarray | None = None
    row_excluded: np.ndarray | None = None
    n_rate_excluded: np.ndarray | None = None
    rate_row_excluded: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.t)

    def llh(self):
        """(lat [rad], lon [rad], h [m]) arrays."""
        return earth.ecef_to_geodetic(self.r_e)

    def v_n(self) -> np.ndarray:
        """(E, 3) NED velocity [m/s]."""
        lat, lon, _ = self.llh()
        return earth.ecef_to_ned_vector(lat, lon, self.v_e)

    @property
    def solved(self) -> np.ndarray:
        """(E,) bool: epochs with a position."""
        return np.isfinite(self.r_e[:, 0])


def summary_counts(sol: SppSolution) -> dict:
    """Epoch and RAIM counts of a solution (for reports)."""
    st = sol.raim_status
    return dict(epochs=int(len(sol)), solved=int(sol.solved.sum()),
                with_velocity=int(np.isfinite(sol.v_e[:, 0]).sum()),
                raim_passed=int((st == 0).sum()), raim_excluded_epochs=int((st == 1).sum()),
                raim_failed=int((st == 2).sum()), raim_untested=int((st == 3).sum()),
                rows_excluded=int(sol.n_excluded.sum()), rows_used=int(sol.n_used.sum()),
                rates_excluded=int(sol.n_rate_excluded.sum()))


# --------------------------------------------------------------------------- the solver


def _w_test(H, w, v):
    """Baarda w statistics ``|v_i| / sqrt(Q_v,ii)`` (0 where the redundancy number is ~0) and ``v^T W v``."""
    Hw = H * w[:, None]
    N = Hw.T @ Hw
    try:
        L = np.linalg.cholesky(N)
    except np.linalg.LinAlgError:
        return None, float("nan")
    B = np.linalg.solve(L, H.T)  # H N^-1 H^T = B^T B
    hii = np.einsum("ij,ij->j", B, B)
    qv = 1.0 / w ** 2 - hii
    wt = np.where(qv > 1e-9 / w ** 2, np.abs(v) / np.sqrt(np.maximum(qv, 1e-300)), 0.0)
    return wt, float(np.sum((v * w) ** 2))


def solve_spp(inputs, r0_e, *, options: SppOptions | None = None, sigma_pr_m=None, sigma_prr_mps=None,
              raim: bool | None = None, warm_start: bool = True) -> SppSolution:
    """Weighted least-squares position/clocks and velocity/drift per epoch, with RAIM FDE.

    The epochs are solved by the compiled solver (``insnav/gnss/spp_solver.hpp``,
    GIL released, no allocation per epoch) when every epoch has at most
    ``_core.SPP_MAX_ROWS`` rows, else by :func:`_solve_spp_python` (the same
    algorithm in numpy; the reference the compiled solver is tested against).

    Parameters
    ----------
    inputs : insnav.gnss.tight_inputs.TightInputs
        Rows with NaN pseudorange are not used; ``inputs.system`` gives each row's system.
    r0_e : (3,) starting ECEF position [m] (first epoch, and after an epoch without solution)
    options : SppOptions
    sigma_pr_m, sigma_prr_mps : (M,) arrays, optional
        Row sigmas replacing ``inputs.sats[:, 10]`` / ``[:, 11]`` (a :class:`insnav.gnss.weighting.Weighting`).
    raim : bool, optional
        Overrides ``options.raim``.
    warm_start : bool
        Start each epoch from the previous epoch's solution.

    Returns
    -------
    SppSolution
    """
    opt = (options or SppOptions()).validate()
    use_raim = opt.raim if raim is None else bool(raim)
    counts = np.diff(np.asarray(inputs.epoch_start, np.int64))
    batch = getattr(_core, "solve_spp_batch", None)
    if batch is None or counts.max(initial=0) > _core.SPP_MAX_ROWS:
        return _solve_spp_python(inputs, r0_e, options=opt, sigma_pr_m=sigma_pr_m, sigma_prr_mps=sigma_prr_mps,
                                 raim=use_raim, warm_start=warm_start)
    E = inputs.epoch_t.size
    M = len(inputs.prn)
    out = _empty_outputs(E, M)
    spr_all = inputs.sats[:, 10] if sigma_pr_m is None else sigma_pr_m
    sprr_all = inputs.sats[:, 11] if sigma_prr_mps is None else sigma_prr_mps
    ref = np.full(E, -1, np.int8)
    row_excl = np.zeros(M, np.uint8)
    rate_excl = np.zeros(M, np.uint8)
    out.update(ref_system=ref, row_excluded=row_excl, rate_row_excluded=rate_excl)
    batch(np.asarray(inputs.epoch_start, np.int64), inputs.sats, np.asarray(spr_all, float),
          np.asarray(sprr_all, float), clock_system_index(inputs.system).astype(np.int8), np.asarray(r0_e, float),
          dict(raim=use_raim, raim_alpha=float(opt.raim_alpha), max_exclusions=int(opt.max_exclusions),
               min_sats=int(opt.min_sats), iterations=int(opt.iterations), velocity=bool(opt.velocity),
               warm_start=bool(warm_start)), out)
    letters = np.array(list(SYSTEMS) + [""], dtype="<U1")
    out.update(ref_system=letters[ref], row_excluded=row_excl.astype(bool), rate_row_excluded=rate_excl.astype(bool))
    return SppSolution(t=inputs.epoch_t.copy(), info=dict(raim=use_raim, raim_alpha=opt.raim_alpha), **out)


def _empty_outputs(E: int, M: int) -> dict:
    """The per-epoch arrays of an :class:`SppSolution` before any epoch is solved (NaN, 0, no solution)."""
    nS = len(SYSTEMS)
    nan3 = np.full((E, 3), np.nan)
    return dict(r_e=nan3.copy(), v_e=nan3.copy(), clock_bias_m=np.full(E, np.nan), clock_drift_mps=np.full(E, np.nan),
                sigma_pos_n_m=nan3.copy(), sigma_vel_n_mps=nan3.copy(), pdop=np.full(E, np.nan),
                isb_m=np.full((E, nS), np.nan), sigma_isb_m=np.full((E, nS), np.nan),
                cov_r_e=np.full((E, 3, 3), np.nan), cov_v_e=np.full((E, 3, 3), np.nan),
                sigma_clock_m=np.full(E, np.nan), sigma_drift_mps=np.full(E, np.nan), gdop=np.full(E, np.nan),
                hdop=np.full(E, np.nan), vdop=np.full(E, np.nan), tdop=np.full(E, np.nan),
                chi2=np.full(E, np.nan), chi2_threshold=np.full(E, np.nan), n_sats=np.zeros(E, np.int64),
                n_used=np.zeros(E, np.int64), n_excluded=np.zeros(E, np.int64), n_rate_used=np.zeros(E, np.int64),
                n_rate_excluded=np.zeros(E, np.int64), raim_status=np.full(E, 4, np.int8))


def _leave_one_out(sats, system, w, x0, iterations):
    """The row whose omission gives the smallest weighted residual sum among the fits that converge, or
    None (the fault exclusion of RTKLIB ``raim_fde`` for an epoch whose full fit does not converge:
    one pseudorange off by thousands of kilometres).  The C++ twin is ``detail::leave_one_out``."""
    best, best_chi2 = None, np.inf
    keep = np.ones(len(sats), bool)
    for k in range(len(sats)):
        keep[k] = False
        fit = _position_fit(sats[keep], system[keep], w[keep], x0, iterations)
        keep[k] = True
        if fit is None or not fit[4]:
            continue
        chi2 = float(np.sum((fit[3] * w[np.arange(len(sats)) != k]) ** 2))
        if chi2 < best_chi2:
            best, best_chi2 = k, chi2
    return best


def _solve_spp_python(inputs, r0_e, *, options: SppOptions | None = None, sigma_pr_m=None, sigma_prr_mps=None,
                      raim: bool | None = None, warm_start: bool = True) -> SppSolution:
    """:func:`solve_spp` epoch by epoch in numpy (the reference of the compiled solver)."""
    opt = (options or SppOptions()).validate()
    use_raim = opt.raim if raim is None else bool(raim)
    E = inputs.epoch_t.size
    M = len(inputs.prn)
    nS = len(SYSTEMS)
    nan3 = np.full((E, 3), np.nan)
    out = dict(r_e=nan3.copy(), v_e=nan3.copy(), clock_bias_m=np.full(E, np.nan), clock_drift_mps=np.full(E, np.nan),
               sigma_pos_n_m=nan3.copy(), sigma_vel_n_mps=nan3.copy(), pdop=np.full(E, np.nan),
               isb_m=np.full((E, nS), np.nan), sigma_isb_m=np.full((E, nS), np.nan),
               cov_r_e=np.full((E, 3, 3), np.nan), cov_v_e=np.full((E, 3, 3), np.nan),
               sigma_clock_m=np.full(E, np.nan), sigma_drift_mps=np.full(E, np.nan), gdop=np.full(E, np.nan),
               hdop=np.full(E, np.nan), vdop=np.full(E, np.nan), tdop=np.full(E, np.nan),
               chi2=np.full(E, np.nan), chi2_threshold=np.full(E, np.nan))
    n_sats = np.zeros(E, np.int64)
    n_used = np.zeros(E, np.int64)
    n_excl = np.zeros(E, np.int64)
    n_rate = np.zeros(E, np.int64)
    status = np.full(E, 4, np.int8)
    ref_sys = np.full(E, "", dtype="<U1")
    row_excl = np.zeros(M, bool)
    rate_excl = np.zeros(M, bool)
    n_rate_x = np.zeros(E, np.int64)
    spr_all = inputs.sats[:, 10] if sigma_pr_m is None else np.asarray(sigma_pr_m, float)
    sprr_all = inputs.sats[:, 11] if sigma_prr_mps is None else np.asarray(sigma_prr_mps, float)
    system_all = np.asarray(inputs.system, dtype="<U1")
    r0 = np.asarray(r0_e, float)
    x_prev = np.append(r0, 0.0)
    sys_index = {s: k for k, s in enumerate(SYSTEMS)}
    for e in range(E):
        a, b = int(inputs.epoch_start[e]), int(inputs.epoch_start[e + 1])
        rows = np.arange(a, b)[np.isfinite(inputs.sats[a:b, 0]) & np.isfinite(spr_all[a:b]) & (spr_all[a:b] > 0)]
        n_sats[e] = int(np.isfinite(inputs.sats[a:b, 0]).sum())
        excluded = []
        x0 = x_prev if warm_start else np.append(r0, 0.0)
        while True:
            s = inputs.sats[rows]
            sysr = system_all[rows]
            w = 1.0 / spr_all[rows]
            p = 3 + len(set(sysr.tolist())) if rows.size else 4
            if rows.size < max(opt.min_sats, p):
                fit = False  # too few rows: keep the previous epoch's start
                break
            fit = _position_fit(s, sysr, w, x0, opt.iterations)
            if (fit is None or not fit[4]) and use_raim and rows.size - 1 - p >= 1 and not (
                    0 <= opt.max_exclusions <= len(excluded)):
                k = _leave_one_out(s, sysr, w, x0, opt.iterations)
                if k is not None:  # a gross row kept Gauss-Newton from converging: leave it out and refit
                    excluded.append(int(rows[k]))
                    rows = np.delete(rows, k)
                    continue
            if fit is None or not fit[4]:
                fit = None
                break
            x, u, H, v, _, letters, col = fit
            dof = rows.size - H.shape[1]
            if dof < 1:
                st = 3
                chi2 = thr = float("nan")
                break
            wt, chi2 = _w_test(H, w, v)
            thr = chi2_quantile(1.0 - opt.raim_alpha, dof)
            if not use_raim:
                st = 3
                break
            if wt is None:
                fit = None
                break
            if chi2 <= thr:
                st = 1 if excluded else 0
                break
            if dof < 2 or (0 <= opt.max_exclusions <= len(excluded)):
                st = 2
                break
            k = int(np.argmax(wt))
            excluded.append(int(rows[k]))
            rows = np.delete(rows, k)
            x0 = x  # the clock columns are rebuilt from x[3] (reference clock)
        if fit is False:
            continue
        if fit is None:
            x_prev = np.append(r0, 0.0)
            continue
        x, u, H, v, _, letters, col = fit
        if not np.all(np.isfinite(x)):
            x_prev = np.append(r0, 0.0)
            continue
        w = 1.0 / spr_all[rows]
        Hw = H * w[:, None]
        try:
            Q = np.linalg.inv(Hw.T @ Hw)
        except np.linalg.LinAlgError:
            x_prev = np.append(r0, 0.0)
            continue
        lat, lon, _ = earth.ecef_to_geodetic(x[:3])
        C_ne = earth.C_en(lat, lon).T
        out["r_e"][e] = x[:3]
        out["clock_bias_m"][e] = x[3]
        out["cov_r_e"][e] = Q[:3, :3]
        out["sigma_pos_n_m"][e] = np.sqrt(np.diag(C_ne @ Q[:3, :3] @ C_ne.T))
        out["sigma_clock_m"][e] = math.sqrt(Q[3, 3])
        out["isb_m"][e, sys_index[letters[0]]] = 0.0
        out["sigma_isb_m"][e, sys_index[letters[0]]] = 0.0
        for k, sname in enumerate(letters[1:]):
            out["isb_m"][e, sys_index[sname]] = x[4 + k]
            out["sigma_isb_m"][e, sys_index[sname]] = math.sqrt(Q[4 + k, 4 + k])
        Hn = H.copy()
        Hn[:, :3] = -(u @ C_ne.T)
        try:
            Qn = np.linalg.inv(Hn.T @ Hn)
            dg = np.diag(Qn)
            out["pdop"][e] = math.sqrt(dg[:3].sum())
            out["gdop"][e] = math.sqrt(dg.sum())
            out["hdop"][e] = math.sqrt(dg[:2].sum())
            out["vdop"][e] = math.sqrt(dg[2])
            out["tdop"][e] = math.sqrt(dg[3])
        except np.linalg.LinAlgError:
            pass
        out["chi2"][e] = chi2
        out["chi2_threshold"][e] = thr
        status[e] = st
        ref_sys[e] = letters[0]
        n_used[e] = rows.size
        n_excl[e] = len(excluded)
        row_excl[excluded] = True
        x_prev = np.append(x[:3], x[3])
        if not opt.velocity:
            continue
        idx = np.flatnonzero(np.isfinite(inputs.sats[rows, 1]) & np.isfinite(sprr_all[rows]) & (sprr_all[rows] > 0))
        n_rx = 0
        while True:  # the rates' own FDE: the same tests on the linear velocity problem
            if idx.size < max(opt.min_sats, 4):
                idx = None
                break
            sr = inputs.sats[rows[idx]]
            wr = 1.0 / sprr_all[rows[idx]]
            Hv = np.column_stack([-u[idx], np.ones(idx.size)])
            yv = sr[:, 1] - np.einsum("ij,ij->i", u[idx], sr[:, 5:8]) + sr[:, 9]
            Hvw = Hv * wr[:, None]
            sol = np.linalg.lstsq(Hvw, yv * wr, rcond=None)[0]
            dof = idx.size - 4
            if not use_raim or dof < 2 or (0 <= opt.max_exclusions <= n_rx):
                break
            wt, chi2_v = _w_test(Hv, wr, yv - Hv @ sol)
            if wt is None or chi2_v <= chi2_quantile(1.0 - opt.raim_alpha, dof):
                break
            k = int(np.argmax(wt))
            rate_excl[rows[idx[k]]] = True
            idx = np.delete(idx, k)
            n_rx += 1
        if idx is None:
            continue
        try:
            Qv = np.linalg.inv(Hvw.T @ Hvw)
        except np.linalg.LinAlgError:
            continue
        out["v_e"][e], out["clock_drift_mps"][e] = sol[:3], sol[3]
        out["cov_v_e"][e] = Qv[:3, :3]
        out["sigma_vel_n_mps"][e] = np.sqrt(np.diag(C_ne @ Qv[:3, :3] @ C_ne.T))
        out["sigma_drift_mps"][e] = math.sqrt(Qv[3, 3])
        n_rate[e] = int(idx.size)
        n_rate_x[e] = n_rx
    return SppSolution(t=inputs.epoch_t.copy(), n_sats=n_sats, n_used=n_used, n_excluded=n_excl, n_rate_used=n_rate,
                       n_rate_excluded=n_rate_x, rate_row_excluded=rate_excl,
                       raim_status=status, ref_system=ref_sys, row_excluded=row_excl,
                       info=dict(raim=use_raim, raim_alpha=opt.raim_alpha), **out)


# --------------------------------------------------------------------------- inputs from RINEX


def spp_inputs_from_rinex(obs, nav, t0_gps_s: float, approx_r_e, *, weighting=None, elevation_mask_deg: float = 10.0,
                          iono: bool = True, tropo: bool = True, sigma_pr_zenith_m: float = 3.0,
                          sigma_prr_zenith_mps: float = 0.3, use_cn0: bool = True):
    """RINEX observations + broadcast navigation -> (:class:`TightInputs`, (M,) C/N0 [dB-Hz]) for every system.

    The same rows as :func:`insnav.gnss.tight_inputs.tight_inputs_from_rinex`
    (receiver clock estimate per epoch, reception time, Klobuchar and
    Saastamoinen in the satellite-clock column, rate ``-lambda D``) but with
    every satellite (no best-GDOP limit), the masks and sigmas of
    ``weighting`` (:class:`insnav.gnss.weighting.Weighting`; default: the
    legacy sigmas and only the elevation mask) and the C/N0 kept per row.
    Satellite states come from :func:`_sat_states` (GPS LNAV through
    :mod:`insnav.gnss.ephemeris`; further systems when the navigation data
    carry them).

    The satellite states are evaluated once, at the receiver's time tags; those of the
    second clock iteration (and, with ``prior``, every state of a second pass from another
    start position) are these states carried to the new reception time and receiver
    position by :func:`_propagate_states` (to about 1e-8 m of a new evaluation).
    """
    inp, cn0, _ = _spp_inputs_from_rinex(obs, nav, t0_gps_s, approx_r_e, weighting=weighting,
                                         elevation_mask_deg=elevation_mask_deg, iono=iono, tropo=tropo,
                                         sigma_pr_zenith_m=sigma_pr_zenith_m,
                                         sigma_prr_zenith_mps=sigma_prr_zenith_mps, use_cn0=use_cn0)
    return inp, cn0


def _spp_inputs_from_rinex(obs, nav, t0_gps_s: float, approx_r_e, *, weighting=None, elevation_mask_deg: float = 10.0,
                           iono: bool = True, tropo: bool = True, sigma_pr_zenith_m: float = 3.0,
                           sigma_prr_zenith_mps: float = 0.3, use_cn0: bool = True, prior=None):
    """:func:`spp_inputs_from_rinex` returning ``(inputs, cn0, states)``; ``states`` can serve as the
    ``prior`` of a later call on the same observations and navigation data from another start
    position, whose satellite states are then carried over by :func:`_propagate_states`
    instead of evaluated again."""
    from .._median import group_median
    from .corrections import klobuchar_coefficients, klobuchar_delay, saastamoinen_delay
    from .ephemeris import C_LIGHT
    from .geometry import elevation_azimuth
    from .tight_inputs import TightInputs
    from .weighting import Weighting

    wgt = (weighting or Weighting()).validate()
    r0 = np.asarray(approx_r_e, float)
    t_tag = np.asarray(obs.t_gps_s, float)
    system = _obs_system(obs)
    ok = np.isfinite(obs.C1) & np.isin(system, np.asarray(wgt.systems, dtype="<U1"))
    rows = np.flatnonzero(ok)
    prn = np.asarray(obs.prn)
    rows_ok = rows
    reuse = prior is not None and np.array_equal(prior["rows_ok"], rows)
    if reuse:
        # another pass over the same rows: the earlier pass's states carried to the time tags and r0
        keep = prior["keep"]
        rows = rows[keep]
        ts0 = _propagate_states(prior["states_tag"], t_tag[rows], r0, nav, system[rows], prn[rows], obs, rows)
    else:
        # the states at the receiver's time tags (clock estimate 0) decide which rows have an ephemeris and
        # are the first of the two clock iterations (row by row: the same numbers as a call on the kept rows)
        states = _sat_states(nav, system[rows], prn[rows], t_tag[rows], r0, obs, rows)
        keep = states["valid"]
        ts0 = {k: v[keep] for k, v in states.items()}
        rows = rows[keep]
    ep = obs.epoch[rows]
    n_ep = obs.epoch_t_gps_s.size
    clk = np.zeros(n_ep)
    lat, lon, h = earth.ecef_to_geodetic(r0)
    sys_r = system[rows]
    for it in range(2):
        t_rx = t_tag[rows] - clk[ep] / C_LIGHT
        if it == 0:
            ts = ts0
        else:  # the second clock iteration: from the nearest states evaluated or carried before
            ts = _propagate_states(prior["states"] if reuse else ts0, t_rx, r0, nav, sys_r, prn[rows], obs, rows)
        raw = obs.C1[rows] - (ts["range_m"] - C_LIGHT * ts["clock_bias_s"])
        med, present = group_median(raw, ep, n_ep)
        clk[present] = med[present]
    el, az = elevation_azimuth(r0, ts["r_e"])
    iono_m = np.zeros(rows.size)
    tropo_m = np.zeros(rows.size)
    if iono:
        alpha, beta, _ = klobuchar_coefficients(nav)
        iono_m = klobuchar_delay(t_rx, np.full(rows.size, lat), np.full(rows.size, lon), el, az,
                                 alpha, beta) * ts["iono_scale"]
    if tropo:
        tropo_m = saastamoinen_delay(np.full(rows.size, lat), np.full(rows.size, h), el)
    prr = -ts["wavelength_m"] * np.asarray(obs.D1, float)[rows]
    cn0 = np.asarray(obs.S1, float)[rows]
    spr, sprr = wgt.sigmas(el, cn0, sys_r, sigma_pr_zenith_m=sigma_pr_zenith_m,
                           sigma_prr_zenith_mps=sigma_prr_zenith_mps, use_cn0=use_cn0)
    sats = np.column_stack([obs.C1[rows], prr, ts["r_e"], ts["v_e"], C_LIGHT * ts["clock_bias_s"] - iono_m - tropo_m,
                            C_LIGHT * ts["clock_drift_s_s"], spr, sprr])
    t_ep = t_tag[rows] - clk[ep] / C_LIGHT - t0_gps_s
    order = np.argsort(t_ep, kind="stable")
    inp = TightInputs.from_rows(t_ep, np.asarray(obs.prn)[rows], sats, np.degrees(el),
                                info=dict(source=str(getattr(obs, "path", "rinex")), approx_r_e=r0,
                                          rx_clock_tag_m=clk, iono_m=iono_m, tropo_m=tropo_m), system=sys_r)
    cn0 = cn0[order]
    m = wgt.mask(np.radians(inp.elevation_deg), cn0, inp.system, elevation_mask_deg=elevation_mask_deg)
    return inp.select(m), cn0[m], dict(rows_ok=rows_ok, keep=keep, states_tag=ts0, states=ts)


def _propagate_states(ts: dict, t_rx_gps_s, r_rx_e, nav, system, prn, obs, rows) -> dict:
    """:func:`_sat_states` rows carried to a new reception time and receiver position
    (:func:`insnav.gnss.tight_inputs.carry_transmit_states`); rows whose transmit time moves by
    more than :data:`insnav.gnss.tight_inputs.CARRY_MAX_S` are evaluated again."""
    from .tight_inputs import carry_transmit_states

    t_rx = np.asarray(t_rx_gps_s, float)
    r_rx = np.broadcast_to(np.asarray(r_rx_e, float), (t_rx.size, 3))
    new, far = carry_transmit_states(ts["r_e"], ts["v_e"], ts["clock_bias_s"], ts["clock_drift_s_s"],
                                     ts["t_tx_gps_s"], ts["tau_s"], t_rx, r_rx)
    out = {**ts, **new}
    far = np.flatnonzero(far & ts["valid"])
    if far.size:  # a clock estimate far off (or a start position far away): evaluated anew
        new = _sat_states(nav, system[far], prn[far], t_rx[far], r_rx[far], obs, rows[far])
        for k in out:
            out[k] = out[k].copy()
            out[k][far] = new[k]
    return out


def _obs_system(obs) -> np.ndarray:
    """(m,) system letter of each observation row (GPS-only readers have none: 'G')."""
    s = getattr(obs, "system", None)
    if s is None:
        return np.full(len(obs.prn), "G", dtype="<U1")
    return np.asarray(s, dtype="<U1")


def _sat_states(nav, system, prn, t_rx_gps_s, r0, obs, rows) -> dict:
    """Satellite states at transmission for rows of any system.

    Through the multi-system entry point ``insnav.gnss.broadcast.transmit_states_multi``
    when the package has it (GPS rows there are exactly
    :func:`insnav.gnss.ephemeris.transmit_states` with T_GD), with each
    row's pseudorange code (``obs.pseudorange_code()``: group delay, and the
    GLONASS FDMA wavelength); otherwise GPS LNAV only.

    Returns a dict of (k,) / (k, 3) arrays: ``valid`` (an ephemeris was
    found), ``r_e``, ``v_e``, ``clock_bias_s`` (group delay applied),
    ``clock_drift_s_s``, ``range_m``, ``wavelength_m`` (of the Doppler),
    ``iono_scale`` (the L1 Klobuchar delay times (f_L1/f)^2 = (lambda/lambda_L1)^2),
    ``tau_s`` (light time), ``t_tx_gps_s`` (transmit time).
    Rows without ephemeris get NaN states.
    """
    from .ephemeris import select_ephemeris, transmit_states
    from .measurements import L1_WAVELENGTH

    k = len(prn)
    try:
        from .broadcast import transmit_states_multi
    except ImportError:  # a GPS-only package
        transmit_states_multi = None
    if transmit_states_multi is not None and hasattr(nav, "eph_r"):
        codes = obs.pseudorange_code()[rows] if hasattr(obs, "pseudorange_code") else None
        if codes is not None:
            codes = np.where(codes == "", "C1C", codes)
        ts = transmit_states_multi(nav, t_rx_gps_s, r0, system=system, prn=prn, codes=codes)
        valid = ts.valid & np.isfinite(ts.range_m)
        lam = np.where(valid, ts.wavelength_m, np.nan)
        return dict(valid=valid, r_e=ts.r_e, v_e=ts.v_e, clock_bias_s=ts.clock_bias_s,
                    clock_drift_s_s=ts.clock_drift_s_s, range_m=ts.range_m, wavelength_m=lam,
                    iono_scale=np.where(valid, (lam / L1_WAVELENGTH) ** 2, 1.0), tau_s=ts.tau_s,
                    t_tx_gps_s=ts.t_tx_gps_s)
    out = dict(valid=np.zeros(k, bool), r_e=np.full((k, 3), np.nan), v_e=np.full((k, 3), np.nan),
               clock_bias_s=np.full(k, np.nan), clock_drift_s_s=np.full(k, np.nan), range_m=np.full(k, np.nan),
               wavelength_m=np.full(k, np.nan), iono_scale=np.ones(k), tau_s=np.full(k, np.nan),
               t_tx_gps_s=np.full(k, np.nan))
    g = np.flatnonzero(system == "G")
    if g.size:
        idx = select_ephemeris(nav.eph, prn[g], t_rx_gps_s[g])
        gg = g[idx >= 0]
        if gg.size:
            ts = transmit_states(nav.eph, idx[idx >= 0], t_rx_gps_s[gg], r0, tgd=True)
            out["valid"][gg] = True
            out["r_e"][gg], out["v_e"][gg] = ts.r_e, ts.v_e
            out["clock_bias_s"][gg], out["clock_drift_s_s"][gg] = ts.clock_bias_s, ts.clock_drift_s_s
            out["range_m"][gg] = ts.range_m
            out["tau_s"][gg], out["t_tx_gps_s"][gg] = ts.tau_s, ts.t_tx_gps_s
            out["wavelength_m"][gg] = L1_WAVELENGTH
    return out
