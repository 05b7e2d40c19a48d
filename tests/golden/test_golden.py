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

Regenerated once, deliberately, by issue 26 (the body board's inclinometer and gyroscope, the
boards' cycle budget): against a9c82b3 every CAN log has the same frames in the same order with
the same identifiers; only the body board's Sensors 2 packets (0x285) carry other Data1..4 bytes
(its sensors, where it sent constants before), and the frames after one of them move by at most
3 us (their bit stuffing). The summaries gained ``task_load_max``, ``deadline_misses`` and
``imu_tilt_error_rms_deg``; every other key is unchanged.

Regenerated for the summaries alone by issue 37 (the summary says when): every CAN log, frame
count and exit code is unchanged, and so is every key the summaries held; they gained
``trunk_tilt_max_at_s``, ``trunk_tilt_max_motion_deg``, ``trunk_tilt_max_motion_at_s``,
``slip_mm_at_s``, ``cop_margin_min_at_s``, ``cop_margin_min_motion_mm``,
``cop_margin_min_motion_at_s`` and ``booted``.

Regenerate only when a change of behaviour is deliberate (and say so in the commit message):

    PYTHONPATH=TREE .venv/bin/python tests/golden/test_golden.py --hashseeds 0,1  # new vs pinned
    PYTHONPATH=TREE .venv/bin/python tests/golden/test_golden.py --write  # also rewrites golden.json

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

PINNED_COMMIT = "a9c82b3 + issue 26"
DETAILS = Path(__file__).with_name("golden.json")
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

# BEGIN GOLDEN (printed by `python tests/golden/test_golden.py`)
GOLDEN: dict[str, dict[str, Any]] = {
    "flexao_seed0": {"exit": 0, "frames": 21480,
        "can_sha256": "80d6a46576845c5e33778857e2bd7b9150c0b3ebb2227ebc8151dd2e4a56dd2b",
        "summary_sha256": "008b06ded190b105e654a272048085704916c2c024978bbf2f48595cdfabc661"},
    "inclinar_seed2": {"exit": 0, "frames": 21487,
        "can_sha256": "2c7b90c0c8f831de74bb38df2633aa1f50f840799425f703531b412165baa175",
        "summary_sha256": "741815fe54e18531e96e4a3627bbb4f448bfe59ca28285c2a0e95836313467aa"},
    "levantar_perna_1": {"exit": 0, "frames": 51880,
        "can_sha256": "47414a455fb9bd926f20281dcd60189bb18b343da3c84196dab3410eaa153ee2",
        "summary_sha256": "6eb11bacba79994105b7fd2a0d4eb672ca779507b3e905daaa951a6bd26128a2"},
    "levantar_perna_2": {"exit": 0, "frames": 51880,
        "can_sha256": "4e7d346b543ec7c0a6732fa65efe7b0e8adebe8f1fc919321854d24d798fba8d",
        "summary_sha256": "5769478f3ce9349e06339b84f02ea4fe445d6c2b1676e693285a96e710508949"},
    "stand_tilt15": {"exit": 0, "frames": 74680,
        "can_sha256": "620cedc39cc92134939ef4ecc28bbbb2f46e4be39257fab1eb5ad6e7269049db",
        "summary_sha256": "9d251deb83a3d4a29e9a2e420aaee253b2964eedc10d173983040108a73146f2"},
    "flexao_can_drop": {"exit": 0, "frames": 20996,
        "can_sha256": "0918701ae18ee7ce5174bc3b00789ab57cda3f8a073c0b1c335a232d3aaad0f1",
        "summary_sha256": "5972eba099a2b6f160a1854ed4ca17adac92992198cf41b40a42e35418ef9427"},
    "flexao_bus_off_1": {"exit": 3, "frames": 21475,
        "can_sha256": "2ad2fd2fa7bbf86f687e62f82fd4fc047ce9efe18120b17b5a3ef249c6b968db",
        "summary_sha256": "98bbc272b670e8bc4234e2d67bfb9e8af9dde8fab4f2d9972461f557a11a2ea1"},
    "flexao_silent_3": {"exit": 3, "frames": 20950,
        "can_sha256": "25665970116efb76eb45761adcd7d2dac0134937d32eceff306035709ab09a83",
        "summary_sha256": "9d35f17d8144297d7714321c331d59dcd4e71795eb2070be6f4a24e00116c619"},
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
            "about": "tests/golden/test_golden.py: the pinned runs (summary without wall_s/rtf; CAN log: "
                     f"python-can CSV, sha256 of each block of {BLOCK} frames, 16 hex digits)",
            "commit": PINNED_COMMIT,
            "runs": {name: {"args": list(RUNS[name]), **records[name]} for name in RUNS},
        }
        DETAILS.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        print(f"wrote {DETAILS}", file=sys.stderr)
    return 1 if unstable else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
