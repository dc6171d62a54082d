"""MuJoCo warnings during generation: logged, not printed, and no MUJOCO_LOG.TXT in the cwd.

The reference is MuJoCo's own default handler: outside the context the same warning writes the
file in the working directory, so the check inside can fail."""

from __future__ import annotations

import logging

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from sim.episode.mjlog import mujoco_warnings_logged  # noqa: E402

XML = "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>"


def _warn() -> None:
    """Raise MuJoCo's mjWARN_BADQPOS the way its own bindings test does (NaN qpos)."""
    model = mujoco.MjModel.from_xml_string(XML)
    data = mujoco.MjData(model)
    data.qpos[0] = np.nan
    mujoco.mj_checkPos(model, data)
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQPOS].number == 1


def test_warnings_go_to_the_log_and_the_hook_is_restored(tmp_path, monkeypatch, caplog, capfd):
    monkeypatch.chdir(tmp_path)
    before = mujoco.get_mju_user_warning()
    with caplog.at_level(logging.DEBUG, logger="sim.episode.mjlog"), mujoco_warnings_logged():
        _warn()
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert "Nan, Inf or huge value in QPOS" in caplog.text
    assert "QPOS" not in capfd.readouterr().err
    assert mujoco.get_mju_user_warning() is before

    _warn()  # MuJoCo's default handler: the file the context keeps away
    assert "QPOS" in (tmp_path / "MUJOCO_LOG.TXT").read_text()


def test_the_hook_is_restored_when_the_body_raises():
    before = mujoco.get_mju_user_warning()
    with pytest.raises(RuntimeError), mujoco_warnings_logged():
        raise RuntimeError("boom")
    assert mujoco.get_mju_user_warning() is before
