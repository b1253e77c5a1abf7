"""The ``ocslam`` parser: every command listed, and a command imports only what it needs."""

from __future__ import annotations

import subprocess
import sys

import pytest

from app.cli import BENCHES, COMMANDS, _selected, build_parser


def _modules_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys; print(' '.join(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True, timeout=120)
    return set(out.stdout.split())


@pytest.mark.parametrize(("argv", "expected"), [
    ([], (None, None)),
    (["--help"], (None, None)),
    (["replay", "BAG", "--headless", "--set", "a.b=c"], ("replay", None)),
    (["bench", "soak", "--sim-hours", "2"], ("bench", "soak")),
    (["bench", "--help"], ("bench", None)),
])
def test_selected_command(argv, expected):
    assert _selected(argv) == expected
    assert _selected(None) is None


def test_help_lists_every_command_and_benchmark(capsys):
    for argv in (["--help"], ["bench", "--help"]):
        with pytest.raises(SystemExit) as e:
            build_parser(argv).parse_args(argv)
        assert e.value.code == 0
    out = capsys.readouterr().out
    for name in list(COMMANDS) + list(BENCHES):
        assert name in out


def test_a_command_parses_with_only_its_own_module():
    args = build_parser(["bench", "soak", "--sim-hours", "0.5"]).parse_args(["bench", "soak", "--sim-hours", "0.5"])
    assert args.sim_hours == 0.5 and callable(args._run)
    full = build_parser().parse_args(["bench", "soak", "--sim-hours", "0.5"])
    assert full.sim_hours == 0.5


def test_headless_commands_do_not_import_the_web_stack():
    # the entry module and a headless command's parser stay free of viser (0.4 s of imports) and of the
    # other commands' modules (scipy's sparse and spatial through the SLAM benchmark)
    mods = _modules_after("import app.server\nfrom app.cli import build_parser\n"
                          "build_parser(['replay', 'BAG', '--headless'])")
    assert "viser" not in mods
    assert "app.commands.replay" in mods
    assert not {m for m in mods if m.startswith("app.bench.")}
    assert "app.commands.sweep" not in mods
