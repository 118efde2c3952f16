"""write_atomic: the whole file or nothing, with the permissions an ordinary write gives."""
import os
import stat

import pytest

from bolus_addon.core.errors import BolusError
from bolus_addon.core.files import write_atomic


def test_written_file_has_the_bytes_and_no_temporary_is_left(tmp_path):
    target = tmp_path / "pattern.svg"
    write_atomic(str(target), b"<svg/>")
    assert target.read_bytes() == b"<svg/>"
    assert [p.name for p in tmp_path.iterdir()] == ["pattern.svg"]


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_written_file_is_readable_like_an_ordinary_write(tmp_path):
    plain = tmp_path / "plain.txt"
    plain.write_bytes(b"x")
    target = tmp_path / "pattern.dxf"
    write_atomic(str(target), b"0\nEOF\n")
    assert stat.S_IMODE(target.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)
    assert target.stat().st_mode & stat.S_IROTH == plain.stat().st_mode & stat.S_IROTH


def test_unwritable_folder_raises_and_leaves_the_old_file(tmp_path):
    target = tmp_path / "missing_folder" / "pattern.svg"
    with pytest.raises(BolusError, match="could not write"):
        write_atomic(str(target), b"data")
    assert not target.exists()
