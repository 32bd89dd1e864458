"""Every numeric option of every command refuses nan, inf and out-of-range values with one line.

``--seconds nan`` made ``rehab play --headless`` run forever and ``--fps inf`` made ``rehab simulate``
hang; ``rom-test --fps 0`` divided by zero after the whole test. The parser is walked, so a new
option with a bare ``type=float`` fails here.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from game.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]


def commands(parser: argparse.ArgumentParser, prefix=()):
    """(argv prefix, sub-parser) of every command, nested ones too."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from commands(sub, prefix + (name,))
    if prefix:
        yield prefix, parser


def numeric_options():
    out = []
    for prefix, parser in commands(build_parser()):
        for action in parser._actions:
            if action.option_strings and action.type is not None and action.choices is None:
                out.append((prefix, action))
    return out


def test_no_numeric_option_is_a_bare_float_or_int():
    bare = [f"{' '.join(p)} {a.option_strings[0]}" for p, a in numeric_options() if a.type in (float, int)]
    assert bare == []
    assert len([1 for _, a in numeric_options() if getattr(a.type, "__name__", "") == "number"]) >= 40


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "-5", "1e30", "banana"])
def test_every_numeric_option_refuses_with_one_line(bad, capsys):
    checked = 0
    for prefix, action in numeric_options():
        if getattr(action.type, "__name__", "") != "number":
            continue
        if bad == "-5" and _accepts(action, "-5"):
            continue   # e.g. --turn-deg takes negative angles
        with pytest.raises(SystemExit) as exit_:
            main([*prefix, f"{action.option_strings[0]}={bad}"])
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and err.count("\n") == 1 and action.option_strings[0] in err, (prefix, err)
        checked += 1
    assert checked >= 30


def _accepts(action, text) -> bool:
    try:
        action.type(text)
        return True
    except argparse.ArgumentTypeError:
        return False


@pytest.mark.parametrize("argv", [
    ["play", "--headless", "--seconds", "nan"],
    ["simulate", "out", "--fps", "inf"],
    ["rom-test", "--fps", "0", "--test", "elbow_flexion", "--dry-run"],
    ["rom-test", "--fps", "-30", "--test", "elbow_flexion", "--dry-run"],
    ["rom-test", "--attempts", "2.7", "--test", "elbow_flexion", "--dry-run"],
    ["simulate", "out", "--noise", "-5"],
    ["record", "out", "--seconds", "nan"],
    ["simulate", "out", "--drift", "nan"],
    ["simulate", "out", "--jpeg-quality", "0"],
    ["simulate", "out", "--exposure-ms", "nan"],
    ["simulate", "out", "--jpeg-quality", "50", "--jpeg-chroma", "411"],
    ["play", "--max-fps", "nan"],
])
def test_the_reported_hangs_and_tracebacks_are_one_line_before_any_work(argv, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and err.startswith("rehab "), err


def test_list_into_a_closed_pipe_ends_quietly():
    code = ("import subprocess, sys\n"
            "p = subprocess.Popen([sys.executable, '-m', 'game', 'rom-test', '--list'], stdout=subprocess.PIPE,"
            " stderr=subprocess.PIPE, bufsize=0)\n"
            "p.stdout.close()\n"
            "err = p.stderr.read().decode(); rc = p.wait()\n"
            "print(rc, repr(err))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120).stdout
    rc, err = out.split(" ", 1)
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert int(rc) in (0, 141), out
