"""CLI start-up: building the parser (``sot-apps --help``, ``sot-apps track --help``) imports no heavy library;
a command imports what it needs when it runs. Checked on sys.modules in a fresh interpreter (not timed)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
HEAVY = ("scipy", "cv2", "trimesh", "pyarrow", "mcap", "embreex", "jsonschema", "pandas", "matplotlib", "sklearn")

PROBE = """
import contextlib, io, json, sys
from sot_apps.cli.main import main
with contextlib.redirect_stdout(io.StringIO()) as out:
    try:
        main(sys.argv[1:])
    except SystemExit:
        pass
print(json.dumps({"modules": sorted({m.split(".")[0] for m in sys.modules}), "help": out.getvalue()}))
"""


def _probe(*argv: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run([sys.executable, "-c", PROBE, *argv], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.parametrize("argv", [["--help"], ["track", "--help"], ["flow", "--help"], ["bench", "--help"],
                                  ["motion-export", "--help"], ["simulate-lidar", "--help"]])
def test_help_imports_no_heavy_library(argv):
    probe = _probe(*argv)
    assert [m for m in HEAVY if m in probe["modules"]] == []
    assert "usage: sot-apps" in probe["help"]


@pytest.mark.parametrize("argv", [["--help"], ["track", "--help"]])
def test_the_most_used_helps_do_not_load_numpy(argv):
    """``sot-apps --help`` and ``sot-apps track --help`` build their parsers without numpy (the preset names come
    from tracker/config.py, whose ground parameters live apart from the ground remover's numpy code)."""
    assert "numpy" not in _probe(*argv)["modules"]


def test_help_texts_are_complete():
    """The fast path (only the named command's module) gives the same help as the full parser."""
    from sot_apps.cli.main import _build_parser, _subcommand_choices, _subcommand_modules

    full = _subcommand_choices(_build_parser(_subcommand_modules()))
    top = _probe("--help")["help"]
    for name, parser in full.items():
        assert name in top
        assert _probe(name, "--help")["help"] == parser.format_help(), name


def test_a_typo_still_lists_the_commands(capsys):
    from sot_apps.cli.main import main

    with pytest.raises(SystemExit) as exc:
        main(["trak", "--help"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'trak'" in err and "track" in err


def test_the_command_list_is_the_full_parsers_help():
    """``sot-apps --help`` builds each subcommand up to its help line only (``SubcommandListed``): the listing is
    the full parser's, and the subcommands' own options are not built."""
    from sot_apps.cli.main import _build_parser, _subcommand_modules, listing_parser

    full = _build_parser(_subcommand_modules())
    listed = listing_parser()
    assert _probe("--help")["help"] == full.format_help() == listed.format_help()
    track = listed._subparsers._group_actions[0].choices["track"]
    assert [a.dest for a in track._actions] == ["help"]   # only argparse's own -h
