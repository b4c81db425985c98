"""The odometer scale-factor state (``[constraints] odo_scale``; the 16-state
``Layout16Odo``, ``cpp/include/insnav/meas/vehicle.hpp``): convergence to a
known simulated scale error, consistency of its sigma, no loss when the true
error is zero, the RB-UKF and the smoother on the 16 states, and bad
configuration as one-line errors.  The Jacobian of the odometer row with the
scale column is checked against central differences in
``cpp/tests/test_vehicle_constraints.cpp``."""
from __future__ import annotations

import numpy as np
import pytest

import insnav
from insnav.analysis import errors
from insnav.config import ConfigError, Constraints, RunConfig, config_from_dict

PPM = 1e-6


def _car(scale_ppm: float, seed: int, outage=None):
    """car-mems with a known odometer scale error (no random part) and optionally one GNSS outage."""
    sc = {"extends": "car-mems", "name": f"car-odo{scale_ppm:+.0f}ppm",
          "odometer": {"scale_error_ppm": float(scale_ppm), "scale_error_sigma_ppm": 0.0}}
    if outage is not None:
        sc["gnss"] = {"outages": [list(outage)]}
    return insnav.simulate(sc, seed=seed)


def _run(ds, odo_scale, filt="ekf", smooth=False, **kw):
    return insnav.run(ds, config=RunConfig(filter=filt, init_seed=1, smooth=smooth, output_decimation=20,
                                           constraints=Constraints(use=["nhc", "odo"], odo_scale=odo_scale, **kw)))


@pytest.fixture(scope="module")
def car3000():
    return _car(3000.0, seed=4)


def test_scale_converges_to_the_truth(car3000):
    """+3000 ppm, GNSS on: after the first 300 s the estimate stays within 300
    ppm and 3 sigma of the truth, and rms(error / sigma) is at most 1.5
    (not over-confident) and not absurdly pessimistic."""
    sol = _run(car3000, True)
    assert sol.summary["layout"] == 16 and sol.odo_scale is not None
    t, s, sg = sol.t, sol.odo_scale, sol.sigma_odo_scale
    late = t > t[0] + 300.0
    err = s[late] - 3000.0 * PPM
    z = err / sg[late]
    print(f"final {s[-1] / PPM:.0f} ppm sigma {sg[-1] / PPM:.0f} ppm; max |err| {np.abs(err).max() / PPM:.0f} ppm, "
          f"rms(err/sigma) {np.sqrt(np.mean(z ** 2)):.2f}")
    assert np.abs(err).max() < 300.0 * PPM
    assert np.abs(z).max() < 3.0
    assert 0.1 < np.sqrt(np.mean(z ** 2)) < 1.5
    assert sg[-1] < sg[0] / 5  # the sigma shrank from its initial 10000 ppm
    c = sol.summary["constraints"]
    assert abs(c["odo_scale_ppm"] - 3000.0) < 300.0 and c["rejected"] == 0


def test_rbukf_and_smoother_run_the_16_states(car3000):
    """The RB-UKF (nonlinear model with the scale state) converges like the
    EKF; the RTS smoother runs on the 16 states and keeps the filtered scale."""
    ekf = _run(car3000, True)
    ukf = _run(car3000, True, filt="rbukf")
    assert abs(ukf.odo_scale[-1] - 3000.0 * PPM) < 300.0 * PPM
    assert abs(ukf.odo_scale[-1] - ekf.odo_scale[-1]) < 100.0 * PPM
    sm = _run(car3000, True, smooth=True)
    assert sm.summary["smoother"]["gain_failures"] == 0
    np.testing.assert_allclose(sm.odo_scale, ekf.odo_scale, rtol=0, atol=1e-12)
    e_f, e_s = errors(ekf, car3000.truth), errors(sm, car3000.truth)
    rms = lambda e: np.sqrt(np.mean(e["pos_n_m"][:, 0] ** 2 + e["pos_n_m"][:, 1] ** 2))  # noqa: E731
    assert rms(e_s) < rms(e_f)


def _max_in_outage(sol, ds, a, b):
    e = errors(sol, ds.truth)
    t = e["t"]
    return float(np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])[(t >= a) & (t <= b)].max())


def test_state_helps_a_scaled_odometer_through_an_outage():
    """+3000 ppm and a 60 s outage: with the state the along-track drift of
    the odometer's scale error is gone (max horizontal error smaller)."""
    ds = _car(3000.0, seed=2, outage=(500.0, 560.0))
    off = _max_in_outage(_run(ds, False), ds, 500.0, 560.0)
    on = _max_in_outage(_run(ds, True), ds, 500.0, 560.0)
    print(f"60 s outage, +3000 ppm: max horizontal error {off:.2f} m without the state, {on:.2f} m with")
    assert on < 0.7 * off


@pytest.fixture(scope="module")
def car0():
    return _car(0.0, seed=5, outage=(500.0, 530.0))


@pytest.mark.parametrize("sigma_odo", [None, 0.1])
def test_zero_true_scale_is_no_worse(car0, sigma_odo):
    """0 ppm: the state (estimating a zero) costs nothing: the outage error and
    the run's horizontal RMS within 10 % (+5 cm) of the run without it, both
    with each mode's default odometer sigma (None) and with the same 0.1 m/s."""
    ds = car0
    off, on = _run(ds, False, sigma_odo_mps=sigma_odo), _run(ds, True, sigma_odo_mps=sigma_odo)
    m_off, m_on = _max_in_outage(off, ds, 500.0, 530.0), _max_in_outage(on, ds, 500.0, 530.0)
    e_off, e_on = errors(off, ds.truth), errors(on, ds.truth)
    r = [float(np.sqrt(np.mean(e["pos_n_m"][:, 0] ** 2 + e["pos_n_m"][:, 1] ** 2))) for e in (e_off, e_on)]
    print(f"0 ppm: outage max {m_off:.3f} / {m_on:.3f} m, RMS {r[0]:.3f} / {r[1]:.3f} m (off / on); "
          f"estimate {on.odo_scale[-1] / PPM:.0f} +- {on.sigma_odo_scale[-1] / PPM:.0f} ppm")
    assert m_on <= 1.1 * m_off + 0.05
    assert r[1] <= 1.1 * r[0] + 0.05
    assert abs(on.odo_scale[-1]) < 3.0 * on.sigma_odo_scale[-1]


def test_auto_selects_the_state_with_the_odometer_on_15_states(car3000):
    cfg = Constraints(use=["nhc", "odo"])
    assert cfg.odo_scale == "auto" and cfg.odo_scale_state(15) and not cfg.odo_scale_state(21)
    assert not Constraints(use=["nhc"]).odo_scale_state(15)
    nhc = insnav.run(car3000, config=RunConfig(output_decimation=200, constraints=Constraints(use=["nhc"])))
    assert nhc.summary["layout"] == 15 and nhc.odo_scale is None


@pytest.mark.parametrize("table, needle", [
    ({"use": ["nhc", "odo"], "odo_scale": "yes"}, "constraints.odo_scale"),
    ({"use": ["nhc", "odo"], "odo_scale_sigma": -0.01}, "constraints.odo_scale_sigma"),
    ({"use": ["nhc", "odo"], "odo_scale_sigma": 2.0}, "constraints.odo_scale_sigma"),
    ({"use": ["nhc", "odo"], "odo_scale_tau_s": 0}, "constraints.odo_scale_tau_s"),
    ({"use": ["nhc", "odo"], "odo_scale_tau_s": "long"}, "constraints.odo_scale_tau_s"),
    ({"use": ["nhc"], "odo_scale": True}, "constraints.odo_scale"),
    ({"use": ["nhc", "odo"], "odo_scale_sigm": 0.01}, "unknown key 'constraints.odo_scale_sigm'"),
])
def test_bad_odo_scale_config_names_the_key(table, needle):
    with pytest.raises(ConfigError, match=needle.replace(".", r"\.")) as e:
        config_from_dict({"constraints": table})
    assert "\n" not in str(e.value)


def test_odo_scale_needs_the_15_state_layout():
    with pytest.raises(ConfigError, match=r"constraints\.odo_scale.*layout = 15"):
        config_from_dict({"layout": 21, "constraints": {"use": ["odo"], "odo_scale": True}})
    # auto on 21 states: no state, no error
    assert config_from_dict({"layout": 21, "constraints": {"use": ["odo"]}}).constraints.odo_scale == "auto"


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_scale_columns_round_trip_through_the_solution_file(car3000, tmp_path, suffix):
    """A run with the state writes ``odo_scale_ppm`` / ``sigma_odo_scale_ppm``
    last (in the ``bias`` group): back to 1e-4 ppm from the CSV, exactly from
    the npz; a run without it writes neither, and ``--columns nav`` drops them."""
    from insnav.filters.solution import load_solution

    sol = _run(car3000, True)
    path = sol.save(tmp_path / f"sol{suffix}")
    back = load_solution(path)
    # the CSV's 4 decimals of ppm; the npz stores the ppm values bit for bit, and ppm -> [-] costs an ulp or two
    for a, b in ((back.odo_scale, sol.odo_scale), (back.sigma_odo_scale, sol.sigma_odo_scale)):
        tol = 0.5e-4 * PPM * (1 + 1e-9) if suffix == ".csv" else 0.0
        assert np.all(np.abs(a - b) <= tol + 4e-16 * np.abs(b))
    assert abs(back.odo_scale[-1] - 3000 * PPM) < 300 * PPM  # the estimate itself, read back
    names = [n for n, _, _ in sol.columns()]
    assert names[-2:] == ["odo_scale_ppm", "sigma_odo_scale_ppm"] and len(names) == 33
    nav = load_solution(sol.save(tmp_path / f"nav{suffix}", columns="nav"))
    assert nav.odo_scale is None
    plain = _run(car3000, False)
    assert load_solution(plain.save(tmp_path / f"plain{suffix}")).odo_scale is None
