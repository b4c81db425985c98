"""The input-format registry (insnav.io.input_formats) is what `insnav run --format` offers and checks:
its choices, the arguments each format needs or refuses, and a format's loader giving the same
dataset as the direct loader."""
from __future__ import annotations

import argparse
from types import SimpleNamespace

import numpy as np
import pytest

from insnav.io.input_formats import INPUT_FORMATS, input_format


def _args(**kw):
    base = dict(dataset=None, obs=None, nav=None, imu=None, gnss=None, config=None, imu_tag=None)
    return SimpleNamespace(**{**base, **kw})


def test_cli_choices_are_the_registry():
    from insnav.cli.run import add_run_parser

    p = argparse.ArgumentParser()
    add_run_parser(p.add_subparsers())
    for name in INPUT_FORMATS:
        assert p.parse_args(["run", "--format", name]).format == name
    with pytest.raises(SystemExit):
        p.parse_args(["run", "--format", "ubx"])
    with pytest.raises(ValueError, match="known: insnav, kfgins, rinex, csv"):
        input_format("ubx")


@pytest.mark.parametrize("name", list(INPUT_FORMATS))
def test_each_format_names_what_it_needs(name, tmp_path):
    fmt = INPUT_FORMATS[name]
    files = {n: str(tmp_path) for n in fmt.required}
    fmt.check(_args(**files))  # everything given: no error
    for n in fmt.required:
        with pytest.raises(ValueError, match=f"--format {name} needs" if n != "dataset" else "dataset directory not found"):
            fmt.check(_args(**{**files, n: None}) if n != "dataset" else _args(dataset=str(tmp_path / "none")))
    if "dataset" not in fmt.required and set(fmt.required) - {"config"}:
        with pytest.raises(ValueError, match="do not give a dataset directory"):
            fmt.check(_args(**files, dataset=str(tmp_path)))


def test_insnav_format_loads_the_directory(tmp_path):
    import insnav

    ds = insnav.simulate("seed000-sim", seed=1)
    ds.save(tmp_path / "d")
    got = input_format("insnav").load(_args(dataset=str(tmp_path / "d")))
    ref = insnav.load_dataset(tmp_path / "d")
    assert got.tables == {} and got.config.filter == "ekf"
    np.testing.assert_array_equal(got.dataset.imu.dv_b, ref.imu.dv_b)
    np.testing.assert_array_equal(got.dataset.gnss.lat_deg, ref.gnss.lat_deg)
