"""End to end: the CLI writes the run folder, its provenance and its report."""

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd

from canebench.cli import main

REQUIRED = ["trial", "cane", "backend", "protocol", "k_sim", "k_field", "log_ratio", "status", "wall_s"]


def test_run_writes_results_report_and_provenance(tmp_path: Path):
    out = tmp_path / "run"
    assert main(["run", "--trials", "b2c*", "--out", str(out), "--jobs", "1", "--set", "segments=6"]) == 0
    res = pd.read_csv(out / "results.csv")
    assert set(REQUIRED) <= set(res.columns)
    assert len(res) == 18 and set(res.backend) == {"mujoco", "pinocchio"}
    ok = res[res.status == "ok"]
    assert (ok.n_links == 6).all()
    assert ((ok.log_ratio - (ok.k_sim / ok.k_field).apply(__import__("math").log)).abs() < 1e-12).all()
    meta = json.loads((out / "run.json").read_text())
    assert meta["engines"]["mujoco"] and meta["engines"]["pinocchio"]
    assert meta["protocol"]["name"] == "fast" and meta["model_config"]["segments"] == 6
    assert meta["synthetic"] is True
    assert meta["git_dirty"] in (True, False, None)  # uncommitted code says so beside its commit
    assert "mujoco" in meta["backend_settings"] and meta["backend_settings"]["mujoco"]["integrator"] == "discrete"
    for f in ("report.html", "stiffness.png", "log_ratio.png", "traces.png", "traces.csv", "field.csv"):
        assert (out / f).exists(), f
    html = (out / "report.html").read_text()
    assert "SYNTHETIC" in html and "Summary" in html
    # report rebuilds from the files alone
    (out / "stiffness.png").unlink()
    assert main(["report", str(out)]) == 0 and (out / "stiffness.png").exists()


def test_provenance_says_when_a_checkout_has_uncommitted_changes(tmp_path: Path):
    import subprocess

    from canebench.execute.provenance import git_dirty

    assert git_dirty(tmp_path) is None  # not a checkout
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@example.org"]
    subprocess.run([*git, "init", "-q"], cwd=tmp_path, check=True)
    (tmp_path / "a.py").write_text("x = 1\n")
    subprocess.run([*git, "add", "a.py"], cwd=tmp_path, check=True)
    subprocess.run([*git, "commit", "-q", "-m", "a"], cwd=tmp_path, check=True)
    assert git_dirty(tmp_path) is False
    (tmp_path / "new.txt").write_text("untracked files are not the code that ran\n")
    assert git_dirty(tmp_path) is False
    (tmp_path / "a.py").write_text("x = 2\n")
    assert git_dirty(tmp_path) is True


def test_bad_inputs_exit_2_with_message(tmp_path: Path, capsys):
    assert main(["run", "--backends", "mujoco,nosuch", "--out", str(tmp_path / "x")]) == 2
    assert "nosuch" in capsys.readouterr().err
    assert main(["run", "--set", "modulus_pa=soft", "--out", str(tmp_path / "y")]) == 2
    assert "modulus_pa" in capsys.readouterr().err
    assert main(["run", "--field", str(tmp_path / "missing"), "--out", str(tmp_path / "z")]) == 2
    assert main(["run", "--trials", "zzz*", "--out", str(tmp_path / "w")]) == 2
    # every command that takes engine names refuses a mistyped one before doing any work
    # (discover used to fit for minutes first; bench --engines timed it as 54 failed trials)
    for cmd in (["discover", "--out", str(tmp_path / "d")], ["bench", "--engines"], ["bench", "--morris"],
                ["bench", "--discover"]):
        assert main([*cmd, "--backends", "beam,nosuch"]) == 2, cmd
        assert "unknown backend 'nosuch'" in capsys.readouterr().err, cmd
    assert not (tmp_path / "d").exists()
    for cmd in (["run", "--out", str(tmp_path / "r")], ["study", "naive", "--out", str(tmp_path / "s")]):
        assert main([*cmd, "--backends", "nosuch"]) == 2, cmd
        assert "unknown backend 'nosuch'" in capsys.readouterr().err, cmd
    assert not (tmp_path / "r").exists() and not (tmp_path / "s").exists()
    assert main(["bench", "--morris", "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err
    # discovery settings no run can use are refused before any work, naming the option
    for opt, val in (("--alpha", "2"), ("--alpha", "nan"), ("--alpha", "0"), ("--bootstrap", "0"),
                     ("--min-change", "-0.1"), ("--min-change", "inf")):
        assert main(["discover", "--out", str(tmp_path / "d"), opt, val]) == 2, (opt, val)
        assert f"{opt}: field" in capsys.readouterr().err, (opt, val)
    assert main(["discover", "--selftest", "--workers", "0", "--out", str(tmp_path / "d")]) == 2
    assert "--workers" in capsys.readouterr().err
    assert main(["discover", "--selftest", "--selftest-cases", "zz*", "--alpha", "0.1", "--backends", "mujoco",
                 "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert "--selftest-cases" in err and "--backends, --alpha do not apply" in err
    from canebench.cli.common import default_jobs

    # the suite's processes are --workers; the executor's options are named too (they were not read)
    assert main(["discover", "--selftest", "--selftest-cases", "zz*", "--executor", "serial", "--jobs", str(default_jobs() + 1),
                 "--out", str(tmp_path / "d")]) == 2
    assert "--executor, --jobs do not apply" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_a_bad_cane_is_refused_before_any_simulation(tmp_path: Path, capsys):
    import shutil

    from canebench.data.dataset import bundled_dataset

    d = tmp_path / "data"
    shutil.copytree(bundled_dataset(), d)
    y = d / "canes" / "b1c1.yaml"
    y.write_text(y.read_text().replace("- height:", "- height: 9.0\n  bogus:", 1))
    out = tmp_path / "run"
    assert main(["run", "--field", str(d), "--out", str(out), "--trials", "b1c*", "--no-report"]) == 2
    err = capsys.readouterr().err
    assert "b1c1.yaml: field 'calipers[0]" in err  # the unknown key or the height past the tip, named
    assert not (out / "results.csv").exists()


def test_malformed_yaml_stops_with_file_and_line(tmp_path: Path, capsys):
    import shutil

    from canebench.data.dataset import bundled_dataset

    d = tmp_path / "data"
    shutil.copytree(bundled_dataset(), d)
    (d / "canes" / "b1c2.yaml").write_text("id: b1c2\npolyline: [[0, 0\n")
    assert main(["run", "--field", str(d), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "b1c2.yaml" in err and "line" in err


def test_backends_command_lists_versions(capsys):
    assert main(["backends"]) == 0
    out = capsys.readouterr().out
    assert "mujoco" in out and "pinocchio" in out and "canebench.backends" in out


def test_module_entry_point_runs():
    r = subprocess.run([sys.executable, "-m", "canebench", "backends"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "mujoco" in r.stdout


def test_study_modulus_command_writes_tables_figures_and_report(tmp_path: Path, capsys):
    out = tmp_path / "mod"
    # options the in-process study does not read are named, not silently dropped
    assert main(["study", "modulus", "--out", str(out), "--backends", "mujoco", "--timeout", "0",
                 "--executor", "local"]) == 0
    err = capsys.readouterr().err
    assert "leaves --backends, --timeout aside" in err, err
    for f in ("modulus.csv", "modulus_groups.csv", "modulus_tests.csv", "modulus_by_season.png",
              "modulus_fruiting.png", "report.html"):
        assert (out / f).exists(), f
    (out / "report.html").unlink()
    assert main(["report", str(out)]) == 0  # rebuilt from the files alone
    assert "flexural" in (out / "report.html").read_text().lower()


def test_bench_engines_times_the_engines_named(capsys):
    # --backends mujoco once meant "the default", so every installed engine was timed
    assert main(["bench", "--engines", "--backends", "mujoco", "--trials", "b1c1t1"]) == 0
    out = capsys.readouterr().out
    rows = out.split("backend", 1)[1].splitlines()[1:]
    assert [r.split()[0] for r in rows if r.strip() and not r.startswith("total")] == ["mujoco"], out


def test_an_input_warning_is_shown_once_per_message_not_once_per_read(capsys):
    """discover reads a rig CSV in several stages: each file's warning is one line, and two
    files' warnings from the same code line are two (the "default" filter would keep one)."""
    import warnings

    from canebench.cli.common import input_warnings
    from canebench.errors import warn_input

    with warnings.catch_warnings():  # restores the filters and showwarning
        input_warnings(strict=False)
        for _ in range(3):
            for f in ("a.csv", "b.csv"):
                warn_input(f, "Displacement (mm)", "1 sample(s) repeat the previous position")
    err = capsys.readouterr().err.splitlines()
    assert err == [f"canebench: warning: {f}: field 'Displacement (mm)': 1 sample(s) repeat the previous position"
                   for f in ("a.csv", "b.csv")]
