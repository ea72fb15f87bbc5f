"""Every tool follows the same command-line conventions: help text for every option, --version on every tool,
--json printing to stdout, and the same -o / --force / --quiet wherever a command writes a folder.

The parsers are taken from the tools themselves (each main() is called with --help while argparse records the
parser it builds), so a new option without help, or a new command without the shared options, fails here."""
import argparse
import importlib
import json
import subprocess
import sys

import pytest

TOOLS = {"sgim": "sgim.cli", "dda": "dda.cli", "adapters": "adapters.cli", "cases crossval": "cases.lib.crossval",
         "cases study": "cases.lib.study"}


class _Caught(Exception):
    pass


def _parser_of(module, monkeypatch):
    """The root ArgumentParser `module.main` builds."""
    seen = []
    original = argparse.ArgumentParser.parse_known_args

    def record(self, args=None, namespace=None):
        seen.append(self)
        raise _Caught

    monkeypatch.setattr(argparse.ArgumentParser, "parse_known_args", record)
    try:
        importlib.import_module(module).main(["--help"])
    except _Caught:
        pass
    finally:
        monkeypatch.setattr(argparse.ArgumentParser, "parse_known_args", original)
    assert seen, f"{module}.main built no parser"
    return seen[0]


def _commands(name, parser):
    """(command name, parser) of every leaf command under `parser`."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [(name, parser)]
    out = []
    for a in subs:
        for sub, p in a.choices.items():
            out += _commands(f"{name} {sub}", p)
    return out


def _all_commands(monkeypatch):
    cmds = []
    for tool, module in TOOLS.items():
        cmds += _commands(tool, _parser_of(module, monkeypatch))
    return cmds


def _options(parser):
    return {s for a in parser._actions for s in a.option_strings}


def test_every_option_of_every_command_has_help_text(monkeypatch):
    missing = []
    for name, parser in _all_commands(monkeypatch):
        for a in parser._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            if not (a.help and a.help.strip()) or a.help == argparse.SUPPRESS:
                missing.append(f"{name} {'/'.join(a.option_strings) or a.dest}")
    assert not missing, "options without help text: " + ", ".join(missing)


def test_shared_options_mean_the_same_everywhere(monkeypatch):
    cmds = dict(_all_commands(monkeypatch))
    assert {"sgim build", "sgim dfn", "dda run", "dda wedge", "adapters export", "adapters run", "cases crossval",
            "cases study run", "cases study report"} <= set(cmds)
    wrong = []
    for name, parser in cmds.items():
        opts = _options(parser)
        if "--output" in opts or "-o" in opts:
            if name not in ("sgim show", "adapters run", "cases study report"):  # a picture, a result folder
                wrong += [f"{name}: no {o}" for o in ("-o", "--force", "--quiet") if o not in opts]
        if name not in ("sgim show",) and "--json" not in opts:
            wrong.append(f"{name}: no --json")
    assert not wrong, "; ".join(wrong)


@pytest.mark.parametrize("tool", ["sgim", "dda", "adapters", "cases"])
def test_every_tool_states_its_version(tool):
    from importlib.metadata import version

    p = subprocess.run([sys.executable, "-c", f"import sys; from {'cases.cli' if tool == 'cases' else tool + '.cli'} "
                        "import main; sys.exit(main(['--version']))"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and p.stdout.strip() == f"{tool} (rockdem {version('rockdem')})", p.stderr


def test_json_goes_to_stdout_alone(tmp_path):
    """--json prints one JSON document on stdout (progress stays on stderr): sgim build as the example."""
    scene = tmp_path / "s.toml"
    scene.write_text('name = "s"\n[domain]\nmin = [0, 0, 0]\nmax = [1, 1, 1]\n[packing]\nkind = "cubic"\n'
                     'radius = 0.25\n[output]\nformats = ["npz"]\n')
    p = subprocess.run([sys.executable, "-m", "sgim.cli", "build", str(scene), "-o", str(tmp_path / "o"), "--json"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["spheres"] == 8 and p.stderr  # progress lines on stderr
