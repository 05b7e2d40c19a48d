"""Every wire fact once (docs/architecture.md, "Where each wire fact lives (once)"): a number or a
name that belongs to one module is not written again elsewhere in the package.

A scan of the code (comments and docstrings are prose, not code, and are not scanned) for the
literals that leaked before: the seed stride, the RS-232 rate, the Master's 250 us grid, the
control-type labels, int8 conversions by hand and the force sensors' calibration value.
"""

from __future__ import annotations

import ast
import functools

import pytest
from helpers import REPO

PKG = REPO / "humanoid_twin"


def _segment(lines: list[str], node: ast.expr) -> str:
    """``ast.get_source_segment`` on lines split once (it splits the whole file at each call:
    quadratic over a module's constants)."""
    if node.end_lineno is None or node.end_col_offset is None:
        return ""
    first, last = node.lineno - 1, node.end_lineno - 1
    if first == last:
        return lines[first].encode()[node.col_offset:node.end_col_offset].decode()
    head = lines[first].encode()[node.col_offset:].decode()
    tail = lines[last].encode()[:node.end_col_offset].decode()
    return head + "".join(lines[first + 1:last]) + tail


@functools.cache
def _code_constants() -> list[tuple[str, int, ast.Constant, str, ast.AST | None]]:
    """(module, line, constant, its source text, its parent) for every int or str constant of the
    package's code, docstrings left out; scanned once, when a test first asks (not at collection)."""
    out = []
    for path in sorted(PKG.rglob("*.py")):
        src = path.read_text(encoding="utf-8")
        lines = [line + "\n" for line in src.split("\n")]   # ast counts lines at "\n"
        tree = ast.parse(src)
        docs = set()
        parents: dict[int, ast.AST] = {}
        for node in ast.walk(tree):
            for child in ast.iter_child_nodes(node):
                parents[id(child)] = node
            body = getattr(node, "body", None)
            if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                    and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)):
                docs.add(id(body[0].value))
        rel = path.relative_to(PKG).as_posix()
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and type(node.value) in (int, str) and id(node) not in docs:
                text = _segment(lines, node)
                out.append((rel, node.lineno, node, text, parents.get(id(node))))
    return out


def _where(pred) -> list[str]:
    return sorted({f"{mod}:{line} {text}" for mod, line, node, text, parent in _code_constants()
                   if pred(mod, node, text, parent)})


def _number(*texts: str):
    return lambda mod, node, text, parent: type(node.value) is int and text.replace("_", "") in texts


# (what, the literal, the modules that own it)
NUMBERS = [
    ("the seed stride (seeds.derive_seed)", _number("7919"), {"seeds.py"}),
    ("the RS-232 rate (wire.BAUDRATE)", _number("115200"), {"protocol/wire.py"}),
    # (cycles.py's tables count instruction cycles, not microseconds: a 250 there is a cost)
    ("the Master's 250 us timer grid (master/pic.TIMER_PERIOD_US)",
     lambda mod, node, text, parent: (_number("250")(mod, node, text, parent)
                                      and not (mod == "cycles.py" and isinstance(parent, ast.Dict))),
     {"master/pic.py"}),
    # one microsecond-per-second constant, clock.US_PER_S; the PIC18F258's CAN bitrate, canframes
    ("a million (clock.US_PER_S; canframes.CAN_BITRATE)", _number("1000000"),
     {"clock.py", "protocol/canframes.py"}),
]


@pytest.mark.parametrize("what, pred, owners", NUMBERS, ids=[n[0] for n in NUMBERS])
def test_numbers_live_in_their_module(what, pred, owners) -> None:
    stray = [w for w in _where(pred) if w.split(":")[0] not in owners]
    assert not stray, f"{what} written outside {sorted(owners)}: {stray}"


def test_int8_is_converted_by_the_codecs_only() -> None:
    """``x - 256``, ``x += 256`` ... (a signed byte by hand): protocol/wire.py's ``s8``/``from_s8``."""
    def by_hand(mod, node, text, parent) -> bool:
        return (node.value == 256 and isinstance(parent, (ast.BinOp, ast.AugAssign))
                and isinstance(parent.op, (ast.Add, ast.Sub)))
    stray = [w for w in _where(by_hand) if not w.startswith("protocol/wire.py:")]
    assert not stray, f"int8 converted by hand (use wire.s8 / wire.from_s8): {stray}"


def test_force_calibration_value_is_named() -> None:
    """``reading - 128`` (a force reading against its calibration): hardware.FORCE_CALIBRATION_VALUE."""
    def minus_128(mod, node, text, parent) -> bool:
        return (text == "128" and isinstance(parent, (ast.BinOp, ast.AugAssign))
                and isinstance(parent.op, ast.Sub) and (getattr(parent, "right", None) is node
                                                        or getattr(parent, "value", None) is node))
    stray = _where(minus_128)
    assert not stray, f"128 subtracted by hand (hardware.FORCE_CALIBRATION_VALUE, wire.from_s8): {stray}"


LABELS = ("none", "locomotion", "reaction", "balance")


def test_control_type_labels_live_in_the_protocol() -> None:
    """The control types' short names are ``wire.ControlType.label``; the firmware's laws and the
    host do not retype them (``"balance"`` is also a supervisor fault's name, protocol/rs232.py,
    and ``"reaction"`` a variable of the toolbox's ``cop_acquire`` file, host/cop.py)."""
    others = {"balance": {"protocol/rs232.py", "master/supervisor.py"}, "reaction": {"host/cop.py"},
              "none": {"bus/protocol_twin.py"}}
    stray = [w for label in LABELS
             for w in _where(lambda mod, node, text, parent, label=label: node.value == label)
             if w.split(":")[0] not in {"protocol/wire.py", *others.get(label, ())}]
    assert not stray, f"control-type labels retyped (use wire.ControlType.label): {stray}"
