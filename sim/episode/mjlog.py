"""MuJoCo's warnings as Python log records, not stderr lines and a MUJOCO_LOG.TXT in the cwd.

MuJoCo's default handler prints each warning and appends it to ``MUJOCO_LOG.TXT`` in the working
directory. The episode runner reads the same warnings from ``data.warning`` and rejects the
attempt (reason ``"warning"``, counted in the dataset's ``rejects``), so during generation they
are expected events: they go to the ``sim.episode.mjlog`` logger at DEBUG level instead, and neither
break a progress bar nor litter the user's folder.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

import mujoco

LOG = logging.getLogger(__name__)


def _to_log(message: str) -> None:
    LOG.debug("MuJoCo: %s", message.strip())


@contextmanager
def mujoco_warnings_logged() -> Iterator[None]:
    """Inside, MuJoCo warnings go to the ``sim.episode.mjlog`` logger (DEBUG); the previous hook
    after.

    Uses MuJoCo's warning hook (``mju_user_warning``), which its default log handler calls
    instead of printing and writing the file. Errors are untouched (the bindings raise them).
    The hook is process-wide, not per thread: generation's workers are processes.
    """
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(_to_log)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)
