"""The GPS single-point solver of ``insnav.io.rinex_dataset`` before it moved to
:mod:`insnav.gnss.spp` (kept verbatim as the reference of an equivalence test)."""
import math

import numpy as np

from insnav import earth


def old_single_point(inputs, r0_e, *, min_sats=4, iterations=10):
    E = inputs.epoch_t.size
    r_out = np.full((E, 3), np.nan)
    v_out = np.full((E, 3), np.nan)
    b_out = np.full(E, np.nan)
    d_out = np.full(E, np.nan)
    sp = np.full((E, 3), np.nan)
    sv = np.full((E, 3), np.nan)
    pdop = np.full(E, np.nan)
    n_used = np.zeros(E, np.int64)
    x = np.append(np.asarray(r0_e, float), 0.0)
    for e in range(E):
        s = inputs.sats[inputs.epoch_start[e]:inputs.epoch_start[e + 1]]
        s = s[np.isfinite(s[:, 0])]
        n_used[e] = len(s)
        if len(s) < min_sats:
            continue
        w = 1.0 / s[:, 10]
        ok = False
        for _ in range(iterations):
            d = s[:, 2:5] - x[:3]
            rng = np.linalg.norm(d, axis=1)
            u = d / rng[:, None]
            H = np.column_stack([-u, np.ones(len(s))])
            y = s[:, 0] - (rng - s[:, 8] + x[3])
            dx = np.linalg.lstsq(H * w[:, None], y * w, rcond=None)[0]
            x = x + dx
            if np.linalg.norm(dx[:3]) < 1e-4:
                ok = True
                break
        if not ok or not np.all(np.isfinite(x)):
            x = np.append(np.asarray(r0_e, float), 0.0)
            continue
        d = s[:, 2:5] - x[:3]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        H = np.column_stack([-u, np.ones(len(s))])
        lat, lon, _ = earth.ecef_to_geodetic(x[:3])
        C_ne = earth.C_en(lat, lon).T
        Q = np.linalg.inv((H * (w ** 2)[:, None]).T @ H)
        Hn = np.column_stack([-(u @ C_ne.T), np.ones(len(s))])
        Qn = np.linalg.inv(Hn.T @ Hn)
        r_out[e], b_out[e] = x[:3], x[3]
        sp[e] = np.sqrt(np.diag(C_ne @ Q[:3, :3] @ C_ne.T))
        pdop[e] = math.sqrt(np.trace(Qn[:3, :3]))
        m = np.isfinite(s[:, 1])
        if m.sum() >= min_sats:
            wr = 1.0 / s[m, 11]
            y = s[m, 1] - np.einsum("ij,ij->i", u[m], s[m, 5:8]) + s[m, 9]
            sol = np.linalg.lstsq(H[m] * wr[:, None], y * wr, rcond=None)[0]
            v_out[e], d_out[e] = sol[:3], sol[3]
            Qv = np.linalg.inv((H[m] * (wr ** 2)[:, None]).T @ H[m])
            sv[e] = np.sqrt(np.diag(C_ne @ Qv[:3, :3] @ C_ne.T))
    return dict(r_e=r_out, clock_bias_m=b_out, v_e=v_out, clock_drift_mps=d_out, n_sats=n_used,
                sigma_pos_n_m=sp, sigma_vel_n_mps=sv, pdop=pdop)
