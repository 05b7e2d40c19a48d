"""Golden runs: the twin's end-to-end behaviour pinned, byte for byte, before the compiled core.

What is pinned, for each run of ``RUNS`` (``humanoid-twin run ARGS --no-record --can-log
golden.csv --json --no-progress``, in a subprocess, in a fresh directory):

- the CAN log: sha256 of the bytes of python-can's CSV log (virtual timestamps, id, flags, dlc,
  data: no channel name, no date, no path, identical run after run), its frame count and, in
  ``tests/golden/golden.json``, the sha256 of every block of ``BLOCK`` frames, so that a failure
  says how many frames there are now and where the traffic first differs;
- the summary: the ``--json`` summary without its wall-clock keys (``TIMING_KEYS``: ``wall_s``,
  ``rtf``), as ``json.dumps(summary, sort_keys=True)``: its sha256 here and the whole dict in
  ``tests/golden/golden.json``, so that a failure lists the keys that differ;
- the exit code (3 for the runs that end with the supervisor in ``safe``).

Every run is checked on both cores: ``compiled`` (the environment without
``HUMANOID_TWIN_PURE_PYTHON``: the compiled core where it is built) and ``python``
(``HUMANOID_TWIN_PURE_PYTHON=1``: the interpreted source). Both must give the pinned bytes.

The digests were computed from commit a9c82b3 (the pure-Python twin, before the clock, bus,
Master and Slave modules were compiled), in a git worktree of that commit, with python-can 4.6.1:
each digest was the same over repeated runs and under different ``PYTHONHASHSEED`` values.
The 8 runs take ~20 s of wall time in pure Python on a 2-core machine (the 16 cases here ~45 s,
more on a loaded machine).

Regenerate only when a change of behaviour is deliberate (and say so in the commit message):

    PYTHONPATH=TREE .venv/bin/python tests/test_golden.py --hashseeds 0,1  # new digests vs the pinned ones
    PYTHONPATH=TREE .venv/bin/python tests/test_golden.py --write      # also rewrite tests/golden/golden.json

then paste the printed ``GOLDEN = {...}`` over the one below. ``TREE`` is the source tree to pin
(e.g. a ``git worktree``; without ``PYTHONPATH`` the installed package); the script prints where
``humanoid_twin`` was imported from.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)

PINNED_COMMIT = "a9c82b3"
DETAILS = Path(__file__).with_name("golden") / "golden.json"
PURE_PYTHON_ENV = "HUMANOID_TWIN_PURE_PYTHON"
CAN_LOG = "golden.csv"          # relative, the run's cwd is its own directory: the summary's can_log
TIMING_KEYS = ("wall_s", "rtf")  # the summary's keys that depend on the wall clock
BLOCK = 1000                    # frames per block digest of the CAN log
RUN_TIMEOUT_S = 600
COMMON_ARGS = ("--no-record", "--can-log", CAN_LOG, "--json", "--no-progress")

# name -> the scenario and its arguments (COMMON_ARGS appended). Default durations: boot ~2.65 s +
# the motion (or the tilt ramp, 1 deg/s) + 2 s of settling. The faults hit flexao mid-squat.
RUNS: dict[str, tuple[str, ...]] = {
    "flexao_seed0": ("flexao", "--seed", "0"),
    "inclinar_seed2": ("inclinar", "--seed", "2"),
    "levantar_perna_1": ("levantar_perna", "--perna", "1", "--seed", "0"),
    "levantar_perna_2": ("levantar_perna", "--perna", "2", "--seed", "0"),
    "stand_tilt15": ("stand", "--tilt", "15", "--seed", "0"),
    "flexao_can_drop": ("flexao", "--seed", "0", "--fault", "can-drop:0.05"),
    "flexao_bus_off_1": ("flexao", "--seed", "0", "--fault", "bus-off:1@3"),
    "flexao_silent_3": ("flexao", "--seed", "0", "--fault", "silent:3@3"),
}

# BEGIN GOLDEN (printed by `python tests/test_golden.py`)
GOLDEN: dict[str, dict[str, Any]] = {
    "flexao_seed0": {"exit": 0, "frames": 21480,
        "can_sha256": "8084b3bc56a9f7b4648101572b3d98c5d3975718a0fdce19fe241e62a6f62a27",
        "summary_sha256": "899b20509506177b404745563002f504f93707d9d5eeb423a7dae008504dcc7b"},
    "inclinar_seed2": {"exit": 0, "frames": 21487,
        "can_sha256": "fd5739a72005f37069d09a324873945e9d3fa6882bde1e83f68566da6ab9d806",
        "summary_sha256": "a505eda17808b8366bd95cae0502a1286b6a0382e8fc20cd43a9d955b7510e71"},
    "levantar_perna_1": {"exit": 0, "frames": 51880,
        "can_sha256": "d71736506e19da9ee1de4a01b59ec0c80cead3cedf7e568f590adda02139d20d",
        "summary_sha256": "02ed91f8317c1d89e656bc9296815334b1af8ec68462983f0d0f000a4f0e2b8c"},
    "levantar_perna_2": {"exit": 0, "frames": 51880,
        "can_sha256": "40332b6e2436fd740e94e0e54287b66b1316b862d920fe931e30ff16ec58f725",
        "summary_sha256": "f1d2f7ed6e0e4b637d556619482086c76ac3efefb82819bba29cd07e70531eaf"},
    "stand_tilt15": {"exit": 0, "frames": 74680,
        "can_sha256": "fd7481c9f7bd5f89b342ab73e6ca749265601f09fdca47f42757d1202a3ae0de",
        "summary_sha256": "e2cb10eefd3e7ae12d37d8a116d7bd221c793f4b9525bc0fa1bbb9c3e16d3569"},
    "flexao_can_drop": {"exit": 0, "frames": 20996,
        "can_sha256": "bfd457a217ac85f462fa36e59e81ec1fe755812ab7f152b9b82cc3e69edf7081",
        "summary_sha256": "bb2bc16bd0b378ee55ed14e00e33459337a73819766376d31142cd492495ea5e"},
    "flexao_bus_off_1": {"exit": 3, "frames": 21475,
        "can_sha256": "0482560bc6f999844d926c66799e0bd7bf022ebf8f5746f5b0ac47c1c6dde173",
        "summary_sha256": "c18f5c588130fb39450509b314f82c604737e7a6403d29c6814a8049062032d5"},
    "flexao_silent_3": {"exit": 3, "frames": 20950,
        "can_sha256": "518936ea57dac76f5b8fd328ff45e6c5759c55118cfa68f3342001553aca0af0",
        "summary_sha256": "247c7aa90df2f9e627ee52c030b589551ec6c0333a4eda413398c5766a4b3deb"},
}
# END GOLDEN

CORES = ("compiled", "python")


def core_env(core: str) -> dict[str, str]:
    """The environment of a run on ``core``: ``compiled`` without HUMANOID_TWIN_PURE_PYTHON,
    ``python`` with it set to 1."""
    env = dict(os.environ)
    env.pop(PURE_PYTHON_ENV, None)
    if core == "python":
        env[PURE_PYTHON_ENV] = "1"
    return env


@dataclass
class Outcome:
    """What one run left: exit code, CAN log bytes (None: no file), summary (None: no JSON)."""

    exit: int
    can_log: bytes | None
    summary: dict[str, Any] | None
    stderr: str
    wall_s: float


def run_cli(name: str, workdir: Path, env: dict[str, str]) -> Outcome:
    cmd = [sys.executable, "-m", "humanoid_twin.cli.main", "run", *RUNS[name], *COMMON_ARGS]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    wall = time.perf_counter() - t0
    summary = None
    lines = proc.stdout.strip().splitlines()
    if lines:
        try:
            summary = json.loads(lines[-1])
        except json.JSONDecodeError:
            summary = None
    log = workdir / CAN_LOG
    return Outcome(proc.returncode, log.read_bytes() if log.exists() else None, summary, proc.stderr, wall)


def canonical_summary(summary: dict[str, Any]) -> dict[str, Any]:
    """The summary without its wall-clock keys, through a JSON round trip (sorted keys)."""
    return json.loads(json.dumps({k: v for k, v in summary.items() if k not in TIMING_KEYS}, sort_keys=True))


def summary_sha256(summary: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(canonical_summary(summary), sort_keys=True).encode()).hexdigest()


def frame_lines(can_log: bytes) -> list[bytes]:
    """The CSV log's frame lines (its header line dropped)."""
    return can_log.splitlines()[1:]


def block_digests(lines: list[bytes]) -> list[str]:
    return [hashlib.sha256(b"\n".join(lines[i:i + BLOCK])).hexdigest()[:16]
            for i in range(0, len(lines), BLOCK)]


def record(out: Outcome) -> dict[str, Any]:
    """The pinned description of a run."""
    lines = frame_lines(out.can_log or b"")
    return {
        "exit": out.exit,
        "frames": len(lines),
        "can_sha256": hashlib.sha256(out.can_log or b"").hexdigest(),
        "can_block_sha256": block_digests(lines),
        "summary_sha256": summary_sha256(out.summary or {}),
        "summary": canonical_summary(out.summary or {}),
    }


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 160 else text[:157] + "..."


def differences(out: Outcome, pinned: dict[str, Any], details: dict[str, Any]) -> list[str]:
    """What differs between a run and its pins, one line each (empty: the golden bytes)."""
    problems: list[str] = []
    if out.exit != pinned["exit"]:
        tail = "\n      ".join(out.stderr.strip().splitlines()[-5:]) or "(nothing)"
        problems.append(f"exit code {pinned['exit']} -> {out.exit}; stderr ends:\n      {tail}")
    # the CAN log
    if out.can_log is None:
        problems.append(f"CAN log: no {CAN_LOG} written")
    elif hashlib.sha256(out.can_log).hexdigest() != pinned["can_sha256"]:
        lines = frame_lines(out.can_log)
        what = f"CAN log differs: frame count {pinned['frames']} -> {len(lines)}"
        blocks = block_digests(lines)
        old_blocks = details.get("can_block_sha256", [])
        first = next((i for i, (a, b) in enumerate(zip(old_blocks, blocks, strict=False)) if a != b),
                     min(len(old_blocks), len(blocks)))
        if first < len(blocks):
            block = lines[first * BLOCK:(first + 1) * BLOCK]
            t0, t1 = block[0].split(b",")[0].decode(), block[-1].split(b",")[0].decode()
            what += (f"; first differing block: frames {first * BLOCK}..{first * BLOCK + len(block) - 1} "
                     f"(now virtual time {t0}..{t1} s)")
        elif len(lines) == pinned["frames"]:
            what += "; same frames, different bytes (header or line endings?)"
        problems.append(what)
    # the summary
    if out.summary is None:
        problems.append("summary: no JSON on the last line of stdout")
    elif summary_sha256(out.summary) != pinned["summary_sha256"]:
        now, old = canonical_summary(out.summary), details.get("summary", {})
        keys = sorted(set(now) | set(old))
        diffs = [f"{k}: {_short(old[k]) if k in old else '(absent)'} -> "
                 f"{_short(now[k]) if k in now else '(absent)'}"
                 for k in keys if old.get(k, KeyError) != now.get(k, KeyError)]
        problems.append("summary differs (timing keys aside): "
                        + ("; ".join(diffs) if diffs else "the pinned copy in golden.json is stale"))
    return problems


def load_details() -> dict[str, Any]:
    return json.loads(DETAILS.read_text())["runs"]


def test_pins_agree() -> None:
    """``GOLDEN`` and tests/golden/golden.json describe the same runs."""
    details = load_details()
    assert sorted(GOLDEN) == sorted(RUNS) == sorted(details)
    for name, pinned in GOLDEN.items():
        d = details[name]
        assert d["args"] == list(RUNS[name]), name
        for key in ("exit", "frames", "can_sha256", "summary_sha256"):
            assert d[key] == pinned[key], (name, key)
        assert summary_sha256(d["summary"]) == pinned["summary_sha256"], name
        assert len(d["can_block_sha256"]) == -(-pinned["frames"] // BLOCK), name


@pytest.mark.parametrize("core", CORES)
@pytest.mark.parametrize("name", list(RUNS))
def test_golden(name: str, core: str, tmp_path: Path) -> None:
    out = run_cli(name, tmp_path, core_env(core))
    problems = differences(out, GOLDEN[name], load_details()[name])
    assert not problems, (
        f"run {name} ({' '.join(RUNS[name])}) on the {core} core differs from the golden run of "
        f"commit {PINNED_COMMIT}:\n  - " + "\n  - ".join(problems))


# --- regenerating ------------------------------------------------------------------------------


def _main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="Compute the golden digests of RUNS with the humanoid_twin "
                                     "importable here (PYTHONPATH), compare them with the pins.")
    parser.add_argument("--hashseeds", default="0",
                        help="run each once per PYTHONHASHSEED of this comma list (e.g. 0,1,random): "
                        "all must agree")
    parser.add_argument("--core", choices=CORES, default="python")
    parser.add_argument("--only", action="append", choices=list(RUNS), help="only this run (repeatable)")
    parser.add_argument("--write", action="store_true", help="rewrite tests/golden/golden.json")
    args = parser.parse_args(argv)
    env = core_env(args.core)
    where = subprocess.run([sys.executable, "-c", "import humanoid_twin; print(humanoid_twin.__file__)"],
                           env=env, cwd=tempfile.gettempdir(), capture_output=True, text=True, check=True)
    print(f"humanoid_twin from {where.stdout.strip()}, core {args.core}", file=sys.stderr)
    names = args.only or list(RUNS)
    seeds = [s.strip() for s in args.hashseeds.split(",") if s.strip()]
    records: dict[str, dict[str, Any]] = {}
    unstable = False
    total = 0.0
    for name in names:
        seen = []
        for i in seeds:
            with tempfile.TemporaryDirectory() as tmp:
                out = run_cli(name, Path(tmp), {**env, "PYTHONHASHSEED": str(i)})
            total += out.wall_s
            rec = record(out)
            seen.append(rec)
            print(f"{name:18s} PYTHONHASHSEED={i} {out.wall_s:6.2f} s exit {rec['exit']} "
                  f"frames {rec['frames']} can {rec['can_sha256'][:12]} summary {rec['summary_sha256'][:12]}",
                  file=sys.stderr)
        if any(r != seen[0] for r in seen[1:]):
            unstable = True
            print(f"{name}: NOT STABLE over PYTHONHASHSEED {args.hashseeds}", file=sys.stderr)
        records[name] = seen[0]
        old = GOLDEN.get(name)
        if old is not None:
            same = all(old[k] == seen[0][k] for k in ("exit", "frames", "can_sha256", "summary_sha256"))
            print(f"{name:18s} {'= pinned' if same else 'DIFFERS from the pinned digests'}", file=sys.stderr)
    print(f"total wall time {total:.1f} s over {len(names) * len(seeds)} runs", file=sys.stderr)
    print("GOLDEN: dict[str, dict[str, Any]] = {")
    for name, rec in records.items():
        print(f'    "{name}": {{"exit": {rec["exit"]}, "frames": {rec["frames"]},\n'
              f'        "can_sha256": "{rec["can_sha256"]}",\n'
              f'        "summary_sha256": "{rec["summary_sha256"]}"}},')
    print("}")
    if args.write:
        if unstable or set(names) != set(RUNS):
            print("not written: every run is needed, and stable", file=sys.stderr)
            return 1
        DETAILS.parent.mkdir(exist_ok=True)
        doc = {
            "about": "tests/test_golden.py: the pinned runs (summary without wall_s/rtf; CAN log: python-can "
                     f"CSV, sha256 of each block of {BLOCK} frames, 16 hex digits)",
            "commit": PINNED_COMMIT,
            "runs": {name: {"args": list(RUNS[name]), **records[name]} for name in RUNS},
        }
        DETAILS.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        print(f"wrote {DETAILS}", file=sys.stderr)
    return 1 if unstable else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
