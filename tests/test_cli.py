"""The one command line (cosim/cli.py): its commands, the shims, and the exit codes mapped once."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cosim import __version__
from cosim.cli import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, BadInput, build_parser, exit_code, main
from cosim.master.coupling import STRATEGIES
from cosim.master.fmi import FMUError
from cosim.master.guard import InstabilityError
from cosim.master.scene import SceneError

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ("run", "list", "accuracy", "spectrum", "separation", "export-ssp", "study", "study-plot", "study-compare",
            "calibrate", "report", "build-fmus",
            "cr-table", "fmu-docs", "opensees")


def test_the_commands():
    parser, subs = build_parser()
    assert tuple(subs) == COMMANDS
    # --coupling offers the registry's names, nothing else
    action = next(a for a in subs["run"]._actions if a.dest == "coupling")
    assert sorted(action.choices) == sorted(STRATEGIES)


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_answers_help(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == 0 and capsys.readouterr().out.startswith("usage: pounding-cosim")


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0 and capsys.readouterr().out.strip() == f"pounding-cosim {__version__}"


@pytest.mark.parametrize("args", [["-m", "cosim", "--help"], ["-m", "cosim.cli", "--help"],
                                  ["-m", "cosim.run", "--help"], ["cosim/run.py", "--help"],
                                  ["cosim/study.py", "--help"], ["cosim/study.py", "plot", "--help"],
                                  ["cosim/calibrate.py", "--help"], ["cosim/report.py", "--help"],
                                  ["build_fmu.py", "--help"]])
def test_shims_answer_help_with_their_own_name(args):
    proc = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    expected = "usage: pounding-cosim" if args[0] == "-m" and args[1] in ("cosim", "cosim.cli") else \
        "usage: python " + (" ".join(args[:2]) if "plot" in args else args[-2] if args[0] != "-m" else "")
    assert proc.stdout.startswith(expected.rstrip()), proc.stdout[:200]


def test_exit_codes_are_mapped_once():
    assert exit_code(KeyboardInterrupt()) == EXIT_INTERRUPTED == 130
    assert exit_code(SceneError("x")) == exit_code(BadInput("x")) == exit_code(FileNotFoundError("x")) == EXIT_BAD_INPUT
    assert exit_code(FMUError("p", "fmi2DoStep", 2)) == EXIT_FAILED                     # a run that failed
    assert exit_code(FMUError("p", "fmi2ExitInitializationMode", 3)) == EXIT_BAD_INPUT  # a parameter refused
    assert exit_code(InstabilityError("x", 1.0)) == EXIT_FAILED
    with pytest.raises(ZeroDivisionError):          # a bug is not bad input: its traceback is kept
        exit_code(ZeroDivisionError())


def test_an_interrupted_command_exits_130(monkeypatch, capsys):
    import cosim.cli as cli

    def interrupted(args):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "cmd_cr_table", interrupted)
    assert main(["cr-table"]) == EXIT_INTERRUPTED
    assert "interrupted" in capsys.readouterr().err


def test_bad_input_is_one_line_exit_2(capsys, fmu_dir):
    assert main(["build-fmus", "--out", str(fmu_dir), "nonsense"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.startswith("error: unknown FMU ['nonsense']") and err.count("\n") == 1


def test_list_names_every_bundled_scene_and_study(capsys):
    from cosim.apps.study import bundled_studies
    from cosim.master.loader import bundled_scenes

    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in bundled_scenes() + bundled_studies():
        assert f"\n{name} " in "\n" + out
