"""A sweep run's files between a node without the sweep directory and the driver (`unshared`)."""

import os

import pytest

from swarmcode_torch.app import unshared


def test_tree_round_trip_skips_lock_and_links(tmp_path):
    src = tmp_path / "src"
    (src / "tb").mkdir(parents=True)
    (src / "config.toml").write_bytes(b"a = 1\n")
    (src / "tb" / "events").write_bytes(bytes(range(256)))
    (src / "run.lock").write_text("pid=1")
    os.symlink(tmp_path / "elsewhere", src / "link")
    files = unshared.read_tree(src)
    assert sorted(files) == ["config.toml", "tb/events"]
    dst = tmp_path / "dst"
    unshared.write_tree(dst, files)
    assert unshared.read_tree(dst) == files
    assert unshared.read_tree(tmp_path / "missing") == {}


@pytest.mark.parametrize("bad", ["../x", "/etc/x", "a/../../x", ""])
def test_write_tree_refuses_paths_outside(tmp_path, bad):
    with pytest.raises(ValueError, match="refused a file path"):
        unshared.write_tree(tmp_path / "d", {"ok": b"1", bad: b"2"})
    assert not (tmp_path / "d").exists()  # nothing written before the check


def test_storage_mark(tmp_path):
    token = unshared.mark_storage(tmp_path)
    assert unshared.sees_storage(tmp_path, token)
    assert not unshared.sees_storage(tmp_path, token[::-1])
    assert not unshared.sees_storage(tmp_path / "missing", token)
    assert unshared.mark_storage(tmp_path) != token


def test_run_elsewhere_returns_files_even_after_an_error(tmp_path):
    def run(local):
        assert (local / "checkpoint.pt").read_bytes() == b"old"
        (local / "checkpoint.pt").write_bytes(b"new")
        return "stopped"

    error, files = unshared.run_elsewhere(tmp_path / "run", {"checkpoint.pt": b"old"}, run)
    assert error == "stopped" and files == {"checkpoint.pt": b"new"}
