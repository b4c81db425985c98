"""Carrier-phase RTK: MLAMBDA against exhaustive search, double differences against analytic values,
cycle-slip detection on injected slips, a static real pair fixed to the known baseline, bad input."""
from __future__ import annotations

import itertools
import json
import subprocess
import sys

import numpy as np
import pytest

from insnav import _core, earth
from insnav.gnss import rtk

C = 299792458.0
OMEGA_E = 7.2921151467e-5


# --------------------------------------------------------------------------- MLAMBDA


def _random_problem(rng, n):
    """A correlated SPD covariance (ambiguity-like: a few large, strongly correlated directions)."""
    A = rng.normal(size=(n, n))
    scales = np.exp(rng.uniform(np.log(0.05), np.log(1.0), n))
    Q = A @ np.diag(scales ** 2) @ A.T + 1e-3 * np.eye(n)
    Q *= rng.uniform(0.05, 0.4) / np.min(np.diag(Q)) * np.min(np.diag(Q))
    return rng.normal(scale=5.0, size=n), Q


def _exhaustive_two_best(a_hat, Q):
    """The two best integer vectors by enumerating the box that must contain them."""
    Qi = np.linalg.inv(Q)
    n = a_hat.size
    base = np.round(a_hat)
    cands = [base] + [base + s * e for e in np.eye(n) for s in (-1, 1)]
    norms = sorted(float((a_hat - c) @ Qi @ (a_hat - c)) for c in cands)
    chi2 = norms[1] * (1 + 1e-9)  # the second best is at most this
    half = np.sqrt(chi2 * np.diag(Q))
    lo, hi = np.ceil(a_hat - half), np.floor(a_hat + half)
    axes = [np.arange(lo[i], hi[i] + 1) for i in range(n)]
    if np.prod([len(a) for a in axes]) > 400000:
        return None
    grid = np.array(list(itertools.product(*axes)), float)
    d = grid - a_hat
    s = np.einsum("ij,jk,ik->i", d, Qi, d)
    o = np.argsort(s)[:2]
    return grid[o], s[o]


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
def test_mlambda_matches_exhaustive_search(n):
    rng = np.random.default_rng(100 + n)
    checked = 0
    for _ in range(60):
        a_hat, Q = _random_problem(rng, n)
        ref = _exhaustive_two_best(a_hat, Q)
        if ref is None:
            continue
        fix, s = _core.lambda_search(a_hat, Q)
        np.testing.assert_array_equal(fix[:, 0], ref[0][0])
        if n > 1 or len(ref[0]) > 1:
            np.testing.assert_array_equal(fix[:, 1], ref[0][1])
            np.testing.assert_allclose(s, ref[1], rtol=1e-8, atol=1e-10)
        checked += 1
    assert checked >= 20


def test_mlambda_decorrelation_is_unimodular_and_keeps_the_determinant():
    rng = np.random.default_rng(7)
    for n in (2, 4, 6, 10):
        _, Q = _random_problem(rng, n)
        Z, L, D = _core.lambda_decorrelate(Q)
        np.testing.assert_array_equal(Z, np.round(Z))  # integer
        assert abs(abs(np.linalg.det(Z)) - 1.0) < 1e-9  # unimodular
        Qz = Z.T @ Q @ Z
        np.testing.assert_allclose(L.T @ np.diag(D) @ L, Qz, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(np.prod(D), np.linalg.det(Q), rtol=1e-9)
        # decorrelated: the conditional variances are far less spread than the original diagonal
        assert np.max(np.abs(np.tril(L, -1))) <= 0.5 + 1e-9


@pytest.mark.parametrize("n", [6, 12, 20])
def test_mlambda_does_not_depend_on_the_scale_of_q(n):
    """k Q has the same decorrelation Z with k D, the same two integer vectors with norms s / k, and the
    same search, node for node (Chang, Yang & Zhou 2005: integer least squares is scale-free, and with
    the reduction's relative permutation test, lambda.hpp, so is the algorithm).  The scales are powers
    of 4, exact in floating point (and their square roots), so every comparison is the unscaled one.
    A float covariance of a 0.1 mm phase sigma has conditional variances of 1e-7 cycles^2, and an
    absolute test (del + 1e-6 < D) stopped permuting there: the same integers after 10-100x the nodes."""
    rng = np.random.default_rng(50 + n)
    for _ in range(5):
        a_hat, Q = _random_problem(rng, n)
        Z, _, D = _core.lambda_decorrelate(Q)
        fix, s = _core.lambda_search(a_hat, Q)
        st = _core.lambda_search_stats(a_hat, Q)
        assert st["ok"] and st["nodes"] > 0 and st["permutations"] > 0
        for k in (4.0 ** -8, 4.0 ** -15, 4.0 ** 5):  # 1.5e-5, 9.3e-10, 1024
            Zk, _, Dk = _core.lambda_decorrelate(Q * k)
            np.testing.assert_array_equal(Zk, Z)
            np.testing.assert_array_equal(Dk, D * k)
            fk, sk = _core.lambda_search(a_hat, Q * k)
            np.testing.assert_array_equal(fk, fix)
            np.testing.assert_array_equal(np.array(sk) * k, np.array(s))
            assert _core.lambda_search_stats(a_hat, Q * k) == st


# --------------------------------------------------------------------------- double differences


def _synthetic_rows(r_rx, sats_tx, t_rx_bias_m, N, lam, dts_m):
    """Rows for one receiver: exact light-time geometry in the rotating frame, integer ambiguities."""
    m = len(sats_tx)
    rows = np.full((m, int(_core.RTK_ROW_COLS)), np.nan)
    for k, rs in enumerate(sats_tx):
        # exact range: the satellite position at transmission rotated into the ECEF frame at reception
        tau = np.linalg.norm(rs - r_rx) / C
        for _ in range(10):
            th = OMEGA_E * tau
            R = np.array([[np.cos(th), np.sin(th), 0], [-np.sin(th), np.cos(th), 0], [0, 0, 1]])
            tau = np.linalg.norm(R @ rs - r_rx) / C
        rho = C * tau
        P = rho - dts_m[k] + t_rx_bias_m
        rows[k, 0] = k + 1
        rows[k, 1] = 0
        for f in range(2):
            rows[k, 2 + 5 * f] = P
            rows[k, 3 + 5 * f] = (rho - dts_m[k] + t_rx_bias_m) / lam[f] + N[k, f]
            rows[k, 4 + 5 * f] = 0.0
            rows[k, 5 + 5 * f] = 0
            rows[k, 6 + 5 * f] = lam[f]
        rows[k, 17:20] = rs
        rows[k, 20] = dts_m[k]
    return rows


def test_double_differences_equal_analytic_values():
    rng = np.random.default_rng(3)
    lat, lon = np.radians(48.1), np.radians(11.6)
    r_b = np.asarray(earth.geodetic_to_ecef(lat, lon, 500.0), float).ravel()
    C_en = np.array([[-np.sin(lat) * np.cos(lon), -np.sin(lon), -np.cos(lat) * np.cos(lon)],
                     [-np.sin(lat) * np.sin(lon), np.cos(lon), -np.cos(lat) * np.sin(lon)],
                     [np.cos(lat), 0.0, -np.sin(lat)]])
    r_r = r_b + C_en @ np.array([700.0, -450.0, 12.0])
    sats = []
    for el, az in zip(np.radians([80, 55, 40, 30, 22, 65, 35]), np.radians([10, 70, 140, 200, 260, 300, 330])):
        u_n = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
        u = C_en @ u_n
        # a point 26 560 km from the Earth's centre along the line of sight
        b = 2 * r_b @ u
        c = r_b @ r_b - 26_560_000.0 ** 2
        d = (-b + np.sqrt(b * b - 4 * c)) / 2
        sats.append(r_b + d * u)
    lam = np.array([C / 1575.42e6, C / 1227.60e6])
    N_r = rng.integers(-1_000_000, 1_000_000, size=(len(sats), 2))
    N_b = rng.integers(-1_000_000, 1_000_000, size=(len(sats), 2))
    dts = rng.normal(scale=3e4, size=len(sats))
    rows_r = _synthetic_rows(r_r, sats, 1234.5, N_r, lam, dts)
    rows_b = _synthetic_rows(r_b, sats, -98765.4, N_b, lam, dts)
    opt = rtk.RtkOptions(tropo_model=False, elevation_mask_deg=10.0).core_dict()
    dd = _core.rtk_double_differences(rows_r, rows_b, r_r, r_b, opt)
    assert np.sum(dd["is_code"] == 0) == 2 * (len(sats) - 1) and np.sum(dd["is_code"] == 1) == 2 * (len(sats) - 1)
    for j, i, f, code, v in zip(dd["sat_row"], dd["ref_row"], dd["freq"], dd["is_code"], dd["value_m"]):
        expected = 0.0 if code else lam[f] * ((N_r[j, f] - N_b[j, f]) - (N_r[i, f] - N_b[i, f]))
        assert abs(v - expected) < 1e-6, (j, i, f, code, v - expected)
    # the reference is the highest satellite
    assert set(dd["ref_row"]) == {0}


def test_double_differences_with_qzss_have_their_own_reference_satellite():
    """GPS and QZSS on L1/L2 (the same frequencies): every row's reference is of its own system, the
    highest of that system, and the values are the analytic double-differenced ambiguities."""
    rng = np.random.default_rng(11)
    lat, lon = np.radians(35.7), np.radians(139.8)
    r_b = np.asarray(earth.geodetic_to_ecef(lat, lon, 40.0), float).ravel()
    C_en = np.array([[-np.sin(lat) * np.cos(lon), -np.sin(lon), -np.cos(lat) * np.cos(lon)],
                     [-np.sin(lat) * np.sin(lon), np.cos(lon), -np.cos(lat) * np.sin(lon)],
                     [np.cos(lat), 0.0, -np.sin(lat)]])
    r_r = r_b + C_en @ np.array([-350.0, 820.0, -3.0])
    el_deg = [62, 48, 35, 27, 20, 85, 71, 40]  # five GPS, then three QZSS (the highest satellite is QZSS)
    az_deg = [20, 110, 170, 250, 320, 200, 160, 300]
    system = np.array([0, 0, 0, 0, 0, 4, 4, 4])
    radius = np.where(system == 4, 42_164_000.0, 26_560_000.0)
    sats = []
    for el, az, rad in zip(np.radians(el_deg), np.radians(az_deg), radius):
        u = C_en @ np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
        b, c = 2 * r_b @ u, r_b @ r_b - rad ** 2
        sats.append(r_b + (-b + np.sqrt(b * b - 4 * c)) / 2 * u)
    lam = np.array([C / 1575.42e6, C / 1227.60e6])
    N_r = rng.integers(-1_000_000, 1_000_000, size=(len(sats), 2))
    N_b = rng.integers(-1_000_000, 1_000_000, size=(len(sats), 2))
    dts = rng.normal(scale=3e4, size=len(sats))
    rows_r = _synthetic_rows(r_r, sats, 4321.0, N_r, lam, dts)
    rows_b = _synthetic_rows(r_b, sats, -55555.5, N_b, lam, dts)
    prn = np.array([3, 8, 14, 22, 27, 2, 3, 7])  # G03 and J03 both: the key is system and number
    for rows in (rows_r, rows_b):
        rows[:, 0] = system * 64 + prn
        rows[:, 1] = system
    opt = rtk.RtkOptions(tropo_model=False, elevation_mask_deg=10.0, systems="GJ").core_dict()
    dd = _core.rtk_double_differences(rows_r, rows_b, r_r, r_b, opt)
    n_dd = 2 * ((5 - 1) + (3 - 1))  # per frequency, one reference per system
    assert np.sum(dd["is_code"] == 0) == n_dd and np.sum(dd["is_code"] == 1) == n_dd
    assert np.array_equal(system[dd["sat_row"]], system[dd["ref_row"]])
    assert set(dd["ref_row"][system[dd["sat_row"]] == 0].tolist()) == {0}  # G03, 62 deg
    assert set(dd["ref_row"][system[dd["sat_row"]] == 4].tolist()) == {5}  # J02, 85 deg
    for j, i, f, code, v in zip(dd["sat_row"], dd["ref_row"], dd["freq"], dd["is_code"], dd["value_m"]):
        expected = 0.0 if code else lam[f] * ((N_r[j, f] - N_b[j, f]) - (N_r[i, f] - N_b[i, f]))
        assert abs(v - expected) < 1e-6, (j, i, f, code, v - expected)


# --------------------------------------------------------------------------- cycle slips


def _spirent(shared_data):
    d = shared_data / "instinct_spirent_rtk_dynamic_SIMULATED"
    if not d.is_dir():
        pytest.skip("Spirent RTK data not in ../shared/data")
    return d


def _rows_of(obs, nf):
    m = len(obs)
    rows = np.full((m, int(_core.RTK_ROW_COLS)), np.nan)
    si = np.array([rtk.SYSTEM_INDEX[s] for s in obs.system])
    rows[:, 0] = si * 64 + obs.prn
    rows[:, 1] = si
    lam = rtk.wavelengths(obs)
    for f in range(nf):
        rows[:, 2 + 5 * f] = obs.code_m[:, f]
        rows[:, 3 + 5 * f] = obs.phase_cycles[:, f]
        rows[:, 4 + 5 * f] = obs.doppler_hz[:, f]
        rows[:, 5 + 5 * f] = obs.lli[:, f]
        rows[:, 6 + 5 * f] = lam[:, f]
    off = np.searchsorted(obs.epoch, np.arange(obs.epoch_t_gps_s.size + 1)).astype(np.int64)
    return off, rows


def _inject(obs, rng, cycles, slot, spacing=6):
    """Add `cycles` to the phase of slot `slot` from a set of (epoch, satellite) onwards; return the rows hit."""
    ph = obs.phase_cycles.copy()
    hits = []
    sats = sorted(set(zip(obs.system.tolist(), obs.prn.tolist())))
    for j, (s, p) in enumerate(sats):  # staggered: a few satellites slip at any one epoch
        rows = np.flatnonzero((obs.system == s) & (obs.prn == p) & np.isfinite(ph[:, slot]))
        for k in range(spacing + j % spacing, rows.size - 1, spacing):
            if rng.random() < 0.5:
                ph[rows[k:], slot] += cycles
                hits.append(rows[k])
    return ph, np.array(sorted(hits))


@pytest.mark.parametrize("cycles", [1, 2, 10])
def test_dual_frequency_slips_detected_without_false_alarms(shared_data, cycles):
    d = _spirent(shared_data)
    obs = rtk.read_phase_obs(d / "iono-Klob_tropo-Saast" / "Rover-dynamic_MO_Spirent.obs", "GE")
    opt = rtk.RtkOptions(frequencies=2).core_dict()
    off, rows = _rows_of(obs, 2)
    clean = _core.slip_detect(obs.epoch_t_gps_s, off, rows, opt)
    assert not clean.any(), "false alarm on clean data"
    rng = np.random.default_rng(cycles)
    for slot in (0, 1):
        o2 = rtk.PhaseObs(**{**obs.__dict__, "phase_cycles": _inject(obs, rng, cycles, slot)[0]})
        ph, hits = _inject(obs, np.random.default_rng(10 * cycles + slot), cycles, slot)
        o2.phase_cycles = ph
        _, rows2 = _rows_of(o2, 2)
        fl = _core.slip_detect(obs.epoch_t_gps_s, off, rows2, opt)
        flagged = fl[:, :2].any(axis=1)
        assert hits.size > 100
        rate = flagged[hits].mean()
        assert rate >= 0.99, (slot, rate)
        others = np.ones(len(obs), bool)
        others[hits] = False
        assert not flagged[others].any(), "false alarm beside the injected slips"


def test_single_frequency_doppler_slip_test(shared_data):
    """Single frequency: the Doppler-predicted phase flags slips above its threshold (1 cycle by default);
    slips of 2 and 10 cycles on this 1 Hz drive are all found, with no false alarm."""
    d = _spirent(shared_data)
    obs = rtk.read_phase_obs(d / "iono-Klob_tropo-Saast" / "Rover-dynamic_MO_Spirent.obs", "GE")
    opt = rtk.RtkOptions(frequencies=1).core_dict()
    off, rows = _rows_of(obs, 1)
    assert not _core.slip_detect(obs.epoch_t_gps_s, off, rows, opt).any()
    for cycles in (2, 10):
        ph, hits = _inject(obs, np.random.default_rng(cycles), cycles, 0)
        o2 = rtk.PhaseObs(**{**obs.__dict__, "phase_cycles": ph})
        _, rows2 = _rows_of(o2, 1)
        fl = _core.slip_detect(obs.epoch_t_gps_s, off, rows2, opt)[:, 0] != 0
        assert fl[hits].mean() >= 0.99
        others = np.ones(len(obs), bool)
        others[hits] = False
        assert not fl[others].any()


# --------------------------------------------------------------------------- real static pair


def _matrtklib(shared_data):
    d = shared_data / "matrtklib_static_septentrio"
    if not d.is_dir():
        pytest.skip("MatRTKLIB static data not in ../shared/data")
    return d


def _llh(p):
    lat, lon, h = np.loadtxt(p)
    return np.asarray(earth.geodetic_to_ecef(np.radians(lat), np.radians(lon), h), float).ravel()


def test_static_pair_fixes_to_the_known_baseline(shared_data):
    d = _matrtklib(shared_data)
    rb, rt = _llh(d / "base_position.txt"), _llh(d / "rover_position.txt")
    sol = rtk.solve_rtk(d / "rover.obs", d / "base.obs", d / "base.nav", r_base_e=rb,
                        options=dict(mode="static", ar_mode="continuous", frequencies=2, systems="GREC"))
    fixed = sol.status == 1
    assert fixed.mean() >= 0.99
    err = np.linalg.norm(sol.r_e[fixed] - rt, axis=1)
    assert err.max() < 0.01
    base_line = np.linalg.norm(sol.r_e[fixed][-1] - rb)
    assert abs(base_line - np.linalg.norm(rt - rb)) < 0.01
    # consistency: the fixed solution's sigma is of the order of its error
    sig = np.sqrt(np.trace(sol.P_r[fixed][-1]))
    assert 0.1 < np.sqrt(np.mean(err ** 2)) / sig < 10.0


def test_qzss_double_differences_join_gps_on_the_static_pair(shared_data):
    """GPS + QZSS, L1 + L2, single-epoch AR on the real pair: the QZSS satellites add double
    differences (one reference of their own) and the fixed positions are at the truth (single-epoch
    3-D RMS below 1 cm, no error above 2 cm)."""
    d = _matrtklib(shared_data)
    rb, rt = _llh(d / "base_position.txt"), _llh(d / "rover_position.txt")
    sols = {sy: rtk.solve_rtk(d / "rover.obs", d / "base.obs", d / "base.nav", r_base_e=rb,
                              options=dict(ar_mode="instantaneous", frequencies=2, systems=sy)) for sy in ("G", "GJ")}
    g, gj = sols["G"], sols["GJ"]
    assert np.all(gj.n_sat - g.n_sat == 2)  # J03 and J07 above the 15 deg mask (J02 below the horizon)
    assert np.all(gj.n_dd - g.n_dd == 2)  # one more double difference per frequency
    fixed = gj.status == 1
    assert fixed.mean() >= 0.99
    err = np.linalg.norm(gj.r_e[fixed] - rt, axis=1)
    assert np.sqrt(np.mean(err ** 2)) < 0.01 and err.max() < 0.02


def test_fast_reader_matches_the_rinex_reader(shared_data):
    from insnav.gnss.rinex import read_rinex_obs

    d = _matrtklib(shared_data)
    fast = rtk.read_phase_obs(d / "rover.obs", "GE")
    ref = read_rinex_obs(d / "rover.obs", systems="GE")
    for s in "GE":
        a = fast.system == s
        b = ref.system == s
        np.testing.assert_array_equal(fast.prn[a], ref.prn[b])
        np.testing.assert_array_equal(fast.code_m[a, 0], ref.C1[b])
        np.testing.assert_array_equal(fast.phase_cycles[a, 0], np.where(ref.L1[b] == 0, np.nan, ref.L1[b]))
    np.testing.assert_array_equal(fast.epoch_t_gps_s, ref.epoch_t_gps_s)
    assert fast.signals["G"][:2] == ["1C", "2W"] and fast.signals["E"][:2] == ["1C", "7Q"]


#: the RINEX 2.11 types written by _rinex2_copy, per frequency slot of rtk.SIGNALS (C L D S) and system
_V2_SLOT_TYPES = {"G": ("C1 L1 D1 S1", "P2 L2 D2 S2", "C5 L5 D5 S5"),
                  "R": ("C1 L1 D1 S1", "P2 L2 D2 S2", None),
                  "E": ("C1 L1 D1 S1", "C7 L7 D7 S7", "C5 L5 D5 S5")}


def _rinex2_copy(rinex3_path, out_path, chosen, n_epochs, lli_on=None):
    """A RINEX 2.11 file of the first epochs of a RINEX 3 file: each slot's fields (value, LLI and
    signal strength, character for character) of the signal ``chosen[system][slot]`` under the RINEX 2
    types of :data:`_V2_SLOT_TYPES`; GPS, GLONASS and Galileo satellites.  ``lli_on = (epoch, sat id)``
    sets the L2 loss-of-lock digit of that satellite to 1."""
    v2_types = ["C1", "L1", "D1", "S1", "P2", "L2", "D2", "S2", "C5", "L5", "D5", "S5", "C7", "L7", "D7", "S7"]
    lines = rinex3_path.read_text().splitlines()
    types3, i = {}, 0
    while "END OF HEADER" not in lines[i]:
        ln = lines[i]
        if ln[60:].strip() == "SYS / # / OBS TYPES":
            if ln[0] != " ":
                cur = ln[0]
                types3[cur] = []
            types3[cur] += ln[7:60].split()
        i += 1
    out = ["     2.11           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE",
           "  4075580.8863   931853.5784  4801567.9707                  APPROX POSITION XYZ",
           "        0.0710        0.0000        0.0000                  ANTENNA: DELTA H/E/N",
           f"{len(v2_types):6d}" + "".join(f"{t:>6s}" for t in v2_types[:9]).ljust(54) + "# / TYPES OF OBSERV",
           "      " + "".join(f"{t:>6s}" for t in v2_types[9:]).ljust(54) + "# / TYPES OF OBSERV",
           "  2020     6    25     0     0    0.0000000     GPS         TIME OF FIRST OBS",
           " " * 60 + "END OF HEADER"]
    i += 1
    for e in range(n_epochs):
        ep = lines[i]
        nsat = int(ep[32:35])
        recs = [ln for ln in lines[i + 1:i + 1 + nsat] if ln[0] in _V2_SLOT_TYPES]
        i += 1 + nsat
        y, mo, d, h, mi, sec = ep[4:6], int(ep[7:9]), int(ep[10:12]), int(ep[13:15]), int(ep[16:18]), float(ep[18:29])
        ids = [r[:3] for r in recs]
        head = f" {y} {mo:2d} {d:2d} {h:2d} {mi:2d}{sec:11.7f}  0{len(ids):3d}"
        for k in range(0, len(ids), 12):  # 12 satellites per line, continuation lines indented
            out.append((head if k == 0 else " " * 32) + "".join(ids[k:k + 12]))
        for r in recs:
            fields = {t: "" for t in v2_types}
            for slot, names in enumerate(_V2_SLOT_TYPES[r[0]]):
                sig = chosen[r[0]][slot]
                if names is None or not sig:
                    continue
                for kind, name in zip("CLDS", names.split()):
                    t3 = kind + sig
                    if t3 in types3[r[0]]:
                        col = types3[r[0]].index(t3)
                        fields[name] = r[3 + 16 * col:3 + 16 * col + 16]
            if lli_on == (e, r[:3]) and fields["L2"].strip():
                fields["L2"] = fields["L2"][:14].ljust(14) + "1" + fields["L2"][15:16]
            row = [fields[t].ljust(16) for t in v2_types]
            for k in range(0, len(row), 5):
                out.append("".join(row[k:k + 5]).rstrip())
    out_path.write_text("\n".join(out) + "\n")


def test_rinex2_l2_phase_reads_as_the_rinex3_of_the_same_data(shared_data, tmp_path):
    """WTZR's RINEX 3 records rewritten as RINEX 2.11 (16 types, 4 lines per satellite, 12-satellite
    epoch lines continued): code, phase, Doppler, C/N0 and LLI of L1, L2 and L5/E5b/E5a read the same."""
    w = shared_data / "euref_wettzell_wtzr_wtzz"
    if not w.is_dir():
        pytest.skip("WTZR/WTZZ data not in ../shared/data")
    r3 = w / "WTZR00DEU_R_20201770000_01D_30S_MO_120epoch.rnx"
    v3 = rtk.read_phase_obs(r3, "GRE")
    assert v3.signals["G"] == ["1C", "2W", "5Q"] and v3.signals["E"] == ["1C", "7Q", "5Q"]
    n_ep = 6
    keep = v3.epoch < n_ep
    sat = np.array([f"{s}{p:02d}" for s, p in zip(v3.system[keep], v3.prn[keep])])
    lli_sat = sat[(v3.epoch[keep] == 2) & (v3.system[keep] == "G")][0]
    r2 = tmp_path / "wtzr_copy.20o"
    _rinex2_copy(r3, r2, v3.signals, n_ep, lli_on=(2, lli_sat))
    v2 = rtk.read_phase_obs(r2, "GRE")
    np.testing.assert_array_equal(v2.epoch_t_gps_s, v3.epoch_t_gps_s[:n_ep])
    np.testing.assert_array_equal(v2.system, v3.system[keep])
    np.testing.assert_array_equal(v2.prn, v3.prn[keep])
    glo = v2.system == "R"
    for a, b in ((v2.code_m, v3.code_m), (v2.phase_cycles, v3.phase_cycles), (v2.doppler_hz, v3.doppler_hz),
                 (v2.cn0_dbhz, v3.cn0_dbhz)):
        np.testing.assert_array_equal(a[~glo], b[keep][~glo])
        np.testing.assert_array_equal(a[glo, :2], b[keep][glo, :2])
        assert np.all(np.isnan(a[glo, 2]))  # RINEX 2 has no GLONASS G3
    assert np.isfinite(v2.phase_cycles[:, 1]).mean() > 0.9  # L2 (E5b) phase read
    hit = (v2.epoch == 2) & (sat == lli_sat)
    assert v2.lli[hit, 1].tolist() == [1] and v3.lli[keep][hit, 1].tolist() == [0]
    np.testing.assert_array_equal(v2.lli[~hit], v3.lli[keep][~hit])
    assert v2.signals["G"] == ["1C", "2W", "5X"] and v2.signals["R"][1] == "2P"
    np.testing.assert_allclose(v2.antenna_hen_m, [0.071, 0.0, 0.0])
    # the wavelengths follow the bands: L2 of GPS, E5b of Galileo
    lam = rtk.wavelengths(v2)
    g, e = v2.system == "G", v2.system == "E"
    np.testing.assert_allclose(lam[g, 1], C / 1227.60e6)
    np.testing.assert_allclose(lam[e, 1], C / 1207.14e6)


# --------------------------------------------------------------------------- bad input


def _write_obs(path, sats, types="C1C L1C", approx=True, n_epochs=3):
    ty = types.split()
    lines = ["     3.04           OBSERVATION DATA    M                   RINEX VERSION / TYPE"]
    if approx:
        lines.append("  4075580.8863   931853.5784  4801567.9707                  APPROX POSITION XYZ")
    lines.append(f"G{len(ty):5d}" + "".join(f" {t}" for t in ty).ljust(54) + "SYS / # / OBS TYPES")
    lines.append("  2020     6    25     0     0    0.0000000     GPS         TIME OF FIRST OBS")
    lines.append(" " * 60 + "END OF HEADER")
    for e in range(n_epochs):
        lines.append(f"> 2020 06 25 00 00{30.0 * e:11.7f}  0{len(sats):3d}")
        for p in sats:
            vals = "".join(f"{(2.2e7 + 1000 * p) if t[0] == 'C' else (1.1e8 + p):14.3f}  " for t in ty)
            lines.append(f"G{p:02d}{vals}")
    path.write_text("\n".join(lines) + "\n")


def test_bad_input_errors_name_the_file(tmp_path, shared_data):
    d = shared_data / "euref_wettzell_wtzr_wtzz"
    if not d.is_dir():
        pytest.skip("WTZR/WTZZ data not in ../shared/data")
    nav = d / "ESBC00DNK_R_20201770000_01D_MN.rnx"
    rover = tmp_path / "rover.rnx"
    _write_obs(rover, [1, 3, 8, 14, 17])
    no_phase = tmp_path / "base_code_only.rnx"
    _write_obs(no_phase, [1, 3, 8, 14, 17], types="C1C")
    other = tmp_path / "base_other_sats.rnx"
    _write_obs(other, [2, 4, 6, 9])
    no_pos = tmp_path / "base_no_position.rnx"
    _write_obs(no_pos, [1, 3, 8, 14, 17], approx=False)
    opt = dict(systems="G", frequencies=1)
    with pytest.raises(rtk.RtkInputError, match=f"{no_phase}: the base has no carrier phase"):
        rtk.solve_rtk(rover, no_phase, nav, options=opt)
    with pytest.raises(rtk.RtkInputError, match=f"{other}: no satellite in common"):
        rtk.solve_rtk(rover, other, nav, options=opt)
    with pytest.raises(rtk.RtkInputError, match=f"{no_pos}: base position missing"):
        rtk.solve_rtk(rover, no_pos, nav, options=opt)
    # the command line: one line naming the file, exit status 1... or 2, never a traceback
    p = subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "rtk", "--format", "rinex", "--obs",
                        str(rover), "--base", str(no_phase), "--nav", str(nav), "--out", str(tmp_path / "x.pos")],
                       capture_output=True, text=True)
    assert p.returncode != 0
    err = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(err) == 1 and str(no_phase) in err[0] and "Traceback" not in p.stderr
    assert not (tmp_path / "x.pos").exists()


def test_lower_rate_base_is_held(shared_data):
    """A base at 1/5 of the rover rate: the last base epoch is held (max_age_s); the rover still fixes
    every epoch to the known position."""
    d = _matrtklib(shared_data)
    rb, rt = _llh(d / "base_position.txt"), _llh(d / "rover_position.txt")
    base = rtk.read_phase_obs(d / "base.obs", "GE")
    keep_ep = np.flatnonzero(np.arange(base.epoch_t_gps_s.size) % 5 == 0)
    rows = np.isin(base.epoch, keep_ep)
    new_ep = np.searchsorted(keep_ep, base.epoch[rows])
    slow = rtk.PhaseObs(**{**base.__dict__, "epoch_t_gps_s": base.epoch_t_gps_s[keep_ep], "epoch": new_ep,
                           "system": base.system[rows], "prn": base.prn[rows], "code_m": base.code_m[rows],
                           "phase_cycles": base.phase_cycles[rows], "doppler_hz": base.doppler_hz[rows],
                           "cn0_dbhz": base.cn0_dbhz[rows], "lli": base.lli[rows]})
    sol = rtk.solve_rtk(d / "rover.obs", slow, d / "base.nav", r_base_e=rb,
                        options=dict(systems="GE", frequencies=2, max_age_s=10.0))
    assert np.nanmax(sol.base_age_s) == pytest.approx(4.0)
    fixed = sol.status == 1
    assert fixed.mean() >= 0.95
    assert np.linalg.norm(sol.r_e[fixed] - rt, axis=1).max() < 0.03
    # beyond max_age_s no solution
    idx = rtk.match_base([10.0, 20.0, 45.0], [0.0, 15.0], 10.0)
    np.testing.assert_array_equal(idx, [0, 1, -1])


def test_transmit_states_equal_the_iterated_light_time(shared_data):
    """One orbit evaluation per epoch and satellite, carried by a Taylor step to each row: the same
    satellite position (1e-6 m) and clock as evaluating each row at its own t_tx = t - P/c - dt^s,
    for every system (BeiDou GEO/IGSO included: 120 ms of signal time)."""
    from insnav.gnss.broadcast import sat_states_multi
    from insnav.gnss.spp import read_nav_multi

    d = _matrtklib(shared_data)
    o = rtk.read_phase_obs(d / "rover.obs", "GREC")
    nav = read_nav_multi(d / "base.nav", "GREC")
    P = rtk._first_code(o)
    t = o.epoch_t_gps_s[o.epoch]
    rs, clk = rtk.transmit_states(nav, t, o.system, o.prn, P)
    tt = t - P / C
    for _ in range(3):
        st = sat_states_multi(nav, tt, system=o.system, prn=o.prn, group_delay=False)
        tt = t - P / C - np.nan_to_num(st.clock_bias_s)
    ok = np.isfinite(st.r_e[:, 0])
    assert np.array_equal(ok, np.isfinite(rs[:, 0]))
    assert set(o.system[ok]) == set("GREC")
    assert np.max(np.linalg.norm(rs[ok] - st.r_e[ok], axis=1)) < 1e-6
    assert np.max(np.abs(clk[ok] - C * st.clock_bias_s[ok])) < 1e-6


def test_kinematic_velocity_is_nan_where_no_epoch_has_observed_it(shared_data):
    """The velocity state starts at its prior, zero: the first epoch of a kinematic run (every epoch
    with instantaneous AR) printed 0 m/s for a moving rover.  Now NaN there; from the second epoch on
    the static pair's kinematic velocity is within 2 cm/s of zero; static mode is zero by definition."""
    d = _matrtklib(shared_data)
    files = (d / "rover.obs", d / "base.obs", [d / "base.nav"])
    kw = dict(systems="G", frequencies=1)
    v = rtk.solve_rtk(*files, options=dict(kw, mode="kinematic")).v_e
    assert np.all(np.isnan(v[0])) and np.isfinite(v[1:]).all() and np.abs(v[1:]).max() < 0.02
    assert np.isnan(rtk.solve_rtk(*files, options=dict(kw, mode="kinematic", ar_mode="instantaneous")).v_e).all()
    assert np.all(rtk.solve_rtk(*files, options=dict(kw, mode="static")).v_e == 0.0)


def test_cli_run_writes_rtklib_pos_and_evaluate_reports_the_fix_rate(tmp_path, shared_data):
    d = _matrtklib(shared_data)
    cfg = tmp_path / "rtk.toml"
    cfg.write_text('filter = "rtk"\n[rtk]\nsystems = "GE"\nfrequencies = 1\nar_mode = "instantaneous"\n')
    out = tmp_path / "rtk.pos"
    p = subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "rtk", "--format", "rinex", "--obs",
                        str(d / "rover.obs"), "--base", str(d / "base.obs"), "--nav", str(d / "base.nav"),
                        "--base-pos", "35.134707705,136.977577939,104.853", "--config", str(cfg), "--out", str(out),
                        "--quiet"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "301 epochs, 301 fixed" in p.stdout
    assert (tmp_path / "rtk.pos.rtk.csv").exists() and (tmp_path / "rtk.pos.config.toml").exists()
    from insnav.io.gnss_files import read_rtklib_pos

    ref = read_rtklib_pos(out)  # RTKLIB's layout, read by the RTKLIB .pos reader
    assert len(ref.q) == 301 and np.all(ref.q == 1)
    rt = _llh(d / "rover_position.txt")
    assert np.max(np.linalg.norm(ref.r_e - rt, axis=1)) < 0.02
    e = subprocess.run([sys.executable, "-m", "insnav", "evaluate", str(out), "35.13469901,136.97757549,104.8626"],
                       capture_output=True, text=True)
    assert e.returncode == 0, e.stderr
    assert "fix rate 100.0 %; fixed 301" in e.stdout
    # against RTKLIB's own .pos of the same pair (a .pos against a .pos: the solution taken at the reference's
    # epochs raised AttributeError: no sigmas in a .pos); both fixed at the antenna to millimetres
    e = subprocess.run([sys.executable, "-m", "insnav", "evaluate", str(out), str(d / "rover_rtk.pos"), "--json"],
                       capture_output=True, text=True)
    assert e.returncode == 0, e.stderr
    res = json.loads(e.stdout)
    assert res["samples"] == 301 and res["fix_rate"] == 1.0 and res["by_status"]["fixed"]["samples"] == 301
    assert res["rms_3d_m"] < 0.005 and "pos_n_m" not in res["consistency"]  # no covariance in a .pos


def test_fast_reader_errors_name_file_and_line(tmp_path):
    from insnav.gnss.rinex import RinexError

    good = tmp_path / "good.rnx"
    _write_obs(good, [1, 3, 8])
    lines = good.read_text().splitlines()
    bad_num = tmp_path / "bad_number.rnx"
    k = next(i for i, ln in enumerate(lines) if ln.startswith("G03"))
    bad_num.write_text("\n".join(lines[:k] + [lines[k][:5] + "x" + lines[k][6:]] + lines[k + 1:]) + "\n")
    with pytest.raises(RinexError, match=rf"{bad_num}, line {k + 1}: bad number"):
        rtk.read_phase_obs(bad_num, "G")
    short = tmp_path / "truncated.rnx"
    short.write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(RinexError, match=rf"{short}, line \d+: unexpected end of file"):
        rtk.read_phase_obs(short, "G")
    with pytest.raises(RinexError, match="cannot read file"):
        rtk.read_phase_obs(tmp_path / "missing.rnx", "G")


@pytest.mark.slow
def test_matches_or_beats_rnx2rtkp_on_matrtklib(tmp_path, shared_data):
    """Paired with docs/results/rtk_matrtklib_static_septentrio.md: the same files and options through
    RTKLIB's rnx2rtkp and insnav; insnav's fix rate at least RTKLIB's, its RMS of fixed epochs at
    most 1.2x, no wrong fix."""
    import shutil

    if shutil.which("rnx2rtkp") is None:
        pytest.skip("rnx2rtkp (Debian rtklib) not installed")
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("rtk_compare", Path(__file__).resolve().parents[1] / "bench"
                                                  / "rtk_compare.py")
    rc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rc)
    rc.DATA = shared_data
    ds = rc.datasets()["matrtklib_static_septentrio"]
    rc.CONF_DIR = tmp_path
    r = rc.run_setting(ds, ds["settings"][0], 1, tmp_path)
    a, b = r["insnav"], r["rtklib"]
    assert a["fix_rate"] >= b["fix_rate"]
    assert a["rms_fixed_mm"] <= 1.2 * b["rms_fixed_mm"]
    assert a["wrong"] == 0


def test_gpst_texts_equal_the_calendar_of_datetime():
    """RTKLIB's time form of whole arrays (integer milliseconds split into days and time of day)
    equals datetime's calendar for each time, half-millisecond ties rounded to even as round() does."""
    import datetime

    def one(t):
        ms = int(round(t * 1000.0))
        d = datetime.datetime(1980, 1, 6) + datetime.timedelta(milliseconds=ms)
        return d.strftime("%Y/%m/%d %H:%M:%S") + f".{ms % 1000:03d}"

    rng = np.random.default_rng(7)
    t = np.concatenate([rng.uniform(0.0, 2.0e9, 3000),  # 1980 .. 2043
                        np.round(rng.uniform(1.0e9, 1.5e9, 500)) + 0.0005,  # ties
                        1.0e9 + 86400.0 * np.arange(-3, 4) - 0.0004,  # just before midnight
                        [0.0, 86399.9995, 604800.0 * 2000]])
    assert rtk._gpst_texts(t) == [one(x) for x in t]


def test_rtklib_pos_rows_equal_the_per_epoch_enu_rotation(tmp_path):
    """write_rtklib_pos rotates every epoch's ECEF covariance to ENU at once; each row must equal the
    row of the per-epoch product Q = C P C^T (C: ENU <- ECEF at the epoch's latitude and longitude),
    with sdn, sde, sdu the square roots of Q's diagonal and sdne, sdeu, sdun sign(q) sqrt(|q|)."""
    import math

    rng = np.random.default_rng(11)
    n = 40
    lat = rng.uniform(-1.4, 1.4, n)
    lon = rng.uniform(-3.1, 3.1, n)
    r_e = np.stack([np.asarray(earth.geodetic_to_ecef(a, b, h), float).ravel()
                    for a, b, h in zip(lat, lon, rng.uniform(-50.0, 3000.0, n))])
    A = rng.normal(scale=0.02, size=(n, 3, 3))
    P_r = A @ A.transpose(0, 2, 1)
    status = rng.choice([0, 1, 2, 4], n)
    age = np.where(rng.random(n) < 0.2, np.nan, rng.uniform(0.0, 3.0, n))
    t = 1.4e9 + np.arange(n) * 0.5
    sol = rtk.RtkSolution(t_gps_s=t, status=status, ratio=rng.uniform(0.0, 50.0, n), success_rate=np.ones(n),
                          n_fix=np.zeros(n, int), n_dd=np.zeros(n, int), n_sat=rng.integers(4, 30, n), r_e=r_e,
                          v_e=np.zeros((n, 3)), r_float_e=r_e.copy(), P_r=P_r, slips=np.zeros((n, 6), int),
                          base_age_s=age, r_base_e=r_e[0], info=dict(rover="r.obs", base="b.obs"))
    lines = [ln for ln in rtk.write_rtklib_pos(sol, tmp_path / "x.pos").read_text().splitlines()
             if not ln.startswith("%")]
    ok = np.flatnonzero(status > 0)
    assert len(lines) == ok.size > 0
    la, lo, h = earth.ecef_to_geodetic(r_e[ok])
    for i, (k, line) in enumerate(zip(ok, lines)):
        sl, cl, so, co = np.sin(la[i]), np.cos(la[i]), np.sin(lo[i]), np.cos(lo[i])
        C = np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])
        Q = C @ P_r[k] @ C.T
        sd = np.sqrt(np.maximum(np.diag(Q), 0.0))
        f = line.split()
        assert f[1] == rtk._gpst_texts([t[k]])[0].split()[1]
        assert [float(x) for x in f[2:5]] == pytest.approx([np.degrees(la[i]), np.degrees(lo[i]), h[i]], abs=1e-4)
        assert (int(f[5]), int(f[6])) == (status[k], sol.n_sat[k])
        assert f[7:13] == [f"{v:.4f}" for v in (sd[1], sd[0], sd[2], *(math.copysign(math.sqrt(abs(q)), q) for q in
                                                                       (Q[1, 0], Q[0, 2], Q[2, 1])))]
        assert f[13] == f"{age[k] if np.isfinite(age[k]) else 0.0:.2f}"
