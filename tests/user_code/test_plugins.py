"""One rule set for user code named by reference (humanoid_twin/plugins.py; docs/controllers.md,
"References"): a scenario, a ``--law`` class and a ``--host-controller`` function are named the
same ways (``FILE.py:NAME``, ``MODULE:NAME``, an entry point's name) and fail the same way (one
line naming the kind and the reference, exit 2, nothing written)."""

from __future__ import annotations

from pathlib import Path

import pytest

from humanoid_twin.cli.main import main
from humanoid_twin.controllers import ControllerError, LawError, load_host_controller, load_law
from humanoid_twin.scenarios import REGISTRY, ScenarioLoadError, load_scenario

USER = '''
from humanoid_twin.scenarios import REGISTRY
from humanoid_twin.slave.laws import ControlLaw


class Still(ControlLaw):
    cycles = 100

    def step(self, inputs):
        return [0, 0, 0]


def step(ctx):
    ctx.state["calls"] = ctx.calls


stand_again = REGISTRY["stand"]
'''

# the three kinds: (option, loader, error class, a name in USER of that kind)
KINDS = [
    ("law", load_law, LawError, "Still"),
    ("host controller", load_host_controller, ControllerError, "step"),
    ("scenario", load_scenario, ScenarioLoadError, "stand_again"),
]


@pytest.fixture
def user_file(tmp_path: Path) -> Path:
    f = tmp_path / "user_plugins.py"
    f.write_text(USER)
    return f


@pytest.mark.parametrize("what, load, error, name", KINDS)
def test_a_file_names_each_kind(user_file: Path, what, load, error, name) -> None:
    obj = load(f"{user_file}:{name}")
    assert getattr(obj, "__name__", None) == name or obj is REGISTRY["stand"]


@pytest.mark.parametrize("what, load, error, name", KINDS)
def test_each_kind_fails_in_the_same_words(user_file: Path, tmp_path: Path, what, load, error, name) -> None:
    said = []
    for ref in (f"{user_file}:nope", f"{tmp_path}/missing.py:x", "no_such_module_xyz:x", ":x",
                "not_installed_xyz"):
        with pytest.raises(error) as exc:
            load(ref)
        said.append(str(exc.value))
    assert all("\n" not in s for s in said)
    assert said[0].startswith(f"{what} '{user_file}:nope': {user_file} has no 'nope'")
    assert said[1] == f"{what} '{tmp_path}/missing.py:x': no such file {tmp_path}/missing.py"
    assert said[2].startswith(f"{what} 'no_such_module_xyz:x': cannot import no_such_module_xyz: "
                              "ModuleNotFoundError")
    assert said[3] == f"{what} ':x': expected FILE.py:NAME or MODULE:NAME"
    assert said[4].startswith(f"unknown {what} 'not_installed_xyz' (")
    assert "FILE.py:NAME, MODULE:NAME, or an entry point of 'humanoid_twin." in said[4]


@pytest.mark.parametrize("option", [["--law", "balance=exits_at_import:Law"],
                                    ["--host-controller", "exits_at_import:step"]])
def test_user_code_that_exits_while_imported_is_one_line_exit_2(tmp_path, capsys, monkeypatch,
                                                                  option) -> None:
    """Before issue 38 a law's or a host controller's module calling sys.exit(4) at import ended
    the command with exit 4 and no message (a scenario's was already one line, exit 2)."""
    (tmp_path / "exits_at_import.py").write_text("import sys\nsys.exit(4)\n")
    monkeypatch.chdir(tmp_path)
    log = tmp_path / "x.asc"
    with pytest.raises(SystemExit) as exc:
        main(["run", "stand", "--no-record", "--can-log", str(log), *option])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1, err
    assert "cannot import exits_at_import: SystemExit: 4" in err and not log.exists()
