"""The unpacked FMU kept between runs (system_models.fmu_cache): reused, never stale, whole when
runs race, a private copy for a second live instance, unused where other users could write."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from system_models import fmu_cache

ROOT = Path(__file__).resolve().parents[1]


def _fmu(path: Path, text: str) -> Path:
    """A zip with a model description and one resource file holding ``text``."""
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
        z.writestr("resources/data.txt", text)
    return path


@pytest.fixture
def root(tmp_path, monkeypatch) -> Path:
    r = tmp_path / "cache"
    monkeypatch.setattr(fmu_cache, "cache_root", lambda: r)
    return r


def test_unpacked_once_then_reused(root, tmp_path):
    fmu = _fmu(tmp_path / "A.fmu", "one")
    d1, private = fmu_cache.unpack(fmu)
    assert not private and Path(d1).parent == root
    assert (Path(d1) / "resources" / "data.txt").read_text() == "one"
    (Path(d1) / "marker").write_text("")            # a second unpack would not keep it
    fmu_cache.release(d1, private)
    d2, private = fmu_cache.unpack(fmu)
    assert (d2, private) == (d1, False) and (Path(d2) / "marker").exists()
    fmu_cache.release(d2, private)
    assert Path(d2).is_dir()                         # kept for the next run
    assert os.stat(root).st_mode & 0o077 == 0        # closed to other users


def test_a_rebuilt_fmu_is_never_served_the_old_copy(root, tmp_path):
    # same path, same size, same modification time, other bytes: another copy
    fmu = _fmu(tmp_path / "A.fmu", "one")
    st = os.stat(fmu)
    d1, p1 = fmu_cache.unpack(fmu)
    fmu_cache.release(d1, p1)
    _fmu(fmu, "two")
    os.utime(fmu, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert os.stat(fmu).st_size == st.st_size
    d2, p2 = fmu_cache.unpack(fmu)
    assert d2 != d1 and not p2
    assert (Path(d2) / "resources" / "data.txt").read_text() == "two"
    fmu_cache.release(d2, p2)


def test_a_second_live_instance_gets_a_private_copy(root, tmp_path):
    fmu = _fmu(tmp_path / "A.fmu", "one")
    d1, p1 = fmu_cache.unpack(fmu)
    d2, p2 = fmu_cache.unpack(fmu)                   # d1 still in use
    assert not p1 and p2 and d2 != d1
    assert (Path(d2) / "resources" / "data.txt").read_text() == "one"
    fmu_cache.release(d2, p2)
    assert not Path(d2).exists()                     # the private copy is removed
    fmu_cache.release(d1, p1)
    assert Path(d1).is_dir()
    d3, p3 = fmu_cache.unpack(fmu)                   # free again: the cached copy
    assert (d3, p3) == (d1, False)
    fmu_cache.release(d3, p3)


@pytest.mark.parametrize("mode", [0o777, 0o755])
def test_a_cache_directory_others_can_enter_or_write_is_not_used(root, tmp_path, mode):
    root.mkdir()
    os.chmod(root, mode)
    fmu = _fmu(tmp_path / "A.fmu", "one")
    d, private = fmu_cache.unpack(fmu)
    assert private and Path(d).parent != root
    assert (Path(d) / "resources" / "data.txt").read_text() == "one"
    fmu_cache.release(d, private)
    assert not Path(d).exists() and list(root.iterdir()) == []


def test_no_cache_where_files_have_no_posix_owner(root, tmp_path, monkeypatch):
    # Windows: no os.getuid, no owner to check: private copies, as before the cache
    monkeypatch.delattr(fmu_cache.os, "getuid")
    d, private = fmu_cache.unpack(_fmu(tmp_path / "A.fmu", "one"))
    assert private and (Path(d) / "resources" / "data.txt").read_text() == "one"
    fmu_cache.release(d, private)
    assert not Path(d).exists()


def test_a_symlinked_cache_directory_is_not_used(tmp_path, monkeypatch):
    real = tmp_path / "elsewhere"
    real.mkdir(mode=0o700)
    link = tmp_path / "cache"
    link.symlink_to(real)
    monkeypatch.setattr(fmu_cache, "cache_root", lambda: link)
    d, private = fmu_cache.unpack(_fmu(tmp_path / "A.fmu", "one"))
    assert private and list(real.iterdir()) == []
    fmu_cache.release(d, private)


def test_old_copies_no_instance_holds_are_removed_when_a_new_one_is_made(root, tmp_path):
    # copies of A (held by a live instance), B (unused) and C (used recently), a killed
    # run's half-unpacked leftover (old) and one being unpacked (young); then a new FMU D
    old = fmu_cache.PRUNE_AFTER + 60.0            # [s] older than the bound
    dirs = {}
    for name in "ABC":
        d, private = fmu_cache.unpack(_fmu(tmp_path / f"{name}.fmu", name))
        assert not private
        dirs[name] = Path(d)
    for name in "BC":
        fmu_cache.release(str(dirs[name]), False)
    leftover, young = root / ".A-killed", root / ".A-unpacking"
    leftover.mkdir()
    young.mkdir()
    t = time.time()
    for d in (dirs["A"], dirs["B"], leftover):
        os.utime(d, (t - old, t - old))
    d, private = fmu_cache.unpack(_fmu(tmp_path / "D.fmu", "D"))
    assert not private
    left = {p.name for p in root.iterdir()}
    assert left == {dirs["A"].name, dirs["C"].name, Path(d).name, young.name}, left
    fmu_cache.release(str(dirs["A"]), False)
    fmu_cache.release(d, False)


def test_a_copy_removed_as_it_is_taken_is_unpacked_again(root, tmp_path, monkeypatch):
    fmu = _fmu(tmp_path / "A.fmu", "one")
    real = fmu_cache._cached_copy
    calls = []

    def removed_meanwhile(path):
        d = real(path)
        calls.append(d)
        if len(calls) == 1:                       # a prune in another run, just now
            shutil.rmtree(d)
        return d

    monkeypatch.setattr(fmu_cache, "_cached_copy", removed_meanwhile)
    d, private = fmu_cache.unpack(fmu)
    assert len(calls) == 2 and not private
    assert (Path(d) / "resources" / "data.txt").read_text() == "one"
    fmu_cache.release(d, private)


_RACER = """
import sys, time
from pathlib import Path
from system_models import fmu_cache
fmu_cache.cache_root = lambda: Path(sys.argv[1])
start = float(sys.argv[3])
while time.time() < start:
    pass
d, private = fmu_cache.unpack(sys.argv[2])
print(d, private, (Path(d) / "resources" / "data.txt").read_text())
"""


def test_runs_that_race_all_get_one_whole_copy(root, tmp_path):
    # 6 processes released at the same instant on an empty cache (an FMU of 200 members so
    # that the unpacking takes a while): each gets the one copy, whole; no temporary left
    fmu = tmp_path / "A.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
        z.writestr("resources/data.txt", "one")
        for i in range(200):
            z.writestr(f"resources/f{i}.bin", os.urandom(4096))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    start = time.time() + 1.5
    procs = [subprocess.Popen([sys.executable, "-c", _RACER, str(root), str(fmu), str(start)],
                              stdout=subprocess.PIPE, text=True, env=env) for _ in range(6)]
    outs = [p.communicate(timeout=120)[0].split() for p in procs]
    assert all(p.returncode == 0 for p in procs)
    dirs = {o[0] for o in outs}
    assert len(dirs) == 1 and all(o[1:] == ["False", "one"] for o in outs), outs
    (d,) = dirs
    assert len(list(Path(d).rglob("*.bin"))) == 200
    assert [p.name for p in root.iterdir()] == [Path(d).name]


def test_the_loser_of_a_race_uses_the_winners_copy(root, tmp_path, monkeypatch):
    # another run renames its whole copy into place while this one unpacks: this one's rename
    # fails (the target is not empty), it uses the winner's copy and removes its own
    fmu = _fmu(tmp_path / "A.fmu", "one")
    real_rename = os.rename

    def rename(src, dst):
        winner = Path(dst)
        winner.mkdir()
        with zipfile.ZipFile(fmu) as z:
            z.extractall(winner)
        (winner / "winner").write_text("")
        real_rename(src, dst)                     # OSError: directory not empty

    monkeypatch.setattr(fmu_cache.os, "rename", rename)
    d, private = fmu_cache.unpack(fmu)
    assert not private and (Path(d) / "winner").exists()
    assert [p.name for p in root.iterdir()] == [Path(d).name]     # the loser's copy is gone
    fmu_cache.release(d, private)


def test_two_live_fmu_blocks_of_one_fmu_step_alike(tmp_path, monkeypatch):
    # the real PRSM FMU: two instances at once (the second on its private copy) give the same
    # outputs; the private copy goes when its instance ends, the cached one stays
    pytest.importorskip("fmpy")
    pytest.importorskip("pythonfmu")
    from test_fmu import built_fmus

    from system_models.fmu import FMUBlock

    root = tmp_path / "cache"
    monkeypatch.setattr(fmu_cache, "cache_root", lambda: root)
    path = built_fmus()["PRSM2"]
    a = FMUBlock(path, "a")
    b = FMUBlock(path, "b")
    try:
        assert not a._private_copy and b._private_copy
        da, db = a._unzipdir, b._unzipdir
        assert Path(da).parent == root and Path(db).parent != root
        for blk in (a, b):
            blk.set_inputs([2.0, 100.0])         # screw torque [N·m], load force [N]
            for k in range(5):
                blk.do_step(k * 1e-3, 1e-3)
        first = a.get_outputs()
        assert b.get_outputs() == first
    finally:
        a.terminate()
        b.terminate()
    assert Path(da).is_dir() and not Path(db).exists()
    # a later instance in this process loads the kept copy again (the library may still be
    # loaded from the first: pythonfmu's is never unloaded) and steps alike
    c = FMUBlock(path, "c")
    try:
        assert c._unzipdir == da and not c._private_copy
        c.set_inputs([2.0, 100.0])
        for k in range(5):
            c.do_step(k * 1e-3, 1e-3)
        assert c.get_outputs() == first
    finally:
        c.terminate()
