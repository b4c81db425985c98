"""Property-based fuzzing of the readers and the batch API boundary.

Each reader gets a valid file mutated by a hypothesis-drawn list of edits
(delete / duplicate / swap lines, replace a field by NaN, inf, a huge or a
non-numeric token, truncate, insert junk bytes).  The property: the reader
either succeeds -- and then what it returns holds no NaN where NaN is not
allowed -- or raises the reader's documented error type (``ValueError`` and
its subclasses ``RinexError``, ``ConfigError``, ``ScenarioError``), whose
message names the file.  Never another exception, never a crash.

Fixed budget (``max_examples``) so the suite stays fast; the long run is
``bench/fuzz_readers.py``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import insnav
from insnav.config import ConfigError, config_from_dict
from insnav.data.dataset import load_dataset
from conftest import SHARED_DATA  # ../shared/data beside the repo, or $INSNAV_SHARED_DATA
from insnav.gnss import RinexError, read_rinex_nav, read_rinex_obs
from insnav.io import kfgins
from insnav.sim.scenario import ScenarioError, load_scenario, resolve_raw

FUZZ = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
TOKENS = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-320", "", "x", "0x1p3", "1,5", "--1", "1e",
          "\x00", "\xff", "9" * 40, "-0", "+", "1.0.0", "\t", "1e155", "-1e155", "300", "-1"]

edit = st.one_of(
    st.tuples(st.just("del"), st.integers(0, 10_000)),
    st.tuples(st.just("dup"), st.integers(0, 10_000)),
    st.tuples(st.just("swap"), st.integers(0, 10_000)),
    st.tuples(st.just("field"), st.integers(0, 10_000), st.integers(0, 30), st.sampled_from(TOKENS)),
    st.tuples(st.just("trunc"), st.floats(0.0, 1.0)),
    st.tuples(st.just("junk"), st.integers(0, 10_000), st.text(max_size=8)),
)
edits = st.lists(edit, min_size=1, max_size=4)
#: the edits of the whole-pipeline fuzz: also an emptied file and a field replaced in every line
edit_run = st.one_of(edit, st.just(("empty",)),
                     st.tuples(st.just("column"), st.integers(0, 30), st.sampled_from(TOKENS)))
edits_run = st.lists(edit_run, min_size=1, max_size=3)


def mutate(text: str, ops, sep=None) -> str:
    lines = text.split("\n")
    for op in ops:
        n = len(lines)
        if n == 0:
            break
        i = op[1] % n if op[0] not in ("trunc", "empty", "column") else 0
        if op[0] == "empty":
            return ""
        if op[0] == "column":  # one field of every line (a unit typed wrong for the whole file)
            for k, line in enumerate(lines):
                parts = line.split(sep) if sep else line.split()
                if parts:
                    parts[op[1] % len(parts)] = op[2]
                    lines[k] = (sep or " ").join(parts)
            continue
        if op[0] == "del":
            del lines[i]
        elif op[0] == "dup":
            lines.insert(i, lines[i])
        elif op[0] == "swap" and n > 1:
            j = (i + 1) % n
            lines[i], lines[j] = lines[j], lines[i]
        elif op[0] == "field":
            parts = lines[i].split(sep) if sep else lines[i].split()
            if parts:
                parts[op[2] % len(parts)] = op[3]
                lines[i] = (sep or " ").join(parts)
        elif op[0] == "trunc":
            s = "\n".join(lines)
            return s[: int(len(s) * op[1])]
        elif op[0] == "junk":
            k = op[1] % (len(lines[i]) + 1)
            lines[i] = lines[i][:k] + op[2] + lines[i][k:]
    return "\n".join(lines)


def expect_reader_error(exc: BaseException, name: str) -> None:
    assert isinstance(exc, (ValueError, FileNotFoundError)), f"{type(exc).__name__}: {exc}"
    assert name in str(exc), f"message does not name the file {name}: {exc}"


@pytest.fixture(scope="module")
def small_ds():
    ds = insnav.simulate("seed000-sim", seed=1)
    n = 600  # 3 s of IMU, 3 fixes
    ds.imu = type(ds.imu)(ds.imu.t[:n], ds.imu.dtheta_b[:n], ds.imu.dv_b[:n])
    ds.gnss = type(ds.gnss).from_array(ds.gnss.to_array()[:3])
    ds.truth = None
    ds.imu_errors = None
    return ds


@pytest.fixture(scope="module")
def ds_dir(small_ds, tmp_path_factory):
    return small_ds.save(tmp_path_factory.mktemp("fuzz") / "ds")


@FUZZ
@given(ops=edits, which=st.sampled_from(["imu.csv", "gnss.csv", "dataset.json"]))
def test_fuzz_dataset_dir(ds_dir, tmp_path_factory, ops, which):
    import shutil

    d = tmp_path_factory.mktemp("m") / "ds"
    shutil.copytree(ds_dir, d)
    p = d / which
    p.write_text(mutate(p.read_text(), ops, sep=","), encoding="utf-8", errors="surrogatepass") \
        if which != "dataset.json" else p.write_text(mutate(p.read_text(), ops), encoding="utf-8",
                                                     errors="surrogatepass")
    try:
        ds = load_dataset(d)
    except Exception as exc:  # noqa: BLE001 - the property is about the type
        expect_reader_error(exc, which if which != "dataset.json" else "dataset")
        return
    assert np.isfinite(ds.imu.t).all() and np.isfinite(ds.imu.dtheta_b).all() and np.isfinite(ds.imu.dv_b).all()
    assert np.isfinite(ds.gnss.t_valid).all()
    # the run either works (sanitised) or refuses with a message; never a NaN in the output
    try:
        sol = insnav.run(ds, init_error=False)
    except ValueError as exc:
        assert str(exc)
        return
    assert np.isfinite(sol.lat_deg).all() and np.isfinite(sol.sigma_pos_n_m).all()


@FUZZ
@given(ops=edits)
def test_fuzz_kfgins_imu_and_gnss(small_ds, tmp_path_factory, ops):
    d = tmp_path_factory.mktemp("kf")
    kfgins.write_kfgins_imu(d / "imu.txt", small_ds.imu)
    kfgins.write_kfgins_gnss(d / "gnss.txt", small_ds.gnss, with_velocity=True)
    for name, reader in (("imu.txt", kfgins.read_kfgins_imu), ("gnss.txt", kfgins.read_kfgins_gnss)):
        p = d / name
        p.write_text(mutate(p.read_text(), ops), encoding="utf-8", errors="surrogatepass")
        try:
            out = reader(p)
        except Exception as exc:  # noqa: BLE001
            expect_reader_error(exc, name)
            continue
        if name == "imu.txt":
            assert np.isfinite(out.to_array()).all()
            assert not (np.diff(out.t) < 0).any()
            assert out.origin is not None and out.origin.source.endswith(name)
        else:
            assert np.isfinite(out.t_valid).all()


@FUZZ
@given(ops=edits)
def test_fuzz_kfgins_yaml(tmp_path_factory, ops):
    base = ("imupath: imu.txt\ngnsspath: gnss.txt\noutputpath: out\nimudatalen: 7\nimudatarate: 200\n"
            "starttime: 100\nendtime: -1\ninitpos: [30.0, 114.0, 20.0]\ninitvel: [0, 0, 0]\n"
            "initatt: [0, 0, 90]\nimunoise:\n  arw: [0.2, 0.2, 0.2]\n  vrw: [0.4, 0.4, 0.4]\n"
            "  corrtime: 1.0\nantlever: [0.1, 0.2, 0.3]\n")
    p = tmp_path_factory.mktemp("y") / "kf-gins.yaml"
    p.write_text(mutate(base, ops), encoding="utf-8", errors="surrogatepass")
    try:
        kfgins.read_kfgins_config(p)
    except Exception as exc:  # noqa: BLE001
        expect_reader_error(exc, "kf-gins.yaml")


def _kfgins_set(small_ds, d):
    """A valid KF-GINS YAML + IMU + GNSS set of the small dataset in folder d."""
    i = small_ds.initial
    kfgins.write_kfgins_imu(d / "imu.txt", small_ds.imu)
    kfgins.write_kfgins_gnss(d / "gnss.txt", small_ds.gnss)
    (d / "kf-gins.yaml").write_text(
        f"imupath: imu.txt\ngnsspath: gnss.txt\noutputpath: out\nimudatalen: 7\nimudatarate: 200\n"
        f"starttime: {small_ds.t0}\nendtime: -1\ninitpos: [{i.lat_deg}, {i.lon_deg}, {i.h_m}]\n"
        f"initvel: [0, 0, 0]\ninitatt: [{i.roll_deg}, {i.pitch_deg}, {i.yaw_deg}]\n"
        "imunoise:\n  arw: [0.2, 0.2, 0.2]\n  vrw: [0.4, 0.4, 0.4]\n  corrtime: 1.0\n"
        "antlever: [0.1, 0.2, 0.3]\n")


@FUZZ
@given(ops=edits_run, which=st.sampled_from(["imu.txt", "gnss.txt", "kf-gins.yaml"]))
def test_fuzz_kfgins_load_and_run(small_ds, tmp_path_factory, ops, which):
    """The whole `insnav run --format kfgins` path on a mutated file: a ValueError naming a file, or a
    finite solution; never IndexError (an empty IMU file, endtime before starttime) or FloatingPointError
    (a lever arm in mm, a GNSS sigma of 1e155)."""
    from insnav.io.kfgins_dataset import load_kfgins

    d = tmp_path_factory.mktemp("kfrun")
    _kfgins_set(small_ds, d)
    p = d / which
    p.write_text(mutate(p.read_text(), ops, sep=None), encoding="utf-8", errors="surrogatepass")
    try:
        ds, cfg = load_kfgins(d / "kf-gins.yaml")
        sol = insnav.run(ds, config=cfg)
    except Exception as exc:  # noqa: BLE001 - the property is about the type and the message
        assert isinstance(exc, (ValueError, FileNotFoundError)), f"{type(exc).__name__}: {exc}"
        assert any(n in str(exc) for n in ("imu.txt", "gnss.txt", "kf-gins.yaml", "dataset")), str(exc)
        return
    assert np.isfinite(sol.lat_deg).all() and np.isfinite(sol.sigma_pos_n_m).all()


@pytest.mark.parametrize("kind", ["empty", "endtime", "antlever_mm", "sigma_1e155"])
def test_kfgins_cases_found_by_fuzzing(small_ds, tmp_path, kind):
    """The cases the fuzzing found, each a one-line ValueError naming the file and the key or line."""
    from insnav.io.kfgins_dataset import load_kfgins

    _kfgins_set(small_ds, tmp_path)
    y = tmp_path / "kf-gins.yaml"
    if kind == "empty":
        (tmp_path / "imu.txt").write_text("")
        said = "imu.txt:1: no IMU records"
    elif kind == "endtime":
        y.write_text(y.read_text().replace(f"starttime: {small_ds.t0}", f"starttime: {small_ds.t0 + 1.0}")
                     .replace("endtime: -1", f"endtime: {small_ds.t0 + 0.5}"))
        said = "kf-gins.yaml: key 'endtime'"
    elif kind == "antlever_mm":
        y.write_text(y.read_text().replace("antlever: [0.1, 0.2, 0.3]", "antlever: [100, 200, 300]"))
        said = "kf-gins.yaml: key 'antlever'"
    else:
        g = tmp_path / "gnss.txt"
        rows = g.read_text().splitlines()
        f = rows[1].split()
        f[5] = "1e155"  # std_E
        rows[1] = " ".join(f)
        g.write_text("\n".join(rows) + "\n")
        ds, cfg = load_kfgins(y)
        sol = insnav.run(ds, config=cfg)  # the fix is dropped and counted (insnav.filters.sanitize)
        assert sol.summary["sanitize"]["gnss_invalid_dropped"] == 1
        assert sol.summary["sanitize"]["gnss_dropped_lines"] == [2]
        assert np.isfinite(sol.sigma_pos_n_m).all()
        with pytest.raises(ValueError, match=r"gnss.txt:2: sigma_\{n,e,d\}_m = .*1e\+155"):
            insnav.run(ds, config=cfg, sanitize=False)
        return
    with pytest.raises(ValueError) as err:
        ds, cfg = load_kfgins(y)
        insnav.run(ds, config=cfg)
    assert said in str(err.value) and "\n" not in str(err.value)


#: values of the wrong type for a TOML key (a table, a nested list, a list of strings, a number...)
WRONG_TYPES = [5, 1.5, float("nan"), True, "x", "", [1, 2], [1, 2, 3], ["a", "b", "c"], {"a": 1}, [], [[1]]]


def test_toml_tables_wrong_types():
    """Every key of the run TOML and of its --format csv / rinex tables, with values of every wrong
    type: a ConfigError (a ValueError naming the key), never TypeError."""
    import dataclasses

    from insnav.config import Constraints, Robust, RunConfig, _USER_UNITS
    from insnav.io.csv_dataset import ALIGN_KEYS, GNSS_KEYS, IMU_KEYS, INITIAL_KEYS, load_csv_run
    from insnav.io.rinex_dataset import RinexOptions

    cases = [{k.name: v} for k in dataclasses.fields(RunConfig) for v in WRONG_TYPES]
    cases += [{t: {f.name: v}} for t, c in (("constraints", Constraints), ("robust", Robust))
              for f in dataclasses.fields(c) for v in WRONG_TYPES]
    cases += [{"imu": {k: v}} for k in _USER_UNITS for v in WRONG_TYPES]
    found = []
    for d in cases:
        try:
            config_from_dict(d, source="run.toml")
        except ConfigError:
            pass
        except Exception as exc:  # noqa: BLE001
            found.append(f"{d}: {type(exc).__name__}: {exc}")
    for t, keys in (("imu", IMU_KEYS), ("gnss", GNSS_KEYS), ("initial", INITIAL_KEYS), ("align", ALIGN_KEYS)):
        for k in keys:
            for v in WRONG_TYPES:
                try:
                    load_csv_run("/nonexistent/imu.csv", "/nonexistent/gnss.csv", {t: {k: v}})
                except (ValueError, FileNotFoundError):
                    pass
                except Exception as exc:  # noqa: BLE001
                    found.append(f"[{t}] {k} = {v!r}: {type(exc).__name__}: {exc}")
    for f in dataclasses.fields(RinexOptions):
        for v in WRONG_TYPES:
            try:
                RinexOptions.from_dict({f.name: v})
            except ConfigError:
                pass
            except Exception as exc:  # noqa: BLE001
                found.append(f"[rinex] {f.name} = {v!r}: {type(exc).__name__}: {exc}")
    assert not found, f"{len(found)} wrong types not named: " + "; ".join(found[:5])


RINEX_OBS = SHARED_DATA / "rtklibexplorer_walk_0827" / "rinex_derived"


@pytest.fixture(scope="module")
def rinex_texts():
    if not RINEX_OBS.is_dir():
        pytest.skip("shared RINEX data not available")
    obs = (RINEX_OBS / "gnss_1730.obs").read_text()
    head, body = obs.split("END OF HEADER", 1)
    obs_small = head + "END OF HEADER" + "\n".join(body.split("\n")[:120]) + "\n"
    return {"nav": (RINEX_OBS / "gnss_1730.nav").read_text(), "obs": obs_small}


@FUZZ
@given(ops=edits, which=st.sampled_from(["nav", "obs"]))
def test_fuzz_rinex(rinex_texts, tmp_path_factory, ops, which):
    p = tmp_path_factory.mktemp("r") / f"fuzz.{which}"
    p.write_text(mutate(rinex_texts[which], ops), encoding="utf-8", errors="surrogatepass")
    reader = read_rinex_nav if which == "nav" else read_rinex_obs
    try:
        reader(p)
    except RinexError as exc:
        assert "fuzz." in str(exc)
    except Exception as exc:  # noqa: BLE001
        pytest.fail(f"{type(exc).__name__} instead of RinexError: {exc}")


toml_scalar = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
                        st.booleans(), st.text(max_size=6), st.lists(st.floats(-1e3, 1e3), max_size=4))


@FUZZ
@given(key=st.sampled_from(["filter", "coupling", "layout", "init_sigma_pos_m", "init_sigma_vel_mps",
                            "init_sigma_att_deg", "init_error", "init_seed", "gate_chi2", "use_position",
                            "propagation_interval_s", "cycle_period_s", "output_decimation", "ut_alpha",
                            "ut_beta", "ut_kappa", "lever_arm_b", "imu", "bogus"]),
       value=toml_scalar)
def test_fuzz_run_config(key, value):
    try:
        cfg = config_from_dict({key: value}, source="run.toml")
    except ConfigError as exc:
        assert "run.toml" in str(exc) or key in str(exc)
        return
    except Exception as exc:  # noqa: BLE001
        pytest.fail(f"{type(exc).__name__} instead of ConfigError for {key}={value!r}: {exc}")
    # an accepted value must be usable: finite numbers where numbers are expected
    for k in ("gate_chi2", "propagation_interval_s", "ut_alpha", "ut_beta"):
        v = getattr(cfg, k)
        assert (v is None and k == "gate_chi2") or math.isfinite(float(v)), (k, v)


@FUZZ
@given(path=st.sampled_from([("initial", "lat_deg"), ("initial", "h_m"), ("imu", "rate_hz"),
                             ("gnss", "rate_hz"), ("gnss", "sigma_h_m"), ("gnss", "outages"),
                             ("time", "t0_s"), ("imu", "gyro", "arw_deg_per_sqrth"), ("motion", "transition_s"),
                             ("gnss", "lever_arm_b_m"), ("truth", "rate_hz"), ("seed",)]),
       value=toml_scalar)
def test_fuzz_scenario(path, value):
    raw, _ = resolve_raw("seed000-sim")
    d = raw
    for k in path[:-1]:
        d = d.setdefault(k, {})
    d[path[-1]] = value
    try:
        load_scenario(raw)
    except ScenarioError:
        return
    except Exception as exc:  # noqa: BLE001
        pytest.fail(f"{type(exc).__name__} instead of ScenarioError for {'.'.join(path)}={value!r}: {exc}")


# --------------------------------------------------------------- batch API boundary
arrays = st.integers(0, 6).flatmap(lambda n: st.tuples(
    st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=n, max_size=n),
    st.lists(st.floats(-1e3, 1e3) | st.sampled_from([np.nan, np.inf]), min_size=3 * n, max_size=3 * n),
    st.lists(st.floats(-1e3, 1e3) | st.sampled_from([np.nan, np.inf]), min_size=3 * n, max_size=3 * n)))


@FUZZ
@given(data=arrays, shape_bug=st.booleans())
def test_fuzz_mechanize_boundary(data, shape_bug):
    t, a, b = (np.array(x, float) for x in data)
    dth = a.reshape(-1, 3) if not shape_bug else a
    dv = b.reshape(-1, 3)
    init = insnav.NavState(30.0, 114.0, 20.0, [0, 0, 0], 0, 0, 0)
    try:
        tr = insnav.mechanize(t, dth, dv, init, t0=-1e300)
    except (ValueError, FloatingPointError) as exc:
        assert str(exc)
        return
    assert np.isfinite(tr.lat_deg).all()


@FUZZ
@given(data=arrays)
def test_fuzz_run_boundary(small_ds, data):
    import dataclasses

    t, a, b = (np.array(x, float) for x in data)
    n = len(t)
    imu = type(small_ds.imu)(np.concatenate([small_ds.imu.t[:200], small_ds.imu.t[199] + np.abs(t)]),
                             np.concatenate([small_ds.imu.dtheta_b[:200], a.reshape(n, 3)]),
                             np.concatenate([small_ds.imu.dv_b[:200], b.reshape(n, 3)]))
    ds = dataclasses.replace(small_ds, imu=imu)
    try:
        sol = insnav.run(ds, init_error=False)
    except (ValueError, FloatingPointError) as exc:
        assert str(exc)
        return
    assert np.isfinite(sol.lat_deg).all() and np.isfinite(sol.sigma_pos_n_m).all()
