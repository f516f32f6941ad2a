"""Scene files: where a name resolves, and every bad scene refused before anything runs.

A scene *name* resolves only inside the scene folders (``./scenes``, the built-in ones); a file
is taken only when given as a path to a ``.toml`` file.  A name that climbs out of the scene
folders (``../../somewhere/evil``) is refused with one line naming ``--scene`` and the valid
scene names, and nothing runs.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from system_models import cli

#: a scene that runs in well under a second with the plain Python PRSM
TINY = ('description = "{what}"\nt_end = 1e-3\nstep = 1e-4\n'
        '[controller]\nmode = "speed"\nreference = 0.0\n')


def _stderr_lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


def test_a_scene_name_never_leaves_the_scene_folders(tmp_path, monkeypatch, capsys):
    # cwd/scenes/../../somewhere/evil.toml exists: a name joined onto the scene folder would
    # reach it (what the loader did before: the run went ahead with the evil scene)
    work = tmp_path / "a" / "b"
    (work / "scenes").mkdir(parents=True)
    (tmp_path / "a" / "somewhere").mkdir()
    (tmp_path / "a" / "somewhere" / "evil.toml").write_text(TINY.format(what="evil"))
    monkeypatch.chdir(work)
    out = tmp_path / "out"
    status = cli.main(["run", "--scene", "../../somewhere/evil", "--prsm", "python",
                       "--out", str(out), "--no-plots"])
    lines = _stderr_lines(capsys)
    assert status == 2
    assert len(lines) == 1 and "--scene" in lines[0] and "position_step" in lines[0], lines
    assert not out.exists()                      # nothing ran, nothing written


@pytest.mark.parametrize("how", ["relative", "absolute"])
def test_a_scene_given_as_a_path_to_a_toml_file_is_taken_as_that_file(tmp_path, monkeypatch,
                                                                       capsys, how):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "my.toml").write_text(TINY.format(what="mine"))
    arg = "./my.toml" if how == "relative" else str(tmp_path / "my.toml")
    status = cli.main(["run", "--scene", arg, "--prsm", "python", "--out", str(tmp_path / "o"),
                       "--no-plots"])
    assert status == 0, capsys.readouterr()
    assert "scene my: mine" in capsys.readouterr().out
