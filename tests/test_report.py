"""``insnav report``: the numbers in the summary table against values known
in advance or computed independently, every figure a real non-blank PNG, and
the page rendered in a real browser (headless Chromium)."""
from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import insnav
from conftest import missing_capability, require_module, short_tight_dataset
from insnav.analysis.evaluate import evaluate
from insnav.analysis.report import chi2_interval, detect_outages, report
from insnav.filters.solution import write_innovations

require_module("matplotlib", "plot")


def _table(html: str) -> dict:
    return {html_unescape(k): html_unescape(v) for k, v in
            re.findall(r"<tr><td>(.*?)</td><td>(.*?)</td></tr>", html)}


def html_unescape(s: str) -> str:
    import html

    return html.unescape(s)


def _images(html: str) -> list[bytes]:
    return [base64.b64decode(b) for b in re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)]


def _nonblank(png: bytes) -> float:
    """Fraction of pixels that are not (near) white."""
    import matplotlib.image as mpimg

    a = mpimg.imread(io.BytesIO(png), format="png")
    rgb = a[..., :3]
    return float(np.mean(rgb.min(axis=-1) < 0.9))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    ds = insnav.simulate("seed000-sim", seed=3)
    ds.save(d / "ds")
    sol = insnav.run(ds, "rbukf", init_seed=3)
    path = sol.save(d / "sol.npz")
    write_innovations(sol, path)
    return d, ds, sol, path


def test_known_offset_gives_known_numbers(tmp_path):
    """A 'solution' equal to the truth moved 2 m north, with 1 m sigmas:
    RMS N = max N = 2 m, E = D = 0, rms(error/sigma) N = 2."""
    ds = insnav.simulate("seed000-sim", seed=1)
    tr = ds.truth
    from insnav.earth import radii
    from insnav.filters.solution import Solution

    n = len(tr.t)
    R_M, _ = radii(np.deg2rad(tr.lat_deg))
    one = np.ones((n, 3))
    sol = Solution(t=tr.t, lat_deg=tr.lat_deg + np.rad2deg(2.0 / (R_M + tr.h_m)), lon_deg=tr.lon_deg, h_m=tr.h_m,
                   v_n=tr.v_n, roll_deg=tr.roll_deg, pitch_deg=tr.pitch_deg, yaw_deg=tr.yaw_deg,
                   sigma_pos_n_m=one, sigma_vel_n_mps=one, sigma_att_deg=one, acc_bias_mps2=0 * one,
                   gyro_bias_rps=0 * one, acc_scale=0 * one, gyro_scale=0 * one, gnss_t=np.zeros(0),
                   innovation=np.zeros((0, 6)), nis=np.zeros(0), gnss_status=np.zeros(0, np.int8))
    path = sol.save(tmp_path / "offset.npz")
    page = report(path, truth=tr, outages=[]).read_text()
    t = _table(page)
    assert t["position RMS [m] N/E/D"] == "2.000 / 0.000 / 0.000"
    assert t["position max [m] N/E/D"] == "2.000 / 0.000 / 0.000"
    assert t["horizontal RMS / max [m]"] == "2.000 / 2.000"
    assert t["consistency rms(error / sigma), position N/E/D"].startswith("2.00 / 0.00 / 0.00")
    assert t["velocity RMS [m/s] N/E/D"] == "0.000 / 0.000 / 0.000"


def _shifted_truth(tr, north_m, dve_mps=0.0, dyaw_deg=0.0, sigmas=(1.0, 0.05, 0.25)):
    """A 'solution' equal to the truth moved north by north_m(t) [m], with an
    east velocity offset [m/s], a yaw offset [deg] and constant sigmas."""
    from insnav.earth import radii
    from insnav.filters.solution import Solution

    n = len(tr.t)
    R_M, _ = radii(np.deg2rad(tr.lat_deg))
    one = np.ones((n, 3))
    v_n = np.array(tr.v_n, float)
    v_n[:, 1] += dve_mps
    return Solution(t=tr.t, lat_deg=tr.lat_deg + np.rad2deg(north_m / (R_M + tr.h_m)), lon_deg=tr.lon_deg,
                    h_m=tr.h_m, v_n=v_n, roll_deg=tr.roll_deg, pitch_deg=tr.pitch_deg,
                    yaw_deg=(tr.yaw_deg + dyaw_deg + 180.0) % 360.0 - 180.0,
                    sigma_pos_n_m=sigmas[0] * one, sigma_vel_n_mps=sigmas[1] * one, sigma_att_deg=sigmas[2] * one,
                    acc_bias_mps2=0 * one, gyro_bias_rps=0 * one, acc_scale=0 * one, gyro_scale=0 * one,
                    gnss_t=np.zeros(0), innovation=np.zeros((0, 6)), nis=np.zeros(0),
                    gnss_status=np.zeros(0, np.int8))


def _floats(cell: str) -> list[float]:
    return [float(x) for x in cell.split(" (")[0].split(" / ")]


def test_outage_maxima_reconvergence_and_consistency_of_a_known_error_profile(tmp_path):
    """North error 1 m before a 50-90 s 'outage', growing linearly to 11 m at
    90 s, then decaying as 11 exp(-(t - 90) / 4 s); east velocity +0.1 m/s
    (sigma 0.05), yaw +0.5 deg (sigma 0.25).  Known in advance: max inside
    11 m, reconvergence (back within 1.5 x the 1 m pre-outage RMS) at
    4 ln(11 / 1.5) = 7.97 s, rms(error / sigma) 2 in velocity E and yaw."""
    tr = insnav.simulate("seed000-sim", seed=1).truth
    t = tr.t
    e_n = np.where(t < 50, 1.0, np.where(t <= 90, 1.0 + 10.0 * (t - 50) / 40, 11.0 * np.exp(-(t - 90) / 4.0)))
    sol = _shifted_truth(tr, e_n, dve_mps=0.1, dyaw_deg=0.5)
    page = report(sol, tmp_path / "r", truth=tr, outages=[(50.0, 90.0)]).read_text()
    tab = _table(page)
    key = "outage 50.0-90.0 s: max horizontal inside / in the 60 s after [m]"
    inside, after = _floats(tab[key])
    assert inside == pytest.approx(11.0, abs=2e-3)
    dt = float(np.median(np.diff(t)))
    assert after == pytest.approx(11.0 * np.exp(-dt / 4.0), abs=2e-3)  # the first sample after 90 s
    reconv = _floats(tab["outage 50.0-90.0 s: reconvergence [s]"])[0]
    assert reconv == pytest.approx(4.0 * np.log(11.0 / 1.5), abs=0.051)
    assert _floats(tab["position RMS [m] N/E/D"]) == pytest.approx([np.sqrt(np.mean(e_n ** 2)), 0, 0], abs=6e-4)
    assert _floats(tab["position max [m] N/E/D"]) == pytest.approx([11.0, 0, 0], abs=6e-4)
    assert _floats(tab["velocity RMS [m/s] N/E/D"]) == pytest.approx([0, 0.1, 0], abs=6e-4)
    assert _floats(tab["attitude RMS [deg] roll/pitch/yaw"]) == pytest.approx([0, 0, 0.5], abs=6e-4)
    assert _floats(tab["consistency rms(error / sigma), velocity N/E/D"]) == pytest.approx([0, 2, 0], abs=6e-3)
    assert _floats(tab["consistency rms(error / sigma), attitude roll/pitch/yaw"]) == pytest.approx([0, 0, 2],
                                                                                                 abs=6e-3)
    assert _floats(tab["horizontal RMS / max [m]"])[1] == pytest.approx(11.0, abs=6e-4)


def test_against_exact_fixes_the_offset_comes_back(tmp_path):
    """Fixes equal to the truth at 1 Hz (no noise, sigma 0.5 m / 0.1 m/s), the
    solution the truth moved 3 m north and 0.2 m/s east: position minus fixes
    RMS 3 / 0 / 0 m, velocity 0 / 0.2 / 0, and rms(difference / sigma) from the
    root-sum-square of both sigmas (1 m and 0.5 m: 3 / sqrt(1.25))."""
    from insnav.data.dataset import GnssFixes

    tr = insnav.simulate("seed000-sim", seed=1).truth
    sol = _shifted_truth(tr, np.full(len(tr.t), 3.0), dve_mps=0.2, sigmas=(1.0, 0.2, 0.25))
    i = np.flatnonzero(np.isclose(tr.t % 1.0, 0.0, atol=1e-6) | np.isclose(tr.t % 1.0, 1.0, atol=1e-6))
    m = len(i)
    fixes = GnssFixes(t_valid=tr.t[i], t_arrival=tr.t[i], lat_deg=tr.lat_deg[i], lon_deg=tr.lon_deg[i],
                      h_m=tr.h_m[i], v_n=np.asarray(tr.v_n)[i], sigma_pos_n=np.full((m, 3), 0.5),
                      sigma_vel_n=np.full((m, 3), 0.1))
    html_path = report(sol, tmp_path / "f", gnss=fixes, outages=[])
    tab = _table(html_path.read_text())
    assert _floats(tab["position minus GNSS fixes, RMS [m] N/E/D"]) == pytest.approx([3.0, 0, 0], abs=6e-4)
    assert _floats(tab["position minus GNSS fixes, rms(difference / sigma) N/E/D"])[0] == pytest.approx(
        3.0 / np.sqrt(1.25), abs=6e-3)
    assert _floats(tab["velocity minus GNSS fixes, RMS [m/s] N/E/D"]) == pytest.approx([0, 0.2, 0], abs=6e-4)
    assert _floats(tab["velocity minus GNSS fixes, rms(difference / sigma) N/E/D"])[1] == pytest.approx(
        0.2 / np.sqrt(0.05), abs=6e-3)
    # no IMU-error state estimated (all zero): no empty imu_errors.png
    assert {p.name for p in html_path.parent.glob("*.png")} == {"track.png", "pos_error.png", "vel_error.png"}
    # 3 / sqrt(1.25) = 2.68 north: the verdict word uses evaluate's bounds, not "about 1: consistent"
    assert "overconfident (sigmas too small): north 2.68 > 2" in tab["position minus GNSS fixes, rms(difference / "
                                                                  "sigma) N/E/D"]


def test_tight_report_shows_the_per_satellite_residuals(tmp_path):
    ds = short_tight_dataset()
    sol = insnav.run(ds, filter="ekf", coupling="tight", init_seed=0, output_decimation=10)
    path = sol.save(tmp_path / "tight.npz")
    write_innovations(sol, path)
    html_path = report(path, truth=ds.truth)
    page = html_path.read_text()
    tab = _table(page)
    applied = np.repeat(sol.gnss_status == 1, np.diff(sol.inputs.epoch_start))
    pr = sol.innovation[applied, 0]
    rr = sol.innovation[applied, 1]
    want = [np.sqrt(np.nanmean(pr ** 2)), np.sqrt(np.nanmean(rr ** 2))]
    got = _floats(tab["residual RMS of applied epochs: pseudorange [m] / rate [m/s]"])
    assert got == pytest.approx(want, abs=6e-4)
    names = {p.name for p in html_path.parent.glob("*.png")}
    assert "residuals.png" in names and "innovations.png" in names
    for png in _images(page):
        assert _nonblank(png) > 0.01
    # the same from the Solution object (no files): the same residual figure and numbers
    tab2 = _table(report(sol, tmp_path / "obj", truth=ds.truth).read_text())
    assert tab2["residual RMS of applied epochs: pseudorange [m] / rate [m/s]"] == \
        tab["residual RMS of applied epochs: pseudorange [m] / rate [m/s]"]
    # a loose report written into the same folder afterwards leaves no stale residual figure behind
    loose = insnav.run(ds, filter="ekf", init_seed=0, output_decimation=10)
    report(loose, html_path.parent, truth=ds.truth)
    assert not (html_path.parent / "residuals.png").exists()


def test_summary_matches_evaluate_and_figures_are_real(run):
    d, ds, sol, path = run
    html_path = report(path, truth=d / "ds", gnss=d / "ds")
    assert html_path == path.with_name("sol.npz-report") / "report.html"
    page = html_path.read_text()
    assert "http://" not in page and "https://" not in page and "<script" not in page  # self-contained
    t = _table(page)
    ev = evaluate(sol, ds.truth, [(50.0, 90.0)])
    assert t["horizontal RMS / max [m]"] == f"{ev['horizontal_rms_m']:.3f} / {ev['horizontal_max_m']:.3f}"
    assert t["GNSS outages [s]"] == "50.0-90.0"  # seed000-sim: GPS lost 50-90 s, found from the record gaps
    o = ev["outages"][0]
    key = "outage 50.0-90.0 s: max horizontal inside / in the 60 s after [m]"
    assert t[key] == f"{o['max_horizontal_inside_m']:.3f} / {o['max_horizontal_after_60s_m']:.3f}"
    applied = sol.gnss_status == 1
    assert t["GNSS records"].startswith(f"{len(sol.gnss_t)}: {applied.sum()} applied")
    nis_mean = float(t["NIS of applied updates: mean / mean rows"].split(" / ")[0])
    assert nis_mean == pytest.approx(np.nanmean(sol.nis[applied]), abs=0.006)
    imgs = _images(page)
    files = sorted(p.name for p in html_path.parent.glob("*.png"))
    assert len(imgs) == len(files) == 6, files
    for png in imgs:
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        assert _nonblank(png) > 0.01
    for f in files:  # the PNGs beside the page are the ones inside it
        assert (html_path.parent / f).read_bytes() in imgs


def test_without_truth_the_gnss_fixes_are_the_reference(run, tmp_path):
    d, ds, sol, path = run
    page = report(path, tmp_path / "r", gnss=d / "ds" / "gnss.csv").read_text()
    t = _table(page)
    assert t["errors against"].startswith("GNSS fixes")
    rms = [float(x) for x in t["position minus GNSS fixes, RMS [m] N/E/D"].split(" / ")]
    # the fixes' own noise (seed000-sim: 5 m horizontal, 10 m vertical sigma) dominates
    assert 1.0 < rms[0] < 10.0 and 1.0 < rms[1] < 10.0


def test_chi2_interval_and_outage_detection():
    lo, hi = chi2_interval([6, 30])
    # exact 2.5 / 97.5 % quantiles: dof 6: 1.237, 14.449; dof 30: 16.791, 46.979
    np.testing.assert_allclose(lo, [1.237, 16.791], rtol=0.03)
    np.testing.assert_allclose(hi, [14.449, 46.979], rtol=0.01)
    t = np.r_[np.arange(0, 50), np.arange(90, 150)]
    assert detect_outages(t) == [(49.0, 90.0)]


def test_cli_report_and_its_errors(run, tmp_path):
    from insnav.cli import main

    d, ds, sol, path = run
    assert main(["report", str(path), "--truth", str(d / "ds"), "--out", str(tmp_path / "cli")]) == 0
    assert (tmp_path / "cli" / "report.html").is_file()
    r = subprocess.run([sys.executable, "-m", "insnav", "report", str(tmp_path / "nope.csv")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "nope.csv" in r.stderr
    assert "Traceback" not in r.stderr


def test_missing_matplotlib_is_one_clear_error(run, tmp_path, monkeypatch, capsys):
    d, ds, sol, path = run
    for m in [k for k in sys.modules if k == "matplotlib" or k.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, m)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(ImportError, match=r"insnav\[plot\]"):
        report(path, tmp_path / "x")
    from insnav.cli import main

    assert main(["report", str(path), "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("insnav report: error:") and "insnav[plot]" in err[0], err


def _chromium():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        p = shutil.which(name)
        if p:
            return p
    missing_capability("browser", "Chromium is not installed (the report's browser check)")


_WIDTH = 1100  # CSS px of the browser window (the page is at most 1000 px wide)


def _browser_layout(browser: str, page) -> dict:
    """Load ``page`` in headless Chromium inside an iframe as wide as the
    screenshot window (no scrollbars, so the layout is the same) and read back
    the document height and, per image, whether it decoded, its natural size
    and its box in page pixels."""
    page = Path(page)
    probe = page.with_name("layout-probe.html")
    probe.write_text(
        "<html><body style='margin:0'><iframe id='f' src='" + page.name + "' width='" + str(_WIDTH) + "' "
        "height='20000' scrolling='no' style='border:0;display:block'></iframe><script>"
        "window.addEventListener('load', () => { const d = document.getElementById('f').contentDocument;"
        " const boxes = [...d.images].map(i => { const r = i.getBoundingClientRect();"
        " return [i.complete, i.naturalWidth, i.naturalHeight, r.left, r.top, r.width, r.height]; });"
        " document.body.setAttribute('data-layout', JSON.stringify({height: Math.ceil(d.body.getBoundingClientRect()"
        ".bottom) + 20,"
        " images: boxes})); });</script></body></html>")
    r = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
                        "--virtual-time-budget=10000", "--dump-dom", probe.as_uri()],
                       capture_output=True, text=True, timeout=120)
    probe.unlink()
    m = re.search(r'data-layout="([^"]*)"', r.stdout)
    assert m, r.stdout[-500:] + r.stderr[-1500:]
    return json.loads(html_unescape(m.group(1)))


def _screenshot(browser: str, page, shot, height: int) -> list[str]:
    """Screenshot of ``page`` (full height); returns the console messages
    Chromium logged (console.log/error, uncaught exceptions)."""
    r = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                        "--virtual-time-budget=10000", "--enable-logging=stderr", "--v=0",
                        f"--window-size={_WIDTH},{height}", f"--screenshot={shot}", Path(page).as_uri()],
                       capture_output=True, text=True, timeout=120)
    assert Path(shot).is_file(), r.stderr[-1500:]
    return [ln for ln in r.stderr.splitlines() if ":CONSOLE" in ln or "Uncaught" in ln]


def _blank_figures(shot, boxes) -> list[int]:
    """Indices of the image boxes whose screenshot pixels are (nearly) all white."""
    import matplotlib.image as mpimg

    a = mpimg.imread(shot)[..., :3]
    bad = []
    for k, (_, _, _, x, y, w, h) in enumerate(boxes):
        region = a[int(y) + 2:int(y + h) - 2, int(x) + 2:int(x + w) - 2]  # inside the 1 px border
        if region.size == 0 or np.mean(region.min(axis=-1) < 0.9) < 0.01:
            bad.append(k)
    return bad


def test_page_renders_in_a_real_browser(run):
    """Headless Chromium loads the page: no console message, every figure
    decoded by the browser at its full size, and in a screenshot of the whole
    page every figure's box has content.  The checks are shown to fail on a
    copy of the page with a script error and one with a blank figure."""
    browser = _chromium()
    d, ds, sol, path = run
    html_path = report(path, truth=d / "ds", gnss=d / "ds")
    out = html_path.parent
    n_fig = len(_images(html_path.read_text()))
    lay = _browser_layout(browser, html_path)
    boxes = lay["images"]
    assert len(boxes) == n_fig == 6
    for complete, nw, nh, x, y, w, h in boxes:
        assert complete and nw > 300 and nh > 200, boxes  # decoded
        assert x >= 0 and x + w <= _WIDTH and w > 300 and h > 200, boxes  # laid out inside the window
    tops = [b[4] for b in boxes]
    assert tops == sorted(tops) and lay["height"] > tops[-1]
    shot = out / "screenshot.png"
    console = _screenshot(browser, html_path, shot, int(lay["height"]))
    assert not console, console
    assert not _blank_figures(shot, boxes)
    import matplotlib.image as mpimg

    a = mpimg.imread(shot)[..., :3]
    assert a.shape[1] == _WIDTH and a.shape[0] >= int(lay["height"]) - 1
    table = a[: int(tops[0])]  # the title and summary table above the first figure
    assert np.mean(table.min(axis=-1) < 0.5) > 0.005

    # the checks can fail: a script error is seen, a blank figure is found
    page = html_path.read_text()
    broken = out / "broken.html"
    broken.write_text(page.replace("</body>", "<script>console.error('x'); no_such_function();</script></body>"))
    msgs = _screenshot(browser, broken, out / "broken.png", int(lay["height"]))
    assert any("no_such_function" in m for m in msgs), msgs
    import matplotlib.pyplot as plt

    nw, nh = boxes[2][1], boxes[2][2]
    white = io.BytesIO()
    plt.imsave(white, np.ones((nh, nw, 3)), format="png")
    b64 = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    blank = out / "blank.html"
    blank.write_text(page.replace(b64[2], base64.b64encode(white.getvalue()).decode("ascii")))
    _screenshot(browser, blank, out / "blank.png", int(lay["height"]))
    assert _blank_figures(out / "blank.png", boxes) == [2]


def test_consistency_verdict_uses_the_bounds_evaluate_warns_outside():
    from insnav.analysis.evaluate import CONSISTENCY_BOUNDS, consistency_flags
    from insnav.analysis.report import consistency_verdict

    assert CONSISTENCY_BOUNDS == (0.5, 2.0)
    assert consistency_verdict([0.51, 1.46, 1.0]).startswith("consistent")
    v = consistency_verdict([2.31, 1.0, 0.3])
    assert v == "overconfident (sigmas too small): north 2.31 > 2; pessimistic (sigmas too large): down 0.30 < 0.5"
    assert [i for i, *_ in consistency_flags({"q": [2.31, 1.0, 0.3]})["q"]] == [0, 2]
    assert consistency_verdict([0.4, 1.0, 1.0], ("roll", "pitch", "yaw")).endswith("roll 0.40 < 0.5")


def test_steady_limit_and_nis_limits():
    from insnav.analysis.report import nis_limits, steady_limit

    t = np.arange(0.0, 200.0, 0.1)
    sig = np.where(t < 5.0, 100.0, 1.0)  # the start-up sigma
    err = np.where(t < 5.0, 50.0, 0.5 * np.sin(t))
    assert steady_limit(t, err, sig) == pytest.approx(1.1 * 3.0)
    assert steady_limit(t, 0.5 * np.sin(t), np.ones_like(t)) is None  # no transient: the automatic limits
    nis = np.r_[1e-12, np.full(200, 3.0), 30.0]
    lo, hi = nis_limits(nis, np.full(nis.size, 3))
    assert 0.05 < lo < 0.9 and hi >= 90.0


def test_report_axes_time_since_start_no_empty_panels_robust_nis(tmp_path, monkeypatch):
    """A 15-state solution in GPS seconds of week (t from 456300 s), an alignment-epoch NIS of 1e-12 and
    100x larger sigmas for the first 5 s: every time axis starts at 0, no panel for the scale factors that
    were not estimated, the NIS axis ignores the 1e-12, the error axes the start-up sigmas."""
    import insnav.analysis.report as rep

    tr = insnav.simulate("seed000-sim", seed=1).truth
    sol = _shifted_truth(tr, np.full(len(tr.t), 0.5))
    sol.sigma_pos_n_m[tr.t < tr.t[0] + 5.0] *= 100.0
    sol.acc_bias_mps2[:] = 1e-3  # biases estimated, scale factors not (15 states)
    sol.gyro_bias_rps[:] = 1e-5
    off = 456300.0
    sol.t = sol.t + off
    tr.t = tr.t + off
    k = np.arange(0, len(tr.t), 200)
    sol.gnss_t = sol.t[k]
    sol.gnss_status = np.ones(k.size, np.int8)
    sol.nis = np.full(k.size, 4.0)
    sol.nis[0] = 1e-12
    sol.innovation = np.zeros((k.size, 6))
    figs = []

    def keep(fig):
        figs.append(fig)
        return b"png"

    monkeypatch.setattr(rep, "_png", keep)
    import matplotlib.pyplot as plt

    monkeypatch.setattr(plt, "close", lambda fig: None)  # the figures stay readable
    rep.report(sol, tmp_path / "r", truth=tr, outages=[])
    axes = [ax for f in figs for ax in f.axes if ax.get_visible()]
    timed = [ax for ax in axes if ax.get_xlabel().startswith("time since start")]
    assert timed and all(f"start at t = {sol.t[0]:.3f}" in ax.get_xlabel() for ax in timed)
    for ax in timed:
        for line in ax.get_lines():
            x = np.asarray(line.get_xdata(), float)
            if x.size:
                assert x.min() >= -1e-6 and x.max() < tr.t[-1] - tr.t[0] + 1e-6
    titles = [ax.get_title() for ax in axes]
    assert not any("scale factor" in t for t in titles) and any("gyro bias" in t for t in titles)
    nis_ax = [ax for ax in axes if ax.get_ylabel() == "NIS"][0]
    assert nis_ax.get_ylim()[0] > 0.1
    north = [ax for ax in axes if ax.get_ylabel() == "north" and "position error" in (ax.figure.axes[0].get_title())][0]
    assert north.get_ylim()[1] == pytest.approx(1.1 * 3.0)  # 3 sigma after the start-up, not 300 m


# --------------------------------------------------------------------------- the Allan section

_N_G, _N_A = 3e-4, 2e-3  # simulated ARW [rad/sqrt(s)] and VRW [m/s/sqrt(s)]


@pytest.fixture(scope="module")
def allan_dir(tmp_path_factory):
    """`insnav allan` of a 10 min static KF-GINS log (100 Hz) with known white noise:
    (its --out-dir, the fits computed directly from the log)."""
    import math

    import insnav.calib.allan as al
    from insnav.cli import main

    d = tmp_path_factory.mktemp("allan")
    rng = np.random.default_rng(7)
    n, tau0 = 60000, 0.01
    t = 100000.0 + tau0 * np.arange(1, n + 1)
    g = np.array([0.0, 0.0, 7.29e-5]) + _N_G / math.sqrt(tau0) * rng.standard_normal((n, 3))
    f = np.array([0.0, 0.0, -9.80665]) + _N_A / math.sqrt(tau0) * rng.standard_normal((n, 3))
    np.savetxt(d / "static.txt", np.column_stack([t, g * tau0, f * tau0]), fmt="%.9f" + " %.15e" * 6)
    assert main(["allan", str(d / "static.txt"), "--out-dir", str(d / "imu-allan"), "--no-plot"]) == 0
    curve = al.allan_deviation([g, f], tau0)
    return d / "imu-allan", [al.fit_allan(curve, a) for a in range(6)], curve


def _allan_rows(page: str) -> dict:
    """axis -> the cells of the report's Allan table (HTML unescaped)."""
    tab = re.search(r'<table id="allan">(.*?)</table>', page, re.S).group(1)
    out = {}
    for row in re.findall(r"<tr><td>(.*?)</td></tr>", tab):
        cells = [html_unescape(c) for c in row.split("</td><td>")]
        out[cells[0]] = cells[1:]
    return out


def test_allan_section_has_the_fit_of_the_log(run, allan_dir):
    """The report's Allan section, rebuilt from allan.csv, carries the fit of the
    original log (to the 4 digits of the table): N of every axis as the direct fit
    and within 3 % of the simulated white noise, inside its interval, and a TOML
    whose [imu] keys load to the same values; the figure is a real PNG."""
    from insnav.calib.allan import TERMS
    from insnav.config import load_config
    from insnav.cli.allan import read_curve_csv
    from insnav.units import DEG_PER_SQRT_H, MPS_PER_SQRT_H

    out_dir, fits, curve = allan_dir
    c2, source = read_curve_csv(out_dir)
    assert c2.n == curve.n and c2.tau0_s == pytest.approx(curve.tau0_s, rel=1e-8)
    assert np.array_equal(c2.m, curve.m) and np.allclose(c2.adev, curve.adev, rtol=1e-5, atol=0)
    assert source.endswith("static.txt")
    d, ds, sol, path = run
    html_path = report(path, out_dir.parent / "with-allan", truth=d / "ds", allan=out_dir)
    page = html_path.read_text()
    rows = _allan_rows(page)
    assert list(rows) == ["gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"]
    j = list(TERMS).index("N")
    for a, axis in enumerate(rows):
        unit, truth = (DEG_PER_SQRT_H, _N_G) if a < 3 else (MPS_PER_SQRT_H, _N_A)
        m = re.fullmatch(r"([0-9.e+-]+) \(([0-9.e+-]+)\.\.([0-9.e+-]+)\)", rows[axis][j])
        assert m, rows[axis]
        v, lo, hi = (float(x) * unit for x in m.groups())
        assert v == pytest.approx(fits[a].coef["N"], rel=1e-3)  # the table's 4 digits
        assert v == pytest.approx(truth, rel=0.03) and lo < v < hi and hi / lo < 1.05
    toml = html_unescape(re.search(r'<pre id="imu_noise_toml">(.*?)</pre>', page, re.S).group(1))
    (out_dir.parent / "from_report.toml").write_text(toml)
    a, b = load_config(out_dir.parent / "from_report.toml").imu, load_config(out_dir / "imu_noise.toml").imu
    assert np.allclose(a.gyro_arw, b.gyro_arw, rtol=1e-3) and np.allclose(a.acc_vrw, b.acc_vrw, rtol=1e-3)
    assert np.allclose(a.gyro_arw, _N_G, rtol=0.03) and np.allclose(a.acc_vrw, _N_A, rtol=0.03)
    imgs = _images(page)
    assert len(imgs) == 7 and (html_path.parent / "allan.png").read_bytes() == imgs[-1]
    assert _nonblank(imgs[-1]) > 0.02
    # the solution's summary is still there, above the Allan section
    assert "horizontal RMS / max [m]" in _table(page.split('id="allan-noise"')[0])


def test_allan_only_report_and_its_errors(allan_dir, tmp_path):
    """`insnav report --allan DIR` without a solution: a page of the Allan
    section only; a file that is not an `insnav allan` curve and a missing
    SOL without --allan are one-line errors naming the problem."""
    out_dir, fits, curve = allan_dir
    r = subprocess.run([sys.executable, "-m", "insnav", "report", "--allan", str(out_dir), "--out",
                        str(tmp_path / "noise")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    page = (tmp_path / "noise" / "report.html").read_text()
    assert len(_allan_rows(page)) == 6 and len(_images(page)) == 1 and 'id="summary"' not in page
    assert sorted(p.name for p in (tmp_path / "noise").iterdir()) == ["allan.png", "report.html"]
    bad = tmp_path / "allan.csv"
    bad.write_text("tau,adev\n1,2\n")
    for argv, words in ((["--allan", str(bad)], ["not an Allan curve", str(bad)]),
                        ([], ["SOL", "--allan"]),
                        (["--allan", str(out_dir), "--truth", str(out_dir)], ["need SOL"])):
        r = subprocess.run([sys.executable, "-m", "insnav", "report", *argv, "--out", str(tmp_path / "x")],
                           capture_output=True, text=True)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert all(w in r.stderr for w in words) and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "x").exists()


def test_allan_page_renders_in_a_real_browser(allan_dir, tmp_path):
    """Headless Chromium: the Allan-only page's figure decodes at its full size
    and has content in the screenshot, the terms table below it is drawn (dark
    pixels), and no console message."""
    browser = _chromium()
    out_dir, fits, curve = allan_dir
    html_path = report(None, tmp_path / "noise", allan=out_dir)
    lay = _browser_layout(browser, html_path)
    (box,) = lay["images"]
    complete, nw, nh, x, y, w, h = box
    assert complete and nw > 600 and nh > 300 and 0 <= x and x + w <= _WIDTH and w > 600, box
    shot = tmp_path / "shot.png"
    console = _screenshot(browser, html_path, shot, int(lay["height"]))
    assert not console, console
    assert not _blank_figures(shot, [box])
    import matplotlib.image as mpimg

    a = mpimg.imread(shot)[..., :3]
    below = a[int(y + h) + 5:]  # the terms table and the TOML
    assert below.shape[0] > 100 and np.mean(below.min(axis=-1) < 0.5) > 0.005


def test_residuals_by_system_and_prn_robust_rows_out_of_the_rms_and_every_pos_status(monkeypatch):
    """The per-satellite residual figure keys a satellite by system and PRN (G10 and E10 are two
    series, labelled with their letters); rows the robust step rejected (flag 2) stay out of the
    summary's residual RMS; every RTKLIB Q of a .pos is counted; mm values keep 3 digits."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.axes import Axes

    from insnav.analysis import report as rep

    labels = []
    real_plot = Axes.plot
    monkeypatch.setattr(Axes, "plot", lambda self, *a, **k: (labels.append(k.get("label")), real_plot(self, *a, **k))[1])
    t = np.repeat(np.arange(5.0), 3)
    res = dict(t_s=t, prn=np.tile([10, 10, 20], 5), system=np.tile([0, 2, 2], 5),
               pseudorange_residual_m=np.tile([1.0, -1.0, 100.0], 5), rate_residual_mps=np.tile([0.1, -0.1, 0.1], 5),
               pseudorange_flag=np.tile([0, 0, 2], 5), rate_flag=np.zeros(15, int))
    inn = dict(t_s=np.arange(5.0), status=np.ones(5, int), nis=np.full(5, 2.0), rows=np.full(5, 4),
               innovation=np.full((5, 6), np.nan))
    sol = insnav.run(short_tight_dataset(), filter="ekf", coupling="tight", init_seed=0, output_decimation=50)
    rep._figures(sol, None, None, None, None, inn, res, [], plt)
    assert {"G10", "E10", "E20"} <= set(labels) and "row rejected (robust)" in labels
    rows = dict(rep._summary_rows(sol, None, None, inn, res, [], None))
    assert rows["residual RMS of applied epochs: pseudorange [m] / rate [m/s]"].startswith("1.000 / 0.100 (10 / 15")
    pos = type("Pos", (), {})()  # an RTKLIB .pos read as a solution: 3 fixed, 2 single epochs
    pos.t, pos.fix_status = np.arange(5.0), np.r_[np.ones(3, int), np.full(2, 5)]
    rows = dict(rep._summary_rows(pos, None, None, None, None, [], None))
    assert rows["carrier-phase fix rate"] == "60.0 % (3 fixed, 2 single)"
    assert (rep._fmt(0.00053), rep._fmt(2.0), rep._fmt(0.0), rep._fmt(10.986)) == ("0.000530", "2.000", "0.000", "10.986")


def test_a_gnss_only_solution_against_fixes_is_called_an_antenna(tmp_path):
    """An RTKLIB .pos (no attitude: GNSS only) reported against GNSS fixes: "errors against" says the
    solution is an antenna position, not the IMU centre; the position difference to itself is zero."""
    pos = tmp_path / "a.pos"
    hdr = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  "
           "sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n")
    pos.write_text(hdr + "".join(f"2024/06/24 08:20:{s:06.3f}   35.134699000  136.977575000   104.8600   1  12   "
                                 "0.0024   0.0024   0.0069   0.0008  -0.0013  -0.0024   0.00   12.0\n" for s in range(20)))
    page = report(pos, tmp_path / "r", gnss=pos).read_text()
    tab = _table(page)
    assert "antenna position too" in tab["errors against"]
    assert max(_floats(tab["position minus GNSS fixes, RMS [m] N/E/D"])) < 1e-6
