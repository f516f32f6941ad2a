"""Parameter studies (issue 7): the papers' trends read from the sweep's table, Dask execution
with 1 and 2 workers, failed points, reruns, the FMU master and the study format.

Expected values: the papers' statements (Li et al. (2021) §3.2–3.3, the multi-stage assembly article's table) as directions
of change, the steady states found independently by root finding (:func:`steady_state`), the
inertial torque J·α of a ramp from the kinetic energy, and the identity of tables.  The FMUs
are built once in a child process (``python -m fmu_build``, see tests/test_fmu.py for why);
one local Dask cluster of two worker processes serves the module.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dask.distributed")
pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from prsm_fmu import presets, steady_state
from prsm_fmu.sweep import (
    StudyError,
    ensure_fmus,
    load_series,
    load_study,
    read_table,
    run_study,
)
from text_numbers import number_after, same_table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "studies"


# ---------------------------------------------------------------------------------------------
# fixtures: the FMUs and one cluster for the module
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory) -> str:
    """PRSM1 and PRSM2 of both kinds: the native FMUs the FMU backend runs on by default and
    the Python FMUs (``fmu="python"``)."""
    d = tmp_path_factory.mktemp("fmus")
    for kind, name in (("python", "PRSM{}.fmu"), ("native", "PRSM{}-native.fmu")):
        paths = ensure_fmus([1, 2], str(d), kind=kind)
        assert paths == {n: os.path.join(str(d), name.format(n)) for n in (1, 2)}
        assert all(os.path.isfile(p) for p in paths.values())
    return str(d)


@pytest.fixture(scope="module")
def client():
    """A client of the local cluster the sweep starts (prsm_fmu.sweep.execute.local_cluster)."""
    from dask.distributed import Client

    from prsm_fmu.sweep.execute import local_cluster

    cluster = local_cluster(2)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


def _assert_same_results(a, b) -> None:
    """Two runs of a study gave the same table (every number equal as a double) and the same
    series bit for bit."""
    assert same_table(Path(a.table_path).read_text(encoding="utf-8"),
                      Path(b.table_path).read_text(encoding="utf-8"))
    for r in a.rows:
        sa, sb = load_series(a.out_dir, r["id"]), load_series(b.out_dir, r["id"])
        assert sa.keys() == sb.keys()
        for k in sa:
            np.testing.assert_array_equal(sa[k], sb[k])


def _by(rows, **fixed):
    """The rows whose swept values equal ``fixed``."""
    return [r for r in rows if all(r[k] == v for k, v in fixed.items())]


def _one(rows, **fixed):
    found = _by(rows, **fixed)
    assert len(found) == 1, fixed
    return found[0]


@pytest.fixture(scope="module")
def friction(tmp_path_factory, fmu_dir):
    """Li et al. (2021) §3.2 on the FMU, on the default local cluster that run_study starts itself,
    with 2 workers and with 1."""
    study = load_study(STUDIES / "li2021_friction.toml")
    two = run_study(study, str(tmp_path_factory.mktemp("friction2")), workers=2,
                    fmu_dir=fmu_dir, progress=None)
    one = run_study(study, str(tmp_path_factory.mktemp("friction1")), workers=1,
                    fmu_dir=fmu_dir, progress=None, figures=False)
    return two, one


# ---------------------------------------------------------------------------------------------
# Li et al. (2021) §3.2
# ---------------------------------------------------------------------------------------------
def test_li2021_friction_trends_from_the_table(friction):
    res = friction[0]
    rows = res.rows
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    for mu_ss in (0.2, 0.3):
        lo, hi = _one(rows, mu_screw_roller=0.1, mu_spline=mu_ss), \
            _one(rows, mu_screw_roller=0.2, mu_spline=mu_ss)
        # efficiency falls with µ_SR (by far more than µ_SS changes it)
        assert hi["efficiency@end"] < lo["efficiency@end"] - 0.1
        # contact forces rise with µ_SR, and so does their change from t = 0 to 0.75 ms
        for k in (1, 2):
            f = f"stage[{k}].contact_force"
            assert hi[f + "@end"] > lo[f + "@end"]
            assert hi[f + "@0.00075"] - hi[f + "@start"] > lo[f + "@0.00075"] - lo[f + "@start"]
            # the carriers are driven by friction: larger µ_SR, steeper ζ, earlier settling
            z = f"stage[{k}].carrier_speed_ratio@settle"
            assert hi[z] < lo[z]
        assert hi["stage[2].spline_friction@end"] > lo["stage[2].spline_friction@end"]
        assert hi["stage[2].spline_friction@start"] > lo["stage[2].spline_friction@start"]
    for mu_sr in (0.1, 0.2):
        lo, hi = _one(rows, mu_screw_roller=mu_sr, mu_spline=0.2), \
            _one(rows, mu_screw_roller=mu_sr, mu_spline=0.3)
        # µ_SS: slight effect on η, F_Srz1 grows slightly, F_Srz2 independent, f_S2 grows
        assert 0.0 < lo["efficiency@end"] - hi["efficiency@end"] < 0.01
        assert 0.0 < hi["stage[1].contact_force@end"] - lo["stage[1].contact_force@end"] < 0.03 * \
            lo["stage[1].contact_force@end"]
        for when in ("@end", "@0.00075", "@start"):
            assert hi["stage[2].contact_force" + when] == pytest.approx(
                lo["stage[2].contact_force" + when], abs=1e-6)
        assert hi["stage[2].spline_friction@end"] > lo["stage[2].spline_friction@end"]
    # the steady carrier ratios do not depend on friction, and ζ_PS2 > ζ_PS1
    for k in (1, 2):
        z = [r[f"stage[{k}].carrier_speed_ratio@end"] for r in rows]
        assert max(z) - min(z) < 1e-9
    assert all(r["stage[2].carrier_speed_ratio@end"] > r["stage[1].carrier_speed_ratio@end"]
               for r in rows)
    # the study's own claims (the same statements, evaluated by the sweep) all agree
    assert [t.verdict for t in res.trends] == ["agrees"] * len(res.trends)
    # the speed was held: the FMU master tracked the 100 rad/s step
    assert max(r["speed_error@max"] for r in rows) < 1e-9


def test_li2021_friction_end_values_equal_the_independent_steady_state(friction):
    """At t = 1 ms the FMU run has settled onto the steady state that root finding gives."""
    base = presets.load("li2021_two_stage")
    for r in friction[0].rows:
        ss = steady_state(base.with_changes(mu_screw_roller=r["mu_screw_roller"],
                                            mu_spline=r["mu_spline"]), 100.0, 5000.0)
        for name in ("efficiency", "stage[1].contact_force", "stage[2].contact_force",
                     "stage[2].spline_friction", "stage[1].carrier_speed_ratio",
                     "stage[2].carrier_speed_ratio"):
            assert r[name + "@end"] == pytest.approx(ss[name], rel=1e-6), name
        assert r["energy_residual"] < 1e-6


def test_one_and_two_workers_give_identical_tables(friction):
    _assert_same_results(*friction)


def test_the_fmu_backend_runs_on_the_native_fmu_and_the_python_fmu_gives_the_same_table(
        friction, fmu_dir, tmp_path):
    """By default the FMU backend runs the native FMU (Zig's compiler is in the test extra);
    the Python FMU runs the same engine behind pythonfmu, so the same study on it gives the
    same table, every number equal as a double, and the same series."""
    two = friction[0]
    assert two.fmu == "native"
    assert "the native FMU" in (Path(two.out_dir) / "report.md").read_text(encoding="utf-8")
    study = load_study(STUDIES / "li2021_friction.toml")
    py = run_study(study, str(tmp_path / "py"), executor="loop", fmu_dir=fmu_dir,
                   progress=None, figures=False, fmu="python")
    assert py.fmu == "python" and len(py.rows) == 4
    _assert_same_results(two, py)


def test_without_zig_the_fmu_backend_says_so_and_runs_the_python_fmu(tmp_path, fmu_dir,
                                                                      monkeypatch):
    import io

    import fmu_build.platforms

    monkeypatch.setattr(fmu_build.platforms, "zig_available", lambda: False)
    study = load_study(_write_study(tmp_path / "s.toml", "mu_spline = [0.2]"))
    log = io.StringIO()
    res = run_study(study, str(tmp_path / "out"), executor="loop", fmu_dir=fmu_dir,
                    progress=log, figures=False)
    assert res.fmu == "python" and [r["status"] for r in res.rows] == ["ok"]
    notes = [line for line in log.getvalue().splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "pip install ziglang" in notes[0] and "Python FMU" in notes[0]
    with pytest.raises(ValueError, match=r"fmu = 'c' is not allowed: must be one of native, "
                                         r"python"):
        run_study(study, str(tmp_path / "out2"), executor="loop", fmu_dir=fmu_dir,
                  progress=None, figures=False, fmu="c")
    assert not (tmp_path / "out2").exists()         # refused before anything was written


def test_each_worker_loads_the_fmu_once_and_reuses_it(friction):
    for res in friction:
        assert len(res.results) == 4
        for p in res.results:
            assert p.fmu_instances == 1          # one instance per worker process, ever
        workers = {p.worker for p in res.results}
        runs_per_worker = {w: max(p.fmu_points for p in res.results if p.worker == w)
                           for w in workers}
        assert sum(runs_per_worker.values()) == 4
    assert len({p.worker for p in friction[1].results}) == 1


def test_figures_and_report_are_written(friction):
    res = friction[0]
    for name in ("time.png", "steady.png"):
        path = Path(res.out_dir) / name
        assert path.is_file() and path.stat().st_size > 10_000
    text = (Path(res.out_dir) / "report.md").read_text(encoding="utf-8")
    assert "the efficiency decreases as µ_SR increases" in text and "agrees" in text


# ---------------------------------------------------------------------------------------------
# Li et al. (2021) §3.3 and the multi-stage assembly article
# ---------------------------------------------------------------------------------------------
def test_li2021_pitch_trends_from_the_table(tmp_path, client, fmu_dir):
    res = run_study(load_study(STUDIES / "li2021_pitches.toml"), str(tmp_path), client=client,
                    fmu_dir=fmu_dir, progress=None, figures=False)
    rows = sorted(res.rows, key=lambda r: r["stage[1].pitch"])
    assert [r["stage[1].pitch"] for r in rows] == [0.001, 0.0015, 0.002, 0.0025, 0.003]
    assert all(r["stage[1].pitch"] + r["stage[2].pitch"] == pytest.approx(0.004) for r in rows)

    def col(name):
        return np.array([r[name] for r in rows])

    d = np.diff
    assert np.all(d(col("stage[1].contact_force@end")) < 0)       # F_Srz1 falls with p1
    eta = col("efficiency@end")
    assert eta.max() - eta.min() < 0.01                           # little influence on η
    assert np.all(d(col("stage[2].spline_friction@end")) < 0)     # f_S2 rises with p2
    assert np.all(d(col("stage[2].contact_force@end")) < 0)       # F_Srz2 rises with p2 ...
    f2 = col("stage[2].contact_force@end")
    assert f2.max() - f2.min() < 0.01 * f2.mean()                 # ... slightly
    assert np.all(d(col("stage[1].carrier_speed_ratio@end")) < 0)   # small p1: higher ζ_PS1
    assert np.all(d(col("stage[1].carrier_speed_ratio@settle")) > 0)  # ... settling sooner
    assert np.all(d(col("stage[2].carrier_speed_ratio@end")) > 0)   # small p2: higher ζ_PS2
    assert np.all(d(col("stage[2].carrier_speed_ratio@settle")) < 0)  # ... settling sooner
    assert all(t.agrees for t in res.trends)


def test_assembly_friction_trends_from_the_table(tmp_path, client, fmu_dir):
    res = run_study(load_study(STUDIES / "assembly_friction.toml"), str(tmp_path), client=client,
                    fmu_dir=fmu_dir, progress=None, figures=False)
    rows = res.rows
    base = _one(rows, mu_spline=0.1, mu_nut_screw=0.005)
    high_ss = _one(rows, mu_spline=0.2, mu_nut_screw=0.005)
    high_ns = _one(rows, mu_spline=0.1, mu_nut_screw=0.105)
    # the paper's table: 0.872, 0.870 (the µ_NS row is not reproducible, docs/sweeps.md)
    assert base["efficiency@end"] == pytest.approx(0.872, abs=0.01)
    assert high_ss["efficiency@end"] == pytest.approx(0.870, abs=0.01)
    # µ_SS lowers η slightly, µ_NS much more
    d_ss = base["efficiency@end"] - high_ss["efficiency@end"]
    d_ns = base["efficiency@end"] - high_ns["efficiency@end"]
    assert 0.0 < d_ss < 0.01 and d_ns > 5 * d_ss
    # the carrier ratios do not move; ζ_PS2 > ζ_PS1; F_Srz2 unaffected by µ_NS
    for k in (1, 2):
        z = [r[f"stage[{k}].carrier_speed_ratio@end"] for r in rows]
        assert max(z) - min(z) < 1e-9
    for r in rows:
        assert r["stage[2].carrier_speed_ratio@end"] > r["stage[1].carrier_speed_ratio@end"]
        assert r["stage[1].contact_force@end"] > r["stage[2].contact_force@end"]
        # start-up: η lowest with the carriers at rest, carrier 2 settles after carrier 1
        assert r["efficiency@start"] < r["efficiency@end"] - 0.1
        assert r["stage[2].carrier_speed_ratio@settle"] > r["stage[1].carrier_speed_ratio@settle"]
    assert high_ns["stage[2].contact_force@end"] == pytest.approx(
        base["stage[2].contact_force@end"], abs=1e-6)
    assert all(t.agrees for t in res.trends)


# ---------------------------------------------------------------------------------------------
# failures, reruns, backends
# ---------------------------------------------------------------------------------------------
def _write_study(path: Path, grid: str, backend: str = "fmu", extra: str = "") -> Path:
    path.write_text(textwrap.dedent(f"""
        [study]
        name = "small"
        preset = "li2021_two_stage"
        backend = "{backend}"
        [scenario]
        fidelity = "dynamic"
        screw_speed = 100.0
        load_force = 5000.0
        t_end = 2e-4
        output_interval = 2e-6
        [grid]
        {grid}
        """) + extra, encoding="utf-8")
    return path


def test_a_failing_point_is_recorded_and_the_others_complete(tmp_path, client, fmu_dir):
    study = load_study(_write_study(tmp_path / "s.toml", "mu_screw_roller = [0.1, 1.5, 0.2]"))
    out = str(tmp_path / "out")
    res = run_study(study, out, client=client, fmu_dir=fmu_dir, progress=None)
    status = {r["mu_screw_roller"]: r["status"] for r in res.rows}
    assert status == {0.1: "ok", 1.5: "error", 0.2: "ok"}
    bad = _one(res.rows, mu_screw_roller=1.5)
    assert "ValueError" in bad["error"] and number_after(bad["error"], "mu_screw_roller = ") == 1.5
    assert "[0, 1)" in bad["error"]
    assert math.isnan(bad["efficiency@end"])
    ok = [r for r in res.rows if r["status"] == "ok"]
    assert all(0.5 < r["efficiency@end"] < 0.9 for r in ok)
    _, text_rows = read_table(res.table_path)
    assert [r["status"] for r in text_rows] == ["ok", "error", "ok"]
    assert number_after((Path(out) / "report.md").read_text(encoding="utf-8"),
                        "mu_screw_roller = ") == 1.5

    # a rerun skips the two points done and tries the failed one again
    again = run_study(study, out, client=client, fmu_dir=fmu_dir, progress=None, figures=False)
    assert again.skipped == 2
    assert [p.index for p in again.results] == [1]
    assert same_table(Path(again.table_path).read_text(encoding="utf-8"),
                      Path(res.table_path).read_text(encoding="utf-8"))
    # the same rerun in a plain loop: nothing pending but the failed point
    loop = run_study(study, out, executor="loop", progress=None, figures=False)
    assert loop.skipped == 2 and len(loop.results) == 1


def test_short_points_go_in_chunks_and_give_the_loops_table(tmp_path, client):
    """64 points of 100 steps on the model backend (a few ms each): the Dask run sends them in
    chunks of several points (fewer tasks than points), the workers save the series, and the
    table and series equal the plain loop's (each point once)."""
    mu_sr = [round(0.05 + 0.05 * i, 4) for i in range(8)]        # 0.05 ... 0.40
    mu_ss = [round(0.1 + 0.02 * j, 4) for j in range(8)]         # 0.10 ... 0.24
    study = load_study(_write_study(tmp_path / "s.toml", f"mu_screw_roller = {mu_sr}\n"
                                    f"mu_spline = {mu_ss}", backend="model"))
    loop = run_study(study, str(tmp_path / "loop"), executor="loop", progress=None,
                     figures=False)
    dask = run_study(study, str(tmp_path / "dask"), client=client, progress=None, figures=False)
    assert len(dask.rows) == 64 and not dask.failed
    print(f"64 points in {dask.dask_tasks} Dask tasks")
    assert 1 <= dask.dask_tasks < 64
    assert loop.dask_tasks == 0
    assert sorted(p.index for p in dask.results) == list(range(64))      # each point once
    _assert_same_results(loop, dask)


def test_series_sent_back_by_the_workers_equal_the_loops(tmp_path, client):
    """Workers that do not share this file system (ship_fmus) send each point's series back in
    the chunk's pickled results (points.pack_chunk) and this process saves them: table and
    series equal the plain loop's, arrays bit for bit, a failed point included."""
    study = load_study(_write_study(tmp_path / "s.toml", "mu_screw_roller = [0.1, 1.5, 0.2]\n"
                                    "mu_spline = [0.1, 0.2, 0.3]", backend="model"))
    loop = run_study(study, str(tmp_path / "loop"), executor="loop", progress=None,
                     figures=False)
    sent = run_study(study, str(tmp_path / "sent"), client=client, ship_fmus=True,
                     progress=None, figures=False)
    assert [r["status"] for r in sent.rows].count("error") == 3        # µ_SR 1.5, 3 times
    assert same_table(Path(loop.table_path).read_text(encoding="utf-8"),
                      Path(sent.table_path).read_text(encoding="utf-8"))
    ok = [r for r in loop.rows if r["status"] == "ok"]
    assert len(ok) == 6
    for r in ok:
        a, b = load_series(loop.out_dir, r["id"]), load_series(sent.out_dir, r["id"])
        assert a.keys() == b.keys()
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])


def test_the_dashboard_serves_the_studys_progress(tmp_path, client):
    """The local cluster's dashboard server has the page /prsm-progress; after a study of three
    points of which one fails it says so, and the progress stream named the page."""
    import io
    import urllib.request

    from prsm_fmu.sweep.dashboard import page_url

    study = load_study(_write_study(tmp_path / "s.toml", "mu_screw_roller = [0.1, 1.5, 0.2]",
                                    backend="model"))
    stream = io.StringIO()
    res = run_study(study, str(tmp_path / "out"), client=client, progress=stream,
                    figures=False)
    assert [r["status"] for r in res.rows] == ["ok", "error", "ok"]
    url = page_url(client.dashboard_link)
    assert url.startswith("http://127.0.0.1:") and url.endswith("/prsm-progress")
    assert f"progress page: {url}" in stream.getvalue()
    with urllib.request.urlopen(url, timeout=10) as reply:
        page = reply.read().decode("utf-8")
    assert "3 of 3 points done, 1 failed" in page
    assert "<progress value='3' max='3'>" in page


def _listening_addresses() -> list[tuple[int, str, int]]:
    """(pid, ip, port) of every listening TCP socket of this process and its children."""
    import psutil

    me = psutil.Process()
    out = []
    for proc in [me] + me.children(recursive=True):
        try:
            conns = proc.net_connections(kind="inet")
        except psutil.NoSuchProcess:
            continue
        out += [(proc.pid, c.laddr.ip, c.laddr.port) for c in conns
                if c.status == psutil.CONN_LISTEN]
    return out


def test_the_local_cluster_listens_on_loopback_only(client):
    """The cluster a local sweep starts: scheduler, 2 workers, their nannies and the
    scheduler's HTTP (dashboard) server all listen, and none on an address other machines can
    reach: every listening socket is on 127.0.0.1 or ::1."""
    from urllib.parse import urlparse

    socks = _listening_addresses()
    cluster = client.cluster
    ports = {port for _, _, port in socks}
    # the scheduler's comm port and its dashboard port are among them
    assert urlparse(cluster.scheduler_address).port in ports
    assert urlparse(cluster.dashboard_link).port in ports
    # scheduler: comm + HTTP; each of the 2 workers: worker + nanny (at least)
    assert len(socks) >= 2 + 2 * 2, socks
    exposed = [s for s in socks if s[1] not in ("127.0.0.1", "::1")]
    assert not exposed, f"listening beyond this machine: {exposed}"


def test_the_local_clusters_workers_keep_glibcs_malloc_defaults(monkeypatch):
    """Dask's nanny gives its workers MALLOC_TRIM_THRESHOLD_=65536 (freed memory handed back
    to the system at once, glibc's mmap threshold fixed): every point then takes its arrays
    from the system again (page faults, more CPU a point, docs/sweeps.md).  A study's local
    cluster leaves it out; the other variables Dask sets are kept."""
    import dask
    from dask.distributed import Client

    from prsm_fmu.sweep.execute import local_cluster

    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    dask_env = dask.config.get("distributed.nanny.pre-spawn-environ")
    assert "MALLOC_TRIM_THRESHOLD_" in dask_env          # what the test is about is there
    cluster = local_cluster(1)
    try:
        with Client(cluster) as c:
            seen = c.run(lambda: {k: os.environ.get(k) for k in
                                  ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS")})
    finally:
        cluster.close()
    (env,) = seen.values()
    assert env["MALLOC_TRIM_THRESHOLD_"] is None, env
    assert env["OMP_NUM_THREADS"] == str(dask_env["OMP_NUM_THREADS"])


def test_a_point_the_fmu_refuses_records_the_fmus_own_reason(fmu_dir):
    """A refused step (a non-finite load on the FMU's input) and a failed initialization (a
    friction coefficient out of the FMU's range, bypassing the caller's validation): the point's
    error carries what the FMU logged, which names the input or parameter; the runner itself
    knows neither."""
    from prsm_fmu.sweep.fmu_runner import FmuPointError, FmuRunner

    runner = FmuRunner(os.path.join(fmu_dir, "PRSM2.fmu"))
    p = presets.load("li2021_two_stage")
    with pytest.raises(FmuPointError) as refused:
        runner.run(p, "quasi-static", lambda t: 100.0, 0.0, math.nan, 1e-4, 1e-5)
    # the runner's own words name the torque it tried; the FMU's name the load input
    assert "load_force" in str(refused.value) and "finite" in str(refused.value)
    bad = p.with_changes(mu_spline=1.5)          # the FMU's range is [0, 1)
    with pytest.raises(FmuPointError) as failed:
        runner.run(bad, "quasi-static", lambda t: 100.0, 0.0, 5000.0, 1e-4, 1e-5)
    assert number_after(str(failed.value), "mu_spline = ") == 1.5
    runner.close()


def test_the_fmu_runner_recovers_after_a_refused_step(fmu_dir):
    """An FMU that refuses a step (non-finite load) is freed; the next point gets a new one."""
    from prsm_fmu.sweep.fmu_runner import FmuPointError, FmuRunner

    runner = FmuRunner(os.path.join(fmu_dir, "PRSM2.fmu"))
    p = presets.load("li2021_two_stage")
    with pytest.raises(FmuPointError, match="refused|failed"):
        runner.run(p, "quasi-static", lambda t: 100.0, 0.0, math.nan, 1e-4, 1e-5)
    assert runner.fmu is None
    res = runner.run(p, "quasi-static", lambda t: 100.0, 0.0, 5000.0, 1e-4, 1e-5)
    ss = steady_state(p, 100.0, 5000.0)
    assert res["efficiency"][-1] == pytest.approx(ss["efficiency"], rel=1e-9)
    assert runner.instances_made == 2
    # a reset between points: a second point on the same instance gives the same numbers
    again = runner.run(p, "quasi-static", lambda t: 100.0, 0.0, 5000.0, 1e-4, 1e-5)
    assert runner.instances_made == 2
    np.testing.assert_array_equal(again["efficiency"], res["efficiency"])
    runner.close()


def test_a_tracked_ramp_carries_the_inertial_torque(fmu_dir):
    """The friction-torque article's ramp on PRSM1: the speed meets the reference at every communication point,
    and the motor torque during the ramp exceeds the torque after it by J_eq·α, with J_eq from
    the kinetic energy (2 T / ω²) at the end."""
    from prsm_fmu.sweep.fmu_runner import FmuRunner

    runner = FmuRunner(os.path.join(fmu_dir, "PRSM1.fmu"))
    p = presets.load("friction_single_stage")
    ta, w, h = 0.01, 1.0, 1e-4
    res = runner.run(p, "dynamic", lambda t: w * min(t / ta, 1.0), w / ta, 1000.0, 0.015, h)
    runner.close()
    t = res["time"]
    assert np.max(np.abs(res["screw_speed"] - res["speed_reference"])) < 1e-9
    torque = res["stage[1].driven_torque"]
    during = torque[(t > 0.5 * ta) & (t < ta - h / 2)]
    after = torque[t > ta + 20 * h]
    j_eq = 2.0 * res["kinetic_energy"][-1] / w ** 2
    assert np.ptp(after) < 1e-6 * after.mean()
    assert during.mean() - after.mean() == pytest.approx(j_eq * w / ta, rel=0.02)


def test_model_backend_agrees_with_the_fmu_at_steady_state(tmp_path, friction):
    study = load_study(STUDIES / "li2021_friction.toml", backend="model")
    res = run_study(study, str(tmp_path), executor="loop", progress=None, figures=False)
    fmu_rows = {(r["mu_screw_roller"], r["mu_spline"]): r for r in friction[0].rows}
    for r in res.rows:
        f = fmu_rows[(r["mu_screw_roller"], r["mu_spline"])]
        for name in ("efficiency@end", "stage[1].contact_force@end", "stage[2].spline_friction@end",
                     "efficiency@start", "stage[1].contact_force@start"):
            assert r[name] == pytest.approx(f[name], rel=1e-6), name
        assert r["speed_error@max"] == 0.0
    # the ids differ (another backend), so the FMU's results were not reused
    assert {r["id"] for r in res.rows}.isdisjoint(fmu_rows[k]["id"] for k in fmu_rows)


def test_cli_sweep_runs_a_study_and_reports(tmp_path, capsys):
    from prsm_fmu.cli import main

    path = _write_study(tmp_path / "s.toml", "mu_spline = [0.2, 0.3]", backend="model", extra="""
[[trend]]
statement = "f_S2 grows with µ_SS"
metric = "stage[2].spline_friction@end"
vs = "mu_spline"
expect = "rises"
""")
    out = tmp_path / "out"
    code = main(["sweep", str(path), "--out", str(out), "--no-dask", "--quiet"])
    text = capsys.readouterr().out
    assert code == 0
    assert "2 of 2 points ok" in text and "agrees" in text and "f_S2 grows with µ_SS" in text
    # the study's own folder under --out, named after it (the study file says name = "small")
    assert (out / "small" / "results.csv").is_file() and (out / "small" / "steady.png").is_file()
    assert main(["sweep", str(path), "--out", str(out), "--workers", "2", "--no-dask"]) == 2
    assert main(["sweep", str(tmp_path / "missing.toml")]) == 2


def test_a_second_study_under_the_same_out_leaves_the_first_ones_results(tmp_path, capsys):
    """Two studies run with the same --out: each gets its own folder, the first one's table
    is byte for byte what it was; run_study into the other's folder is refused, untouched."""
    from prsm_fmu.cli import main

    first = _write_study(tmp_path / "a.toml", "mu_spline = [0.2]", backend="model")
    second = _write_study(tmp_path / "b.toml", "mu_spline = [0.3]", backend="model")
    second.write_text(second.read_text(encoding="utf-8").replace('name = "small"',
                                                                 'name = "other"'),
                      encoding="utf-8")
    out = tmp_path / "out"
    assert main(["sweep", str(first), "--out", str(out), "--no-dask", "--quiet",
                 "--no-figures"]) == 0
    table = (out / "small" / "results.csv").read_bytes()
    assert main(["sweep", str(second), "--out", str(out), "--no-dask", "--quiet",
                 "--no-figures"]) == 0
    capsys.readouterr()
    assert (out / "small" / "results.csv").read_bytes() == table
    assert (out / "other" / "results.csv").is_file()
    with pytest.raises(ValueError, match="holds the results of study 'small'"):
        run_study(load_study(second), str(out / "small"), executor="loop", progress=None,
                  figures=False)
    assert (out / "small" / "results.csv").read_bytes() == table


# ---------------------------------------------------------------------------------------------
# the study format
# ---------------------------------------------------------------------------------------------
def test_shipped_studies_load_and_cover_the_seeds():
    names = {p.stem for p in STUDIES.glob("*.toml")}
    assert {"li2021_friction", "li2021_pitches", "assembly_friction", "friction_load",
            "friction_accel_time"} <= names
    s = load_study(STUDIES / "li2021_friction.toml")
    assert [p.values for p in s.points()] == [
        {"mu_screw_roller": 0.1, "mu_spline": 0.2}, {"mu_screw_roller": 0.1, "mu_spline": 0.3},
        {"mu_screw_roller": 0.2, "mu_spline": 0.2}, {"mu_screw_roller": 0.2, "mu_spline": 0.3}]
    # the friction-torque article: its own µ_1 and the one its load table's intercept needs, × its table's axis
    s = load_study(STUDIES / "friction_accel_time.toml")
    assert [(p.values["mu_viscous"], p.values["accel_time"]) for p in s.points()] == [
        (mu1, ta) for mu1 in (0.001, 580.0) for ta in (0.01, 0.03, 0.06, 0.09)]
    s = load_study(STUDIES / "friction_load.toml")
    assert [(p.values["mu_viscous"], p.values["load_force"]) for p in s.points()] == [
        (mu1, f) for mu1 in (0.001, 580.0) for f in (500.0, 1000.0, 3000.0, 5000.0)]
    assert s.stage_counts() == {1}


@pytest.mark.parametrize("body, words", [
    ('[grid]\nmu_screw = [0.1]', ["unknown parameter", "mu_screw"]),
    ('[[zip]]\nmu_spline = [0.1, 0.2]\nmu_nut_screw = [0.1]', ["same length"]),
    ('[grid]\nmu_spline = "a"', ["mu_spline", "non-empty list"]),
    ('[grid]\n"stage[1].screw_starts" = [4.5]', ["stage[1].screw_starts", "integer"]),
    ('[[trend]]\nstatement = "x"\nmetric = "efficiency@end"\nvs = "load_force"\nexpect = "up"',
     ["expect", "rises"]),
])
def test_malformed_studies_are_refused_naming_the_key(tmp_path, body, words):
    path = tmp_path / "bad.toml"
    path.write_text('[study]\nname = "bad"\npreset = "li2021_two_stage"\n[scenario]\n'
                    't_end = 1e-3\noutput_interval = 1e-5\n' + body + "\n", encoding="utf-8")
    with pytest.raises(StudyError) as exc:
        load_study(path)
    for w in words:
        assert w in str(exc.value)


def test_random_sampling_is_reproducible_and_within_its_ranges(tmp_path):
    path = tmp_path / "r.toml"
    path.write_text(textwrap.dedent("""
        [study]
        name = "r"
        preset = "li2021_two_stage"
        [scenario]
        t_end = 1e-4
        output_interval = 1e-5
        [grid]
        n_stages = [1, 2]
        [random]
        n = 5
        seed = 3
        uniform = { mu_screw_roller = [0.05, 0.2] }
        loguniform = { load_force = [100.0, 10000.0] }
        choice = { fidelity = ["quasi-static", "dynamic"] }
        """), encoding="utf-8")
    a, b = load_study(path).points(), load_study(path).points()
    assert [p.values for p in a] == [p.values for p in b] and len(a) == 10
    assert [p.id for p in a] == [p.id for p in b] and len({p.id for p in a}) == 10
    for p in a:
        assert 0.05 <= p.values["mu_screw_roller"] <= 0.2
        assert 100.0 <= p.values["load_force"] <= 10000.0
        assert p.values["fidelity"] in ("quasi-static", "dynamic")
    assert load_study(path).stage_counts() == {1, 2}


def test_pitch_and_stage_count_overrides():
    from prsm_fmu.sweep import apply_overrides

    p = presets.load("li2021_two_stage")
    q = apply_overrides(p, {"stage[1].pitch": 0.001, "stage[2].screw_starts": 4,
                            "stage[2].pitch": 0.003, "mu_spline": 0.3})
    assert q.stages[0].screw_lead == pytest.approx(0.005)
    assert q.stages[1].screw_lead == pytest.approx(0.012)       # 4 starts × 3 mm
    assert q.mu_spline == 0.3
    assert apply_overrides(p, {"n_stages": 1}).n_stages == 1
    with pytest.raises(ValueError, match="n_stages"):
        apply_overrides(p, {"n_stages": 3})
    with pytest.raises(ValueError, match="stage 3"):
        apply_overrides(p, {"stage[3].screw_radius": 0.01})


def test_sweep_package_imports_without_dask():
    code = ("import sys; sys.modules['dask'] = None; sys.modules['distributed'] = None; "
            "import prsm_fmu.sweep, prsm_fmu.report; print('ok')")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=False)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_fmus_can_be_sent_to_workers_as_bytes(tmp_path, client, fmu_dir):
    """For a cluster without this file system: the FMU travels as bytes (scattered once)."""
    import hashlib

    from prsm_fmu.sweep.points import FmuFile, _fmu_path

    data = Path(fmu_dir, "PRSM2.fmu").read_bytes()
    sha = hashlib.sha256(data).hexdigest()
    path = _fmu_path(FmuFile(sha, str(tmp_path / "elsewhere" / "PRSM2.fmu"), data))
    assert Path(path).read_bytes() == data
    with pytest.raises(ValueError, match="SHA-256"):
        _fmu_path(FmuFile("0" * 64, "/nowhere/PRSM2.fmu", data))
    study = load_study(_write_study(tmp_path / "s.toml", "mu_spline = [0.2, 0.3]"))
    res = run_study(study, str(tmp_path / "out"), client=client, fmu_dir=fmu_dir,
                    ship_fmus=True, progress=None, figures=False)
    assert [r["status"] for r in res.rows] == ["ok", "ok"]


def test_a_repeated_point_is_refused(tmp_path):
    path = _write_study(tmp_path / "s.toml", "mu_spline = [0.2, 0.3, 0.2]")
    with pytest.raises(StudyError, match="points 0 and 2 are the same"):
        load_study(path)


def test_a_changed_study_reruns_only_the_new_points(tmp_path):
    out = str(tmp_path / "out")
    first = load_study(_write_study(tmp_path / "a.toml", "mu_spline = [0.2, 0.3]",
                                    backend="model"))
    run_study(first, out, executor="loop", progress=None, figures=False)
    second = load_study(_write_study(tmp_path / "b.toml", "mu_spline = [0.3, 0.25]",
                                     backend="model"))
    res = run_study(second, out, executor="loop", progress=None, figures=False)
    assert res.skipped == 1 and [p.values for p in res.results] == [{"mu_spline": 0.25}]
    assert [r["mu_spline"] for r in res.rows] == [0.3, 0.25]
    assert [r["point"] for r in res.rows] == [0.0, 1.0]
