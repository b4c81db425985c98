"""Inputs that are not regular files (a named pipe, a device): one line naming them, before anything
opens them (a FIFO given as ``--obs`` blocked until a writer appeared); output options may name a
device (``--out /dev/null``)."""
from __future__ import annotations

import os

import pytest

from insnav.cli import _refuse_special_inputs, main
from insnav.errors import UserError

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this platform")


@pytest.fixture
def fifo(tmp_path):
    p = tmp_path / "rover.obs"
    os.mkfifo(p)
    return p


def test_a_fifo_as_the_rover_is_one_line_and_nothing_blocks(fifo, tmp_path, capsys):
    rc = main(["run", "--filter", "rtk", "--format", "rinex", "--obs", str(fifo), "--base", str(tmp_path / "b.obs"),
               "--nav", str(tmp_path / "n.nav"), "--out", str(tmp_path / "sol.pos")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert err == [f"insnav run: error: {fifo}: not a regular file (a named pipe, socket or device): insnav reads "
                   "its inputs as files, whole and some twice; copy it to a file first"]
    assert not list(tmp_path.glob("sol.pos*"))


@pytest.mark.parametrize("argv", [["evaluate", "{fifo}", "ref.pos"], ["run", "--nav={here},{fifo}"],
                                  ["run", "--imu", "/dev/zero"]])
def test_every_input_form_is_checked(fifo, argv):
    argv = [a.format(fifo=fifo, here=__file__) for a in argv]
    with pytest.raises(UserError, match="not a regular file"):
        _refuse_special_inputs(argv)


@pytest.mark.parametrize("argv", [["run", "--out", "/dev/null", "--imu", __file__], ["run", "--out=/dev/null"],
                                  ["simulate", "--out-dir", "/dev/null"], ["run", "--base-pos", "35.1,136.9,104.8"],
                                  ["run", "--obs", os.path.dirname(__file__)]])
def test_outputs_regular_files_folders_and_numbers_pass(argv):
    _refuse_special_inputs(argv)


@pytest.mark.parametrize("name", ["sol.csv", "sol.npz", "sol.pos", "eval.json", "sol.csv.innovations.csv"])
def test_an_output_that_is_a_named_pipe_is_refused_without_blocking(tmp_path, name):
    """An existing named pipe given as an output: the check of whether insnav wrote it read its first
    bytes, which blocked until a writer appeared (``insnav run --out fifo.csv`` hung).  Now it is
    "a file insnav did not write", refused before any work, and the pipe is left as it was."""
    import stat

    from insnav._outputs import check_outputs, insnav_output_kind

    p = tmp_path / name
    os.mkfifo(p)
    assert insnav_output_kind(p) is None
    with pytest.raises(UserError, match="exists and is not a file insnav wrote: not replaced"):
        check_outputs([p], {})
    assert stat.S_ISFIFO(os.stat(p).st_mode)
