"""The named parameters on the command line (docs/parameters.md): ``--params FILE.toml`` and
``--set NAME=VALUE`` on ``run``, ``serve`` and ``sweep``, and the ``humanoid-twin params``
command (``params [--json]``, ``params show FILE``, ``params diff A B``).

A bad name, value or file is one line on stderr and exit 2, before anything is written.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from humanoid_twin.cli.messages import usage_error


def add_params_options(p: argparse.ArgumentParser) -> None:
    """``--params FILE.toml`` and ``--set NAME=VALUE`` (both repeatable; the files first, in
    order, then each ``--set`` in order: a later value overrides an earlier one)."""
    p.add_argument("--params", action="append", default=[], type=Path, metavar="FILE.toml",
                   help="the robot's named parameters from a TOML file (humanoid-twin params lists them; "
                   "docs/parameters.md)")
    p.add_argument("--set", action="append", default=[], dest="set_params", metavar="NAME=VALUE",
                   help="one named parameter (a glob sets every match: servo.*_knee.kp=40), after "
                   "--params; repeatable")


def _split_sets(args: argparse.Namespace) -> tuple[list[str], dict[str, str]]:
    """``--set`` s: the named parameters' texts, and the scenario's fields (``scenario.FIELD=V``)."""
    from humanoid_twin.scenarios import SCENARIO_FIELD_PREFIX

    sets: list[str] = []
    fields: dict[str, str] = {}
    for text in vars(args).get("set_params") or ():
        name, eq, value = text.partition("=")
        if name.strip().startswith(SCENARIO_FIELD_PREFIX):
            field = name.strip()[len(SCENARIO_FIELD_PREFIX):]
            if not eq or not field or not value.strip():
                raise usage_error(f"--set {text!r}: expected scenario.FIELD=VALUE")
            fields[field] = value.strip()
        else:
            sets.append(text)
    return sets, fields


def scenario_with_fields(spec: Any, args: argparse.Namespace) -> Any:
    """``run``'s scenario with its own fields set by ``--set scenario.FIELD=VALUE`` (kept in
    ``args.scenario_fields``); a usage error for a field it does not have or a bad value."""
    from humanoid_twin.scenarios import ScenarioInputError, with_fields

    args.scenario_fields = _split_sets(args)[1]
    try:
        return with_fields(spec, args.scenario_fields)
    except ScenarioInputError as exc:
        raise usage_error(str(exc)) from None


def params_from_args(args: argparse.Namespace) -> dict[str, float]:
    """The checked parameters of ``--params`` and ``--set`` (and ``--pic-mhz``, the parameter
    ``pic_mhz``'s own flag): a usage error (exit 2) on a bad one."""
    from humanoid_twin.cycles import DEFAULT_PIC_MHZ
    from humanoid_twin.params import ParamError, merge

    sets, fields = _split_sets(args)
    if fields and vars(args).get("command") != "run":
        raise usage_error(f"--set scenario.{next(iter(fields))}: only run (and sweep) run a scenario")
    try:
        values = merge(vars(args).get("params") or (), sets)
    except ParamError as exc:
        raise usage_error(str(exc)) from None
    pic = vars(args).get("pic_mhz", DEFAULT_PIC_MHZ)
    if pic != DEFAULT_PIC_MHZ:
        if "pic_mhz" in values and values["pic_mhz"] != pic:
            raise usage_error(f"--pic-mhz {pic:g} and the parameter pic_mhz = {values['pic_mhz']:g} "
                              "disagree: give one")
        values["pic_mhz"] = pic
    return values


# -- humanoid-twin params ----------------------------------------------------------------------------
def add_params_parser(sub: argparse._SubParsersAction[Any]) -> argparse.ArgumentParser:
    """The ``params`` subcommand (``sub``: the CLI's subparsers)."""
    p = sub.add_parser(
        "params", help="list the robot's named parameters; check, show or compare params files",
        description="The robot's named parameters (docs/parameters.md). Without an action: every name "
        "with its unit, default, bounds and source. `params show FILE`: check a params file and print "
        "it. `params diff A B`: the parameters whose values differ between two files.")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout (keyed by name)")
    acts = p.add_subparsers(dest="params_action", metavar="ACTION")
    show = acts.add_parser("show", help="check a params file and print its values")
    show.add_argument("file", type=Path, metavar="FILE.toml")
    show.add_argument("--json", action="store_true", dest="json_action", help="one JSON object on stdout")
    diff = acts.add_parser("diff", help="the parameters whose values differ between two params files")
    diff.add_argument("a", type=Path, metavar="A.toml")
    diff.add_argument("b", type=Path, metavar="B.toml")
    diff.add_argument("--json", action="store_true", dest="json_action", help="one JSON object on stdout")
    return p


def _load(path: Path) -> dict[str, float]:
    from humanoid_twin.params import ParamError, load_params_file

    try:
        return load_params_file(path)
    except ParamError as exc:
        raise usage_error(str(exc)) from None


def _table(rows: Sequence[Sequence[str]], header: tuple[str, ...]) -> str:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    out = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip()]
    out += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    return "\n".join(out) + "\n"


def cmd_params(args: argparse.Namespace) -> int:
    """``humanoid-twin params [--json]``, ``params show FILE``, ``params diff A B``."""
    from humanoid_twin.params import registry

    reg = registry()
    as_json = args.json or vars(args).get("json_action", False)
    action = args.params_action
    if action is None:
        _list(reg, as_json)
    elif action == "show":
        _show(reg, args.file, as_json)
    else:
        _diff(reg, args.a, args.b, as_json)
    return 0


def _list(reg: Any, as_json: bool) -> None:
    """Every named parameter: its unit, default, bounds and what it is."""
    if as_json:
        out = json.dumps({p.name: p.as_dict() for p in reg}, ensure_ascii=False)
        sys.stdout.write(out + "\n")
    else:
        rows = [(p.name, p.unit, f"{p.default:.6g}", f"{p.min:.6g}", f"{p.max:.6g}", p.doc) for p in reg]
        sys.stdout.write(_table(rows, ("name", "unit", "default", "min", "max", "doc")))


def _show(reg: Any, path: Path, as_json: bool) -> None:
    """The values a parameter file sets, beside their defaults."""
    values = _load(path)
    if as_json:
        sys.stdout.write(json.dumps(values) + "\n")
    else:
        rows = [(n, f"{v:.6g}", f"{reg.get(n).default:.6g}", reg.get(n).unit) for n, v in values.items()]
        sys.stdout.write(_table(rows, ("name", "value", "default", "unit")) if rows
                         else f"{path}: no parameters (every default)\n")


def _diff(reg: Any, path_a: Path, path_b: Path, as_json: bool) -> None:
    """The parameters two files set differently (a default where a file sets none)."""
    a, b = _load(path_a), _load(path_b)
    changed = {}
    for name in sorted({*a, *b}):
        default = reg.get(name).default
        va, vb = a.get(name, default), b.get(name, default)
        if va != vb:
            changed[name] = (va, vb)
    if as_json:
        sys.stdout.write(json.dumps({n: {"a": va, "b": vb} for n, (va, vb) in changed.items()}) + "\n")
    elif changed:
        rows = [(n, f"{va:.6g}", f"{vb:.6g}", reg.get(n).unit) for n, (va, vb) in changed.items()]
        sys.stdout.write(_table(rows, ("name", str(path_a), str(path_b), "unit")))
    else:
        sys.stdout.write(f"{path_a} and {path_b} set the same values\n")
