"""Every plain field of a scene file typed and ranged: each mistake one line, exit status 2.

The cases are the bad scene files found by the bad-input sweep (a traceback, a refusal that did
not name the field, or a value silently coerced or replaced); each must now be refused before
anything runs, in one line on stderr that names the field and its value, with exit status 2.
``pytest -s`` prints each case's verdict and the counts.
"""

from __future__ import annotations

import pytest

from system_models import cli

GOOD = ('description = "bad field"\nt_end = 1e-3\nstep = 1e-4\n'
        '[controller]\nmode = "speed"\nreference = 0.0\n')


def _with(top: str = "", tables: str = "") -> str:
    """GOOD with top-level lines ``top`` (before any table) and tables ``tables`` appended."""
    return top + GOOD + tables


#: name -> (scene text, words the one line must contain: the field and its value)
CASES = {
    "t0 a list": (_with("t0 = [1]\n"), ["t0", "[1]"]),
    "t0 a string": (_with('t0 = "x"\n'), ["t0", "'x'"]),
    "extrapolation a list": (_with("extrapolation = [1]\n"), ["extrapolation", "[1]"]),
    "extrapolation a string": (_with('extrapolation = "x"\n'), ["extrapolation", "'x'"]),
    "extrapolation a fraction (was coerced to 0)": (_with("extrapolation = 0.7\n"),
                                                    ["extrapolation", "0.7"]),
    "order a number": (_with("order = 5\n"), ["order", "5"]),
    "unknown [retry] field": (_with(tables="[retry]\nfoo = 1\n"), ["retry", "foo"]),
    "retry.max_halvings a fraction": (_with(tables="[retry]\nmax_halvings = 1.5\n"),
                                      ["retry.max_halvings", "1.5"]),
    "initial.screw_speed a string": (_with(tables='[initial]\nscrew_speed = "fast"\n'),
                                     ["initial.screw_speed", "'fast'"]),
    "initial.steady a number": (_with(tables="[initial]\nsteady = 1\n"), ["initial.steady", "1"]),
    "prsm.parameters not a table": (_with(tables="[prsm]\nparameters = 5\n"),
                                    ["prsm.parameters", "5"]),
    "stage index beyond the mechanism": (_with(tables='[prsm]\nparameters = { "stage[9].nut_mass" = 1 }\n'),
                                         ['"stage[9].nut_mass"', "stage 9", "PRSM2"]),
    "stage index not a number": (_with(tables='[prsm]\nparameters = { "stage[x].nut_mass" = 1 }\n'),
                                 ['"stage[x].nut_mass"']),
    "per-stage value a list": (_with(tables='[prsm]\nparameters = { "stage[1].screw_inertia" = [1, 2] }\n'),
                               ['"stage[1].screw_inertia"', "[1, 2]"]),
    "n_rollers a fraction (was coerced to 4)": (
        _with(tables='[prsm]\nparameters = { "stage[1].n_rollers" = 4.9 }\n'),
        ['"stage[1].n_rollers"', "4.9", "integer"]),
    "n_rollers a string (was coerced to 7)": (
        _with(tables='[prsm]\nparameters = { "stage[1].n_rollers" = "7" }\n'),
        ['"stage[1].n_rollers"', "'7'", "integer"]),
    "fidelity in parameters (was replaced by the scene's)": (
        _with(tables='[prsm]\nparameters = { fidelity = "bogus" }\n'),
        ['"fidelity"', "'bogus'", "fidelity field"]),
    "initial_screw_speed in parameters (was replaced by [initial])": (
        _with(tables='[prsm]\nparameters = { initial_screw_speed = 5.0 }\n'),
        ['"initial_screw_speed"', "5.0", "[initial] screw_speed"]),
    "unknown parameter": (_with(tables='[prsm]\nparameters = { mu_scew_roller = 0.1 }\n'),
                          ['"mu_scew_roller"', "mu_screw_roller"]),
    "mechanism not a string": (_with(tables="[prsm]\nmechanism = 2\n"), ["prsm.mechanism", "2"]),
}


def _lines(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.strip()]


def _run_bad(text: str, tmp_path, monkeypatch, capsys, extra=()) -> tuple[int, list[str], str]:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text(text)
    out = tmp_path / "out"
    status = cli.main(["run", "--scene", "./bad.toml", "--prsm", "python", "--out", str(out),
                       "--no-plots", *extra])
    cap = capsys.readouterr()
    assert not out.exists(), "the run started"
    return status, _lines(cap.err), cap.out


def test_every_bad_field_is_refused_in_one_line_naming_it(tmp_path, monkeypatch, capsys):
    verdicts = []
    for name, (text, words) in CASES.items():
        case_dir = tmp_path / f"case{len(verdicts)}"
        case_dir.mkdir()
        status, lines, out = _run_bad(text, case_dir, monkeypatch, capsys)
        ok = (status == 2 and len(lines) == 1 and "Traceback" not in lines[0]
              and all(w in lines[0] for w in words) and "scene bad:" not in out)
        verdicts.append((name, ok, lines))
    with capsys.disabled():
        for name, ok, lines in verdicts:
            print(f"  {'refused, named' if ok else 'WRONG'}: {name}: {lines[-1] if lines else ''}")
        print(f"  {len(verdicts)} bad scene fields tried, "
              f"{sum(ok for _, ok, _ in verdicts)} refused in one line naming the field, "
              "0 tracebacks allowed")
    assert all(ok for _, ok, _ in verdicts), [v for v in verdicts if not v[1]]
    assert len(verdicts) == 20


def test_a_good_scene_with_typed_parameters_still_runs(tmp_path, monkeypatch, capsys):
    # the same fields with values of the right type: nothing refused (the check is not a blanket)
    text = _with("t0 = 0\nextrapolation = 0\n",
                 '[retry]\nmax_halvings = 2\n[initial]\nscrew_speed = 0.0\nsteady = false\n'
                 '[prsm]\nmechanism = "PRSM2"\nparameters = { "stage[2].nut_mass" = 1.5, '
                 '"stage[1].n_rollers" = 5, tolerance = 1e-6, stepper = "default" }\n')
    monkeypatch.chdir(tmp_path)
    (tmp_path / "good.toml").write_text(text)
    status = cli.main(["run", "--scene", "./good.toml", "--prsm", "python", "--out",
                       str(tmp_path / "o"), "--no-plots"])
    assert status == 0, capsys.readouterr()


def test_prsm_native_with_a_pythonfmu_fmu_is_refused(tmp_path, monkeypatch, capsys):
    pytest.importorskip("fmpy")
    pytest.importorskip("pythonfmu")
    from test_fmu import built_fmus

    status, lines, _ = _run_bad(GOOD, tmp_path, monkeypatch, capsys,
                                ["--prsm", "native", "--fmu", str(built_fmus()["PRSM2"])])
    assert status == 2 and len(lines) == 1, lines
    assert "--fmu" in lines[0] and "not a native FMU" in lines[0] and "'PRSM2'" in lines[0]
