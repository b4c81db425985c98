"""Is the RTK reference of the u-blox walk (rtklibexplorer walk_0827) offset?  An experiment.

The tight solutions of ``bench/tight_multignss.py --walk`` sit a nearly constant
~8 m from ``raw/gnss_1730_sf.pos``.  This script compares, at the reference
epochs (matched by GPS time of week):

* the receiver's own fix: UBX NAV-PVT (class 0x01, id 0x07) read from
  ``raw/gnss_1730.ubx`` (:func:`read_nav_pvt`), with its carrier-solution flag;
* the ``.pos`` reference as published (its ``height`` column compared with the
  NAV-PVT ellipsoidal height and height above mean sea level);
* insnav single point (``insnav run --filter spp``, i.e.
  :func:`insnav.filters.spp.run_spp_rinex`) with GPS + Galileo + BeiDou and with
  each system alone (independent orbits, clocks and signals);
* RTKLIB's own single point (``rnx2rtkp -p 0``) on the same RINEX files, when
  ``rnx2rtkp`` is on the PATH (Debian package ``rtklib``): an independent
  implementation of the same geometry;
* per-satellite pseudorange residuals at the reference position and at the
  single-point position.

``bench/tight_multignss.py --walk`` imports :func:`reference_experiment` and adds
the tight solutions.

Reproduce (from the repository root)::

    python3 bench/walk_reference_check.py
"""
from __future__ import annotations

import argparse
import os
import shutil
import struct
import subprocess
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from insnav import earth  # noqa: E402
from insnav.gnss.measurements import RtklibPos  # noqa: E402
from insnav.io.gnss_files import read_rtklib_pos  # noqa: E402

SECONDS_PER_WEEK = 604800.0
DEG = np.pi / 180.0
#: NAV-PVT ``flags`` bits 6-7 (carrSoln): 0 none, 1 RTK float, 2 RTK fixed
CARR_SOLN = {0: "none", 1: "float", 2: "fixed"}


def ubx_frames(data: bytes, msg_class: int, msg_id: int):
    """Payloads (bytes) of every checksum-valid UBX frame of one class/id, in file order.

    Frame: 0xB5 0x62, class, id, u16 length (LE), payload, CK_A, CK_B (8-bit
    Fletcher over class..payload, UBX protocol "UBX checksum").
    """
    out = []
    i = data.find(b"\xb5\x62")
    while 0 <= i and i + 8 <= len(data):
        n = struct.unpack_from("<H", data, i + 4)[0]
        end = i + 8 + n
        if end > len(data):
            break
        body = np.frombuffer(data, np.uint8, 4 + n, i + 2).astype(np.int64)
        ck_a = int(body.sum()) & 0xFF
        ck_b = int(np.dot(np.arange(body.size, 0, -1), body)) & 0xFF
        if ck_a == data[end - 2] and ck_b == data[end - 1]:
            if data[i + 2] == msg_class and data[i + 3] == msg_id:
                out.append(data[i + 6:end - 2])
            i = data.find(b"\xb5\x62", end)
        else:
            i = data.find(b"\xb5\x62", i + 1)
    return out


def read_nav_pvt(path) -> dict:
    """UBX NAV-PVT records of a u-blox log -> dict of (n,) arrays.

    Keys: ``tow_s`` (iTOW, GPS time of week), ``fix_type``, ``gnss_fix_ok``,
    ``diff_soln``, ``carr_soln`` (0 none, 1 float, 2 fixed), ``num_sv``,
    ``lat_deg``, ``lon_deg``, ``h_m`` (height above the ellipsoid), ``h_msl_m``,
    ``h_acc_m``, ``v_acc_m``, ``v_n_mps`` (n, 3) NED.  Offsets from the u-blox
    M9/F9 interface description (NAV-PVT, 92-byte payload).
    """
    rec = []
    for p in ubx_frames(Path(path).read_bytes(), 0x01, 0x07):
        if len(p) < 92:
            continue
        itow, = struct.unpack_from("<I", p, 0)
        fix_type, flags, _, num_sv = struct.unpack_from("<BBBB", p, 20)
        lon, lat, h, h_msl, h_acc, v_acc, vn, ve, vd = struct.unpack_from("<iiiiIIiii", p, 24)
        rec.append((itow / 1e3, fix_type, flags & 1, (flags >> 1) & 1, (flags >> 6) & 3, num_sv, lat * 1e-7,
                    lon * 1e-7, h / 1e3, h_msl / 1e3, h_acc / 1e3, v_acc / 1e3, vn / 1e3, ve / 1e3, vd / 1e3))
    a = np.array(rec, dtype=float).reshape(-1, 15)
    keys = ("tow_s", "fix_type", "gnss_fix_ok", "diff_soln", "carr_soln", "num_sv", "lat_deg", "lon_deg", "h_m",
            "h_msl_m", "h_acc_m", "v_acc_m")
    out = {k: a[:, i] for i, k in enumerate(keys)}
    for k in ("fix_type", "gnss_fix_ok", "diff_soln", "carr_soln", "num_sv"):
        out[k] = out[k].astype(int)
    out["v_n_mps"] = a[:, 12:15]
    return out


def nav_pvt_as_reference(pvt: dict, week: int, height: str = "h_m") -> RtklibPos:
    """NAV-PVT as an :class:`RtklibPos` (GPS seconds of ``week``; q 1 fixed, 2 float, 5 otherwise)."""
    lat, lon = pvt["lat_deg"] * DEG, pvt["lon_deg"] * DEG
    q = np.select([pvt["carr_soln"] == 2, pvt["carr_soln"] == 1], [1, 2], 5)
    return RtklibPos(week * SECONDS_PER_WEEK + pvt["tow_s"], earth.geodetic_to_ecef(lat, lon, pvt[height]),
                     earth.ned_to_ecef_vector(lat, lon, pvt["v_n_mps"]), q)


def pos_columns(path) -> dict:
    """The raw columns of an RTKLIB ``.pos`` the reader converts: ``tow_s``, ``lat_deg``, ``lon_deg``, ``height``,
    ``q``, ``sdn``, ``sde``, ``sdu``."""
    rows = []
    for line in Path(path).read_text(encoding="ascii", errors="replace").splitlines():
        if line.startswith("%") or not line.strip():
            continue
        p = line.split()
        hh, mi, ss = p[1].split(":")
        rows.append([int(hh) * 3600 + int(mi) * 60 + float(ss), *map(float, p[2:6]), *map(float, p[7:10])])
    a = np.array(rows)
    ref = read_rtklib_pos(path)
    tow = np.round(ref.t_gps_s % SECONDS_PER_WEEK, 3)
    assert np.allclose(tow % 86400.0, a[:, 0], atol=1e-3)
    return dict(tow_s=tow, lat_deg=a[:, 1], lon_deg=a[:, 2], height=a[:, 3], q=a[:, 4].astype(int),
                sdn=a[:, 5], sde=a[:, 6], sdu=a[:, 7])


def match(tow_a, tow_b, tol=0.02):
    """Index pairs (ia, ib) of equal GPS times of week (|dt| < tol s)."""
    k = np.clip(np.searchsorted(tow_b, tow_a), 1, len(tow_b) - 1)
    k = np.where(np.abs(tow_b[k - 1] - tow_a) < np.abs(tow_b[k] - tow_a), k - 1, k)
    ok = np.abs(tow_b[k] - tow_a) < tol
    return np.flatnonzero(ok), k[ok]


def ned_diff(r_e, r_ref_e):
    """(n, 3) NED of r_e - r_ref_e at the first reference point [m]."""
    lat0, lon0, _ = earth.ecef_to_geodetic(r_ref_e[0])
    return earth.ecef_to_ned_vector(lat0, lon0, np.asarray(r_e) - np.asarray(r_ref_e))


def offset_stats(d_ned) -> dict:
    """Mean N, E, U offset, horizontal norm of the mean and std per axis of an (n, 3) NED difference."""
    d = np.asarray(d_ned, float)
    d = d[np.all(np.isfinite(d), axis=1)]
    m = d.mean(axis=0)
    s = d.std(axis=0)
    return dict(n=len(d), mean_neu=np.array([m[0], m[1], -m[2]]), hz=float(np.hypot(m[0], m[1])),
                std_neu=s, hz_scatter=float(np.sqrt(np.mean(np.sum((d[:, :2] - m[:2]) ** 2, axis=1)))))


def at_reference(t_tow, r_e, ref: RtklibPos, tol=0.02):
    """(NED difference to ``ref``, reference indices) of a solution at GPS times of week ``t_tow``
    (the reference interpolated to them, at most ``tol`` s away from one of its epochs)."""
    tow_ref = ref.t_gps_s % SECONDS_PER_WEEK
    ia, ib = match(np.asarray(t_tow), tow_ref, tol)
    R = np.column_stack([np.interp(np.asarray(t_tow)[ia], tow_ref, ref.r_e[:, i]) for i in range(3)])
    return ned_diff(np.asarray(r_e)[ia], R), ib


def insnav_spp(obs_p, nav_p, systems: str):
    """insnav single point (what ``insnav run --filter spp`` runs): (t [GPS s of week], r_e, used sats per epoch)."""
    from insnav.filters.spp import run_spp_rinex

    sol = run_spp_rinex(obs_p, nav_p, gnss=dict(systems=systems))
    sp = sol.spp
    t = sp.t + sp.info["t_week0_gps_s"] % SECONDS_PER_WEEK
    return t, sp.r_e, sp.n_used


def rtklib_spp(obs_p, nav_p, systems: str):
    """RTKLIB ``rnx2rtkp`` single point (broadcast, Klobuchar, Saastamoinen, 15 deg mask... its defaults except
    the systems and a 10 deg mask), or None without rnx2rtkp.  -> (t [GPS s of week], r_e)."""
    exe = shutil.which("rnx2rtkp")
    if exe is None:
        return None
    code = {"G": 1, "R": 4, "E": 8, "J": 16, "C": 32}
    navsys = sum(code[s] for s in systems)
    with tempfile.TemporaryDirectory() as tmp:
        conf = Path(tmp) / "spp.conf"
        conf.write_text(f"pos1-posmode=single\npos1-navsys={navsys}\npos1-elmask=10\npos1-ionoopt=brdc\n"
                        "pos1-tropopt=saas\npos1-sateph=brdc\npos2-armode=off\nout-solformat=xyz\n"
                        "out-timesys=gpst\nout-timeform=tow\nout-height=ellipsoidal\n")
        out = Path(tmp) / "spp.pos"
        subprocess.run([exe, "-k", str(conf), "-o", str(out), str(obs_p), str(nav_p)], check=True,
                       capture_output=True)
        rows = [line.split() for line in out.read_text().splitlines() if line.strip() and not line.startswith("%")]
    a = np.array([[float(x) for x in r[1:5]] for r in rows])
    return a[:, 0], a[:, 1:4]


def pr_residual_fit(obs_p, nav_p, ref: RtklibPos, systems="GEC"):
    """Per-satellite pseudorange residuals (one clock per system and epoch removed, least squares) at the
    reference position and at the least-squares best fixed position over the whole run.

    Returns dict: ``rms_ref`` / ``rms_best`` RMS of the residuals [m], ``shift_neu`` the best position minus the
    reference (mean over the run) [m], ``rows``.
    """
    from insnav.gnss.spp import read_nav_multi, read_obs_multi, spp_inputs_from_rinex

    obs, nav = read_obs_multi(obs_p, systems), read_nav_multi(nav_p, systems)
    t_week0 = SECONDS_PER_WEEK * int(obs.epoch_week[0])
    inp, _ = spp_inputs_from_rinex(obs, nav, t_week0, ref.r_e[0])
    tow = inp.epoch_t[inp.row_epoch] + t_week0 % SECONDS_PER_WEEK
    tow_ref = ref.t_gps_s % SECONDS_PER_WEEK
    r = np.column_stack([np.interp(tow, tow_ref, ref.r_e[:, i]) for i in range(3)])
    s = inp.sats
    d = s[:, 2:5] - r
    rng = np.linalg.norm(d, axis=1)
    u = d / rng[:, None]
    res = s[:, 0] - (rng - s[:, 8])  # measured - modelled at the reference, clock not yet removed
    # clock per (epoch, system) as nuisance columns; one common position shift dx (ECEF) for the whole run
    key = inp.row_epoch * 8 + np.searchsorted(np.array(list("GREC")), inp.system)
    _, col = np.unique(key, return_inverse=True)
    n_clk = col.max() + 1

    def clocks_removed(y):
        c = np.bincount(col, y, n_clk) / np.bincount(col, minlength=n_clk)
        return y - c[col]

    v_ref = clocks_removed(res)
    # shift: res = -u.dx + clock -> project out the clocks from both sides, then least squares
    A = np.column_stack([clocks_removed(-u[:, i]) for i in range(3)])
    dx, *_ = np.linalg.lstsq(A, v_ref, rcond=None)
    v_best = v_ref - A @ dx
    lat0, lon0, _ = earth.ecef_to_geodetic(ref.r_e[0])
    dn = earth.ecef_to_ned_vector(lat0, lon0, dx)
    return dict(rms_ref=float(np.sqrt(np.mean(v_ref ** 2))), rms_best=float(np.sqrt(np.mean(v_best ** 2))),
                shift_neu=np.array([dn[0], dn[1], -dn[2]]), rows=int(len(res)))


def reference_experiment(data_dir: Path) -> dict:
    """Every comparison of the module docstring.  -> dict (see the keys at the end)."""
    d = data_dir / "rtklibexplorer_walk_0827"
    obs_p, nav_p = d / "rinex_derived/gnss_1730.obs", d / "rinex_derived/gnss_1730.nav"
    pos_p = d / "raw/gnss_1730_sf.pos"
    ref = read_rtklib_pos(pos_p)
    week = int(ref.t_gps_s[0] // SECONDS_PER_WEEK)
    cols = pos_columns(pos_p)
    pvt = read_nav_pvt(d / "raw/gnss_1730.ubx")
    ia, ib = match(cols["tow_s"], pvt["tow_s"])
    # what the .pos columns are, in NAV-PVT terms
    same = dict(
        n_pos=len(cols["tow_s"]), n_pvt=len(pvt["tow_s"]), n_matched=len(ia),
        dlat_max_deg=float(np.max(np.abs(cols["lat_deg"][ia] - pvt["lat_deg"][ib]))),
        dlon_max_deg=float(np.max(np.abs(cols["lon_deg"][ia] - pvt["lon_deg"][ib]))),
        dh_msl_max=float(np.max(np.abs(cols["height"][ia] - pvt["h_msl_m"][ib]))),
        dh_ell_mean=float(np.mean(cols["height"][ia] - pvt["h_m"][ib])),
        undulation=float(np.mean(pvt["h_m"] - pvt["h_msl_m"])),
        q_agrees=float(np.mean(cols["q"][ia] == np.where(pvt["carr_soln"][ib] == 2, 1, 2))),
        sd_hacc=float(np.max(np.abs(cols["sdn"][ia] - pvt["h_acc_m"][ib] / np.sqrt(2)))),
        carr=np.bincount(pvt["carr_soln"], minlength=3), diff=int(pvt["diff_soln"].sum()),
        fix3d=int(np.sum(pvt["fix_type"] == 3)))
    pvt_ell = nav_pvt_as_reference(pvt, week, "h_m")
    pvt_msl = nav_pvt_as_reference(pvt, week, "h_msl_m")
    comp = {}
    e, _ = at_reference(pvt_msl.t_gps_s % SECONDS_PER_WEEK, pvt_msl.r_e, ref)
    comp["NAV-PVT (hMSL) - RTK .pos"] = offset_stats(e)
    e, _ = at_reference(pvt_ell.t_gps_s % SECONDS_PER_WEEK, pvt_ell.r_e, ref)
    comp["NAV-PVT (ellipsoidal h) - RTK .pos"] = offset_stats(e)
    spp = {}
    for systems, name in (("GEC", "GPS + Galileo + BeiDou"), ("G", "GPS"), ("E", "Galileo"), ("C", "BeiDou")):
        t, r, n_used = insnav_spp(obs_p, nav_p, systems)
        ok = np.isfinite(r[:, 0])
        spp[systems] = (t[ok], r[ok])
        n_txt = f"{int(np.median(n_used[ok]))} sats"
        comp[f"insnav SPP {name} ({n_txt}) - RTK .pos"] = offset_stats(at_reference(t[ok], r[ok], ref)[0])
        comp[f"insnav SPP {name} ({n_txt}) - NAV-PVT"] = offset_stats(at_reference(t[ok], r[ok], pvt_ell)[0])
    rtk = rtklib_spp(obs_p, nav_p, "GEC")
    if rtk is not None:
        comp["RTKLIB rnx2rtkp SPP GPS + Galileo + BeiDou - NAV-PVT"] = offset_stats(at_reference(*rtk, pvt_ell)[0])
        comp["RTKLIB SPP - insnav SPP (GEC)"] = offset_stats(
            at_reference(*rtk, RtklibPos(week * SECONDS_PER_WEEK + spp["GEC"][0], spp["GEC"][1],
                                         np.zeros_like(spp["GEC"][1]), np.ones(len(spp["GEC"][0]))))[0])
    resid = pr_residual_fit(obs_p, nav_p, pvt_ell)
    # the reference corrected by the experiment: NAV-PVT ellipsoidal, shifted by the mean GEC single-point offset
    shift_neu = comp[[k for k in comp if k.startswith("insnav SPP GPS + Galileo") and k.endswith("NAV-PVT")][0]][
        "mean_neu"]
    lat0, lon0, _ = earth.ecef_to_geodetic(pvt_ell.r_e[0])
    shift_e = earth.ned_to_ecef_vector(lat0, lon0, np.array([shift_neu[0], shift_neu[1], -shift_neu[2]]))
    shifted = RtklibPos(pvt_ell.t_gps_s, pvt_ell.r_e + shift_e, pvt_ell.v_e, pvt_ell.q)
    return dict(ref=ref, pvt=pvt, pvt_ell=pvt_ell, pvt_shifted=shifted, shift_neu=shift_neu, same=same,
                comp=comp, resid=resid, spp=spp, rtklib=rtk is not None, week=week)


def comparison_table(comp: dict) -> list[str]:
    lines = ["| solution - reference | epochs | mean offset N, E, U [m] | horizontal offset [m] | "
             "std N / E / U [m] | horizontal scatter [m] |", "|---|---|---|---|---|---|"]
    for k, s in comp.items():
        m, sd = s["mean_neu"], s["std_neu"]
        lines.append(f"| {k} | {s['n']} | {m[0]:+.2f}, {m[1]:+.2f}, {m[2]:+.2f} | {s['hz']:.2f} | "
                     f"{sd[0]:.2f} / {sd[1]:.2f} / {sd[2]:.2f} | {s['hz_scatter']:.2f} |")
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path,
                    default=Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared/data")))
    a = ap.parse_args(argv)
    x = reference_experiment(a.data)
    s = x["same"]
    print(f"NAV-PVT records {s['n_pvt']}, .pos epochs {s['n_pos']}, matched by time of week {s['n_matched']}")
    print(f"NAV-PVT carrSoln none/float/fixed {s['carr'].tolist()}, diffSoln set {s['diff']}, 3D fixes {s['fix3d']}")
    print(f".pos - NAV-PVT: max |dlat| {s['dlat_max_deg']:.1e} deg, max |dlon| {s['dlon_max_deg']:.1e} deg, "
          f"max |height - hMSL| {s['dh_msl_max']:.3f} m, mean height - h(ellipsoid) {s['dh_ell_mean']:+.2f} m "
          f"(NAV-PVT h - hMSL {s['undulation']:+.2f} m); Q matches carrSoln in {100 * s['q_agrees']:.0f} %; "
          f"max |sdn - hAcc/sqrt(2)| {s['sd_hacc']:.4f} m")
    print("\n".join(comparison_table(x["comp"])))
    r = x["resid"]
    print(f"PR residuals (clock per epoch and system removed), {r['rows']} rows: RMS {r['rms_ref']:.2f} m at NAV-PVT, "
          f"{r['rms_best']:.2f} m at the best fixed shift N, E, U {r['shift_neu'][0]:+.2f}, {r['shift_neu'][1]:+.2f}, "
          f"{r['shift_neu'][2]:+.2f} m")


if __name__ == "__main__":
    main()
