"""Every command shown in README.md and docs/*.md still works (issue 15 point 8).

The commands are read from the fenced ``bash``/``sh`` blocks and from inline code spans that start
with ``pounding-cosim`` or ``python cosim/`` (spans with placeholders such as ``SCENE`` or ``...``
are prose, not commands).  A fast equivalent of running each:

* every command parses with the command line's own parser (subcommand, options, value types);
* ``run`` of a bundled scene runs for real for 0.3 s of simulated time into a temporary folder;
  ``--list`` and study ``--dry-run`` run as written;
* other scripts (benchmarks, CI) exist and compile;
* the README's Python example runs as written (its FMU folder the session's) and prints the
  impact counts its comment states.

Setup lines (virtualenv, pip, pytest, environment variables for a foreign host) are not product
commands and are skipped, by the patterns in ``SETUP``.
"""
from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: script shims and the subcommand each is (cosim/<name>.py -> pounding-cosim <command>)
SHIMS = {"cosim/run.py": "run", "cosim/study.py": "study", "cosim/calibrate.py": "calibrate",
         "cosim/report.py": "report", "build_fmu.py": "build-fmus"}
#: lines of other tools: setup, a foreign FMI host, a Dask cluster (docs/studies.md)
SETUP = ("python3 -m venv", "pip install", "-m pytest", "LD_PRELOAD", "PYTHONPATH", "your_fmi_host", "dask scheduler",
         "dask worker")
#: placeholders of prose spans (an upper-case word, an ellipsis, an optional argument)
_PLACEHOLDER = re.compile(r"\b[A-Z][A-Z_]{2,}\b|\.\.\.|\[")


def _lines(text: str):
    for block in re.finditer(r"```(?:bash|sh|shell)\n(.*?)```", text, re.S):
        yield from (line.strip() for line in block.group(1).splitlines())
    for span in re.finditer(r"`((?:pounding-cosim|python cosim/)[^`]*)`", text):
        # prose names a command (`pounding-cosim study`) or shows a use with placeholders: only
        # spans with arguments and no placeholder are complete commands
        if len(span.group(1).split()) > 2 and not _PLACEHOLDER.search(span.group(1)):
            yield span.group(1)


def documented_commands() -> list[tuple[str, str, list[str]]]:
    """(file, command as written, argv of pounding-cosim) of every documented command."""
    out = []
    for path in DOCS:
        for line in _lines(path.read_text()):
            if not line or line.startswith("#") or any(s in line for s in SETUP):
                continue
            words = shlex.split(line, comments=True)
            if words[0] == "pounding-cosim":
                argv = words[1:]
            elif words[0] in ("python", "python3", ".venv/bin/python") and words[1] in SHIMS:
                assert (ROOT / words[1]).is_file(), f"{path.name}: {words[1]} does not exist"
                argv = ([SHIMS[words[1]]] + words[2:]) if SHIMS[words[1]] != "study" or words[2:3] != ["plot"] \
                    else ["study-plot"] + words[3:]
            elif (words[0] in ("python", "python3", ".venv/bin/python") and words[1].endswith(".py")) \
                    or words[0].startswith(".ci/"):
                script = words[1] if words[0].startswith("python") or words[0].startswith(".venv") else words[0]
                SCRIPTS.append((path.name, line, script))     # benchmarks, CI: too long to run here
                continue
            else:
                raise AssertionError(f"{path.name}: {line!r} is neither a command of the package nor a setup line")
            if argv:                                        # the bare program name is prose
                out.append((path.name, line, argv))
    return out


SCRIPTS: list[tuple[str, str, str]] = []    # (file, line, script path) of other documented scripts
COMMANDS = documented_commands()


@pytest.mark.parametrize("where, line, script", SCRIPTS, ids=[s for _, _, s in SCRIPTS])
def test_documented_scripts_exist_and_compile(where, line, script):
    assert (ROOT / script).is_file(), f"{where}: `{line}`: {script} does not exist"
    if script.endswith(".py"):
        compile((ROOT / script).read_text(), script, "exec")      # a SyntaxError fails the test
    else:
        assert (ROOT / script).stat().st_mode & 0o111, f"{script} is not executable"


def test_the_docs_show_commands():
    # README: the quick start, the run examples; docs: other tools, running, studies
    assert len(COMMANDS) >= 20
    assert {name for name, _, _ in COMMANDS} >= {"README.md", "running.md", "studies.md"}


@pytest.mark.parametrize("where, line, argv", COMMANDS, ids=[line[:60] for _, line, _ in COMMANDS])
def test_every_documented_command_parses(where, line, argv):
    parser, subs = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        if exc.code == 0 and "--help" in argv:
            return
        pytest.fail(f"{where}: `{line}` is refused by the command line (exit {exc.code})")
    assert getattr(args, "handler", None) is not None, f"{where}: `{line}` names no command"


def _bundled(name: str) -> bool:
    from cosim.master import bundled_scenes

    return name in bundled_scenes()


RUNS = [(w, line, argv) for w, line, argv in COMMANDS
        if argv[0] == "run" and "--export-ssp" not in argv and (
            "--list" in argv or len(argv) == 1 or argv[1].startswith("-") or _bundled(argv[1]))
        and not any("path/to" in a for a in argv)]


@pytest.mark.parametrize("where, line, argv", RUNS, ids=[line[:60] for _, line, _ in RUNS])
def test_documented_runs_run(where, line, argv, fmu_dir, tmp_path, capsys):
    extra = [] if "--list" in argv else ["--stop-time", "0.3", "--no-plots", "--no-progress",
                                         "--out", str(tmp_path / "out"), "--fmu-dir", str(fmu_dir)]
    assert main(argv + extra) == 0, f"{where}: `{line}` failed: {capsys.readouterr().err}"


DRY_RUNS = [(w, line, argv) for w, line, argv in COMMANDS if argv[0] == "study" and "--dry-run" in argv]


@pytest.mark.parametrize("where, line, argv", DRY_RUNS, ids=[line[:60] for _, line, _ in DRY_RUNS])
def test_documented_study_dry_runs(where, line, argv, fmu_dir, capsys):
    assert main(argv + ["--fmu-dir", str(fmu_dir)]) == 0, f"{where}: `{line}` failed: {capsys.readouterr().err}"
    assert capsys.readouterr().out.strip()                  # it says what the study would run


def test_the_readme_python_example_prints_what_it_says(fmu_dir, tmp_path):
    text = (ROOT / "README.md").read_text()
    block = re.search(r"### From Python\n\n```python\n(.*?)```", text, re.S).group(1)
    expected = re.search(r"# (\d+), (\d+), (\d+)\s*$", block.strip()).groups()
    code = block.replace('"build/fmus"', repr(str(fmu_dir)))
    code = code.replace('write=False)', f'write=False, fmu_dir={str(fmu_dir)!r})')
    code += "\nfrom cosim.master.fmi import exit_process\nexit_process(0)\n"
    script = tmp_path / "example.py"
    script.write_text(code)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    printed = [line.split() for line in done.stdout.splitlines() if line.strip()]
    assert [p[0] for p in printed] == ["0.01", "0.02", "0.03"]
    assert tuple(p[1] for p in printed) == expected, (printed, expected)
