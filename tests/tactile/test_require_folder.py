"""Output folders: a path that is, or lies under, a file is refused with the file named."""

from __future__ import annotations

import pytest

from tactile.errors import ConfigError, require_folder


def test_require_folder(tmp_path):
    file = tmp_path / "f.txt"
    file.write_text("keep")
    for ok in (tmp_path, tmp_path / "new" / "deeper"):
        require_folder(ok)  # existing folders and paths still to be made pass
    for bad in (file, file / "run" / "x"):
        with pytest.raises(ConfigError, match=f"{file} is a file, not a folder. Fix: resume"):
            require_folder(bad, fix="resume")
    assert file.read_text() == "keep" and not (tmp_path / "new").exists()
