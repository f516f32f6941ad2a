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


# ---- every bad scene refused before anything runs --------------------------------------------
GOOD = ('description = "bad scene {cls}"\nt_end = 1e-3\nstep = 1e-4\n'
        'outputs = ["prsm.screw_speed"]\n'
        '[controller]\nmode = "speed"\nreference = 0.0\n')

#: class of mistake -> (scene text or a change to GOOD, extra CLI arguments, words the one line
#: must contain).  15 classes.
BAD = {
    "unknown top-level key": (GOOD + "t_edn = 2.0\n", [], ["t_edn", "allowed"]),
    "unknown key in a table": (GOOD + "[motor]\nresistanse = 0.5\n", [], ["resistanse", "resistance"]),
    "unknown output name": (GOOD.replace('"prsm.screw_speed"', '"prsm.screw_sped"'), [],
                            ["prsm.screw_sped", "valid", "prsm.screw_speed"]),
    "unknown check signal": (GOOD + '[[check]]\nkind = "range"\nsignal = "motor.curent"\nmax = 1.0\n',
                             [], ["motor.curent", "check 1", "motor.current"]),
    "unknown check field": (GOOD + '[[check]]\nkind = "range"\nsignal = "motor.current"\nmx = 1.0\n',
                            [], ["mx", "allowed"]),
    "unknown check kind": (GOOD + '[[check]]\nkind = "rnage"\n', [], ["rnage", "step_response"]),
    "wrong type (string for a number)": (GOOD + '[motor]\nresistance = "low"\n', [],
                                         ["resistance", "float"]),
    "wrong type (table expected)": (GOOD.replace("[controller]", "load = 3.0\n[controller]"), [],
                                    ["load", "table"]),
    "non-finite value (nan)": (GOOD + "[load]\nstiffness = nan\n", [], ["load.stiffness", "nan"]),
    "non-finite value (inf)": (GOOD.replace("t_end = 1e-3", "t_end = inf"), [], ["t_end"]),
    "run too long for the bound": (GOOD.replace("t_end = 1e-3", "t_end = 1000.0"), [],
                                   ["steps", "bound"]),
    "not a whole number of steps": (GOOD.replace("t_end = 1e-3", "t_end = 1.05e-3"), [],
                                    ["t_end", "whole"]),
    "TOML syntax error": (GOOD + "[motor\n", [], ["scene file"]),
    "unwritable output directory": (GOOD, ["--out", "/proc/prsm_out"], ["--out"]),
    "FMU of another stage count": (GOOD, ["--prsm", "fmu", "--fmu", "PRSM1"], ["--fmu", "1-stage",
                                                                               "PRSM2"]),
}


@pytest.mark.parametrize("cls", list(BAD))
def test_every_bad_scene_is_refused_in_one_line_naming_the_field_and_nothing_runs(cls, tmp_path,
                                                                                   monkeypatch,
                                                                                   capsys):
    text, extra, words = BAD[cls]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text(text.format(cls=cls) if "{cls}" in text else text)
    if "--fmu" in extra:
        pytest.importorskip("fmpy")
        pytest.importorskip("pythonfmu")
        from test_fmu import built_fmus

        extra = [built_fmus()[a] if a == "PRSM1" else a for a in extra]
        extra = [str(a) for a in extra]
    out = tmp_path / "out"
    argv = ["run", "--scene", "./bad.toml", "--prsm", "python", "--out", str(out)] + extra
    status = cli.main(argv)
    captured = capsys.readouterr()
    lines = _stderr_lines_of(captured.err)
    assert status == 2, (cls, captured.out, captured.err)
    assert len(lines) == 1, lines                          # one line, no traceback
    assert "Traceback" not in captured.err
    for w in words:
        assert w in lines[0], (cls, w, lines[0])
    assert "scene bad:" not in captured.out                 # the run never started
    assert not out.exists()


def _stderr_lines_of(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.strip()]


def test_there_are_fifteen_bad_scene_classes():
    assert len(BAD) == 15
