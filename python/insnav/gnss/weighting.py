"""Pseudorange (and pseudorange-rate) variance models, masks and per-system factors.

One :class:`Weighting` (the ``[gnss]`` table of a run TOML) says how the
1-sigma of every satellite row is formed and which rows are used.  Models of
the pseudorange 1-sigma ``sigma_pr`` [m] of a satellite at elevation ``el``
with carrier-to-noise density ``C/N0`` [dB-Hz] and system factor ``F_sys``:

``legacy`` (default, today's inputs unchanged)
    ``sigma = s_z / sin(max(el, 5 deg)) * sqrt(max(10^((45 - C/N0)/10), 1))``
    (:func:`insnav.gnss.tight_inputs.pseudorange_sigma`, Groves 2013, eqs.
    (9.165) and (9.168) forms) with ``s_z = sigma_pr_zenith_m`` of the
    ``[rinex]`` table (3 m).

``rtklib``
    ``sigma^2 = F_sys^2 (a^2 + b^2 / sin^p(el))``, the receiver-noise term of
    the RTKLIB code-measurement variance (T. Takasu, *RTKLIB ver. 2.4.2
    Manual*, 2013, Appendix E.6, eq. (E.6.24): ``F^s R_r (a_sigma^2 +
    b_sigma^2 / sin El)``).  RTKLIB's defaults are ``a = b = 0.003 m`` for the
    carrier phase with the code/phase error ratio ``R_r = 100`` (``stats-eratio1``,
    ``stats-errphase``, ``stats-errphaseel``), i.e. ``a = b = 0.3 m`` for the
    code, ``F = 1.5`` for GLONASS (``EFACT_GLO``), and an elevation floor of
    5 deg (``MIN_EL``).  ``p = 2`` (default; the form of RTKLIB's
    ``rtkpos.c`` and of Groves eq. (9.168)); ``p = 1`` is the exponent
    ``pntpos.c`` actually uses for single point positioning.

``cn0``
    ``sigma^2 = F_sys^2 (a^2 + b^2 10^(-C/N0 / 10))``: the SIGMA-epsilon
    model (Hartinger & Brunner, "Variances of GPS phase observations: the
    SIGMA-epsilon model", GPS Solutions 2(4), 1999, eq. (3): variance
    ``C_i 10^(-C/N0/10)``) plus a floor ``a^2`` for the errors that do not
    depend on the signal level.  Tracking-noise variance is inversely
    proportional to C/N0 (Groves eq. (9.165)).  Defaults ``a = 0.3 m`` and
    ``b = 3 m * 10^(45/20) = 533.6 m Hz^0.5`` (3 m at 45 dB-Hz, 9.5 m at
    35 dB-Hz, 30 m at 25 dB-Hz).  A row without C/N0 gets the 45 dB-Hz value.

The pseudorange-rate 1-sigma keeps the ``legacy`` form with
``sigma_prr_zenith_mps`` (Doppler noise is not what these models describe)
times ``F_sys``.  Masks: rows below ``elevation_mask_deg`` or with a C/N0
below ``cn0_mask_dbhz`` (0: off; rows without C/N0 pass) are dropped.

System factors ``F_sys`` (the sigma is multiplied by it): ``G`` 1, ``R`` 1.5
(RTKLIB ``EFACT_GLO``: broadcast orbit/clock and inter-frequency biases of
the FDMA signals are worse), ``E`` 1, ``C`` 1 (RTKLIB ``EFACT_CMP``), ``J`` 1
(RTKLIB ``EFACT_QZS``).  The
``legacy`` model applies them too, so GPS-only results are unchanged.
"""
from __future__ import annotations

import dataclasses

import math
from dataclasses import dataclass, field

import numpy as np

from ..config import ConfigError, TomlTable
from .._median import unique
from .systems import SPP_SYSTEMS, SYSTEMS

__all__ = ["MODELS", "Weighting", "sigma_rtklib", "sigma_cn0", "sigma_legacy", "DEFAULT_SYSTEM_FACTORS",
           "MIN_ELEVATION_DEG", "CN0_DEFAULT_DBHZ"]

#: the variance models of :class:`Weighting`
MODELS = ("legacy", "rtklib", "cn0")
#: elevation floor of every model [deg] (RTKLIB ``MIN_EL``; legacy ``floor_el_deg``)
MIN_ELEVATION_DEG = 5.0
#: C/N0 assumed for rows without one [dB-Hz]
CN0_DEFAULT_DBHZ = 45.0
#: sigma multiplier per system (RTKLIB EFACT_GPS, EFACT_GLO, EFACT_GAL (=GPS), EFACT_CMP)
DEFAULT_SYSTEM_FACTORS = {"G": 1.0, "R": 1.5, "E": 1.0, "C": 1.0, "J": 1.0}


def sigma_rtklib(el_rad, a_m: float = 0.3, b_m: float = 0.3, exponent: float = 2.0, factor=1.0):
    """RTKLIB-style code 1-sigma [m]: ``F sqrt(a^2 + b^2 / sin^p(max(el, 5 deg)))`` (RTKLIB manual eq. (E.6.24))."""
    s = np.sin(np.maximum(np.asarray(el_rad, float), math.radians(MIN_ELEVATION_DEG)))
    return np.asarray(factor, float) * np.sqrt(a_m ** 2 + b_m ** 2 / s ** exponent)


def sigma_cn0(cn0_dbhz, a_m: float = 0.3, b_m_sqrthz: float = 3.0 * 10 ** (45.0 / 20.0), factor=1.0):
    """C/N0 code 1-sigma [m]: ``F sqrt(a^2 + b^2 10^(-C/N0/10))`` (SIGMA-epsilon, Hartinger & Brunner 1999, eq. (3));
    NaN C/N0 -> :data:`CN0_DEFAULT_DBHZ`."""
    c = np.asarray(cn0_dbhz, float)
    c = np.where(np.isfinite(c), c, CN0_DEFAULT_DBHZ)
    return np.asarray(factor, float) * np.sqrt(a_m ** 2 + b_m_sqrthz ** 2 * 10.0 ** (-c / 10.0))


def sigma_legacy(el_rad, sigma_zenith: float, cn0_dbhz=None, factor=1.0):
    """Today's :func:`insnav.gnss.tight_inputs.pseudorange_sigma` times the system factor."""
    from .tight_inputs import pseudorange_sigma

    return np.asarray(factor, float) * pseudorange_sigma(el_rad, sigma_zenith, cn0_dbhz,
                                                         floor_el_deg=MIN_ELEVATION_DEG)


@dataclass
class Weighting(TomlTable):
    """How rows are weighted and masked (the ``[gnss]`` table; see the module docstring).
    Units are in the attribute names.

    Attributes
    ----------
    model : {'legacy', 'rtklib', 'cn0'}
    rtklib_a_m, rtklib_b_m : float
        ``a``, ``b`` of the ``rtklib`` model [m] (RTKLIB defaults 0.3, 0.3).
    rtklib_el_exponent : float
        ``p`` of ``1/sin^p(el)`` (2; RTKLIB ``pntpos.c`` uses 1).
    cn0_a_m, cn0_b_m_sqrthz : float
        ``a`` [m] and ``b`` [m Hz^0.5] of the ``cn0`` model.
    sigma_pr_zenith_m, sigma_prr_zenith_mps : float or None
        Zenith 1-sigma of the ``legacy`` model and of every model's rates;
        None: the ``[rinex]`` table's values (3 m, 0.3 m/s).
    use_cn0 : bool or None
        The ``legacy`` model's C/N0 factor; None: the ``[rinex]`` value (true).
    system_factors : dict
        Sigma multiplier per system letter (missing letters: the defaults).
    elevation_mask_deg : float or None
        None: the ``[rinex]`` value (10 deg).
    cn0_mask_dbhz : float
        Rows with C/N0 below it are dropped (0: off).
    systems : list of str
        Systems to use (letters of :data:`insnav.gnss.systems.SPP_SYSTEMS`; the default
        :data:`insnav.gnss.systems.SYSTEMS`, QZSS ``J`` on request).
    """

    model: str = "legacy"
    rtklib_a_m: float = 0.3
    rtklib_b_m: float = 0.3
    rtklib_el_exponent: float = 2.0
    cn0_a_m: float = 0.3
    cn0_b_m_sqrthz: float = 3.0 * 10 ** (45.0 / 20.0)
    sigma_pr_zenith_m: float | None = None
    sigma_prr_zenith_mps: float | None = None
    use_cn0: bool | None = None
    system_factors: dict = field(default_factory=dict)
    elevation_mask_deg: float | None = None
    cn0_mask_dbhz: float = 0.0
    systems: list = field(default_factory=lambda: list(SYSTEMS))

    TABLE = "gnss"

    def validate(self, source: str = "gnss weighting") -> "Weighting":
        def bad(key, allowed):
            raise ConfigError(f"{source}: key '{self.TABLE}.{key}': bad value {getattr(self, key)!r}; "
                              f"allowed: {allowed}")

        if self.model not in MODELS:
            bad("model", ", ".join(f'"{m}"' for m in MODELS))
        for key in ("rtklib_a_m", "rtklib_b_m", "rtklib_el_exponent", "cn0_a_m", "cn0_b_m_sqrthz", "cn0_mask_dbhz",
                    "sigma_pr_zenith_m", "sigma_prr_zenith_mps", "elevation_mask_deg"):
            v = getattr(self, key)
            if v is None and key in ("sigma_pr_zenith_m", "sigma_prr_zenith_mps", "elevation_mask_deg"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                bad(key, "a finite number")
            if key not in ("elevation_mask_deg",) and v < 0:
                bad(key, ">= 0")
        for key in ("sigma_pr_zenith_m", "sigma_prr_zenith_mps"):
            if getattr(self, key) is not None and not getattr(self, key) > 0:
                bad(key, "> 0")
        if self.model == "rtklib" and not (self.rtklib_a_m > 0 or self.rtklib_b_m > 0):
            bad("rtklib_a_m", "a > 0 or b > 0")
        if self.model == "cn0" and not (self.cn0_a_m > 0 or self.cn0_b_m_sqrthz > 0):
            bad("cn0_a_m", "a > 0 or b > 0")
        if self.use_cn0 is not None and not isinstance(self.use_cn0, bool):
            bad("use_cn0", "true or false")
        if not isinstance(self.system_factors, dict):
            bad("system_factors", "a table such as {R = 1.5}")
        for s, f in self.system_factors.items():
            if s not in SPP_SYSTEMS:
                bad("system_factors", f"system letters {', '.join(SPP_SYSTEMS)}")
            if isinstance(f, bool) or not isinstance(f, (int, float)) or not (math.isfinite(f) and f > 0):
                bad("system_factors", "factors > 0")
        sy = self.systems
        if isinstance(sy, str):
            sy = list(sy)
        if not isinstance(sy, (list, tuple)) or not sy or any(s not in SPP_SYSTEMS for s in sy):
            bad("systems", f"a list of {', '.join(repr(s) for s in SPP_SYSTEMS)}")
        self.systems = list(sy)
        return self

    @property
    def is_default(self) -> bool:
        """True when the rows are weighted exactly as without a ``[gnss]`` table."""
        default = Weighting().validate()
        factors = dict(DEFAULT_SYSTEM_FACTORS, **self.system_factors)  # {R = 1.5} restates the default
        return (factors == dict(DEFAULT_SYSTEM_FACTORS, **default.system_factors)
                and dataclasses.replace(self, system_factors=default.system_factors) == default)

    def factors(self, system) -> np.ndarray:
        """(M,) sigma multiplier of each row's system letter."""
        f = dict(DEFAULT_SYSTEM_FACTORS, **self.system_factors)
        letters = np.atleast_1d(np.asarray(system, dtype="<U1"))
        out = np.empty(letters.shape)
        for s in unique(letters).tolist():  # (np.unique would import numpy.ma: ~15 ms of the SPP command)
            if s not in f:
                raise ValueError(f"unknown GNSS system {s!r} (known: {', '.join(SPP_SYSTEMS)})")
            out[letters == s] = f[s]
        return out

    def sigmas(self, el_rad, cn0_dbhz, system, *, sigma_pr_zenith_m: float = 3.0,
               sigma_prr_zenith_mps: float = 0.3, use_cn0: bool = True):
        """1-sigma of the pseudorange [m] and its rate [m/s] of each row.

        Parameters
        ----------
        el_rad : (M,) elevation [rad]
        cn0_dbhz : (M,) C/N0 [dB-Hz] (NaN: unknown) or None
        system : (M,) system letters
        sigma_pr_zenith_m, sigma_prr_zenith_mps, use_cn0 :
            The ``[rinex]`` values, used where this table leaves them None.
        """
        el = np.asarray(el_rad, float)
        cn0 = np.full(el.shape, np.nan) if cn0_dbhz is None else np.asarray(cn0_dbhz, float)
        F = self.factors(system)
        s_pr = sigma_pr_zenith_m if self.sigma_pr_zenith_m is None else self.sigma_pr_zenith_m
        s_prr = sigma_prr_zenith_mps if self.sigma_prr_zenith_mps is None else self.sigma_prr_zenith_mps
        uc = use_cn0 if self.use_cn0 is None else self.use_cn0
        cn0_legacy = cn0 if uc else None
        if self.model == "legacy":
            spr = sigma_legacy(el, s_pr, cn0_legacy, F)
        elif self.model == "rtklib":
            spr = sigma_rtklib(el, self.rtklib_a_m, self.rtklib_b_m, self.rtklib_el_exponent, F)
        else:
            spr = sigma_cn0(cn0, self.cn0_a_m, self.cn0_b_m_sqrthz, F)
        sprr = sigma_legacy(el, s_prr, cn0_legacy, F)
        return spr, sprr

    def mask(self, el_rad, cn0_dbhz, system, *, elevation_mask_deg: float = 10.0) -> np.ndarray:
        """(M,) bool: rows above the elevation mask, above the C/N0 mask and of a chosen system."""
        el_mask = elevation_mask_deg if self.elevation_mask_deg is None else self.elevation_mask_deg
        keep = np.asarray(el_rad, float) >= math.radians(el_mask)
        if self.cn0_mask_dbhz > 0 and cn0_dbhz is not None:
            c = np.asarray(cn0_dbhz, float)
            keep &= ~(c < self.cn0_mask_dbhz)  # NaN passes
        keep &= np.isin(np.asarray(system, dtype="<U1"), np.asarray(self.systems, dtype="<U1"))
        return keep
