"""Fault injection (humanoid_twin/faults.py) and what the Master's supervisor makes of each kind
(docs/supervisor.md): one injection per kind, through the run API, the twin API and the CLI."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest
from helpers import REPO

from humanoid_twin import faults
from humanoid_twin.faults import FaultInjector, FaultKind, FaultSpecError, parse_fault
from humanoid_twin.host import drivers
from humanoid_twin.master.supervisor import SupervisorConfig
from humanoid_twin.protocol.canframes import SFLAGS_WATCHDOG
from humanoid_twin.scenarios import RunOptions, boot, run
from humanoid_twin.twin import Twin

BOOT_S = 2.7          # the boot (PWM on, calibration) ends at ~2.65 s simulated


def run_with(scenario: str, *specs: str, duration: float = 3.6, **kw) -> dict:
    return run(RunOptions(scenario=scenario, duration=duration, progress=False,
                          faults=tuple(parse_fault(s) for s in specs), **kw))


def first(summary: dict) -> tuple[str, int]:
    f = summary["faults"][0]
    return f["name"], f["node"]


# --- the SPEC parser --------------------------------------------------------------------------
@pytest.mark.parametrize("text, kind, arg, t0, t1", [
    ("can-drop:0.02", "can-drop", 0.02, 0.0, None),
    ("silent:3@1.5", "silent", 3, 1.5, None),
    ("bus-off:0@2-2.5", "bus-off", 0, 2.0, 2.5),
    ("servo-stuck:1.3", "servo-stuck", (1, 3), 0.0, None),
    ("push:-20@3", "push", -20.0, 3.0, None),
    ("force-stuck:2", "force-stuck", 2, 0.0, None),
])
def test_parse_good_specs(text, kind, arg, t0, t1) -> None:
    s = parse_fault(text)
    assert (s.kind, s.arg, s.t0_s, s.t1_s) == (kind, arg, t0, t1)


@pytest.mark.parametrize("text", ["bogus:1", "silent", "silent:9", "can-drop:1.5", "deadline:0",
                                  "force-stuck:3", "servo-stuck:1", "servo-stuck:1.4", "push:0",
                                  "push:10@1-2", "silent:1@2-1", "silent:1@x", "can-drop:0.1@-1"])
def test_parse_bad_specs_one_line(text) -> None:
    with pytest.raises(FaultSpecError) as exc:
        parse_fault(text)
    assert "\n" not in str(exc.value) and repr(text) in str(exc.value)


# --- the registry: a kind is one entry ------------------------------------------------------------
def test_a_new_kind_is_one_registry_entry() -> None:
    """A throwaway kind, registered once, is parsed, started and ended on a twin's clock, listed
    in the CLI's help and the docs table, and composes (two at once on one joint add up)."""
    from humanoid_twin.cli.fault_options import add_fault_options

    def parse(text: str, arg_s: str) -> float:
        try:
            return float(arg_s)
        except ValueError:
            raise FaultSpecError(f"bad --fault {text!r}: NM must be a number") from None

    def load(inj: FaultInjector, spec) -> None:   # start and end: what the active set makes of it
        inj.twin.plant.set_external_torque("r_knee", inj.effective(spec))

    kind = faults.register(FaultKind("knee-load", "NM", parse, load, load, "a torque on the right knee",
                                     combine=lambda args: float(sum(args))))
    try:
        assert parse_fault("knee-load:0.5@0.1-0.3").arg == 0.5
        with pytest.raises(FaultSpecError, match="NM must be a number"):
            parse_fault("knee-load:x")
        ap = argparse.ArgumentParser(formatter_class=lambda prog: argparse.HelpFormatter(prog, width=10_000))
        add_fault_options(ap)
        assert "push:NEWTONS, knee-load:NM (docs/supervisor.md)" in ap.format_help()
        assert ap.parse_args(["--fault", "knee-load:1"]).fault[0].arg == 1.0
        assert "| `knee-load` | NM | a torque on the right knee |" in faults.kinds_markdown()
        with Twin(seed=0) as twin:
            specs = [parse_fault("knee-load:0.5@0.1-0.3"), parse_fault("knee-load:0.25@0.2")]
            inj = FaultInjector(twin, specs).install()
            torque = []
            for t_us in (50_000, 150_000, 250_000, 350_000):
                twin.advance_to(t_us)
                torque.append(float(twin.plant.data.qfrc_applied[twin.plant.model.joint("r_knee").dofadr[0]]))
        assert torque == [0.0, 0.5, 0.75, 0.25]
        assert [(t, what, s.arg) for t, what, s in inj.events] == [
            (100_000, "start", 0.5), (200_000, "start", 0.25), (300_000, "end", 0.5)]
    finally:
        faults.unregister(kind.name)
    with pytest.raises(FaultSpecError, match="unknown kind 'knee-load'"):
        parse_fault("knee-load:0.5")


def test_the_docs_table_of_kinds_is_the_registry() -> None:

    doc = (REPO / "docs" / "supervisor.md").read_text()
    block = doc.split("<!-- generated: fault-kinds -->\n")[1].split("<!-- end generated: fault-kinds -->")[0]
    assert block == faults.kinds_markdown(), "run scripts/gen_docs.py"
    assert [line.split("`")[1] for line in block.splitlines()[2:]] == list(faults.KINDS)


# --- survivable faults: nothing false raised, the robot stands ----------------------------------
@pytest.mark.parametrize("spec", ["can-drop:0.02", "can-corrupt:0.01", "serial-noise:0.01"])
def test_survivable_faults_raise_nothing_and_the_robot_stands(spec) -> None:
    s = run_with("stand", spec, duration=4.0)
    assert s["mode"] == "ready" and s["faults"] == [] and "host_error" not in s
    assert not s["fell"]
    assert s["injected"][0]["spec"] == spec


# --- detected faults ------------------------------------------------------------------------------
@pytest.mark.parametrize("spec, name, node, within_s", [
    ("silent:0@2.9", "silent", 0, 0.05),
    ("silent:5@2.9", "silent", 5, 0.05),
    ("bus-off:0@2.9", "bus_off", 0, 0.05),
    ("bus-off:6@2.9", "slave_can", 6, 0.05),
    ("can-corrupt:0.3@2.9", "bus_off", 0, 0.2),
    ("deadline:4@2.9", "deadline", 4, 0.15),
])
def test_detected_faults_latch_safe_and_the_robot_holds(spec, name, node, within_s) -> None:
    s = run_with("stand", spec)
    assert first(s) == (name, node)
    assert 0 <= s["faults"][0]["t_s"] - 2.9 <= within_s
    assert s["mode"] == "safe" and not s["fell"]


def test_push_falls_and_is_caught_by_balance_a_small_one_is_not() -> None:
    big = run_with("stand", "push:40@3.0", duration=3.8)
    assert big["fell"] and first(big) == ("balance", 0) and big["mode"] == "safe"
    assert big["faults"][0]["t_s"] < 3.0 + 0.4
    small = run_with("stand", "push:-5@3.0", duration=3.8)
    assert not small["fell"] and small["faults"] == [] and small["mode"] == "ready"


def test_servo_stuck_in_flexao_is_caught_by_balance_and_not_without_it() -> None:
    stuck = run_with("flexao", "servo-stuck:1.3@2.8", duration=4.2)
    assert first(stuck) == ("balance", 0) and stuck["mode"] == "safe"
    clean = run_with("flexao", duration=4.2)
    assert clean["faults"] == [] and clean["mode"] == "ready" and not clean["fell"]


def test_over_travel_with_a_tight_limit_during_flexao() -> None:
    s = run_with("flexao", duration=4.2, supervisor=SupervisorConfig(over_travel_deg=5))
    assert s["faults"] and s["faults"][0]["name"] == "over_travel" and s["faults"][0]["node"] in (1, 2, 3, 4)
    assert s["mode"] == "safe"


def test_host_link_is_off_by_default_and_latches_when_configured() -> None:
    on = run_with("stand", duration=3.6, supervisor=SupervisorConfig(host_link_ms=300))
    assert first(on) == ("host_link", 0) and on["mode"] == "safe"
    off = run_with("stand", duration=3.6)
    assert off["faults"] == [] and off["mode"] == "ready"


# --- faults the supervisor does not see (documented): their effect is real --------------------
def _booted(*specs: str, seed: int = 0) -> tuple[Twin, object]:
    twin = Twin(seed=seed)
    FaultInjector(twin, [parse_fault(s) for s in specs], seed).install()
    return twin, boot(twin)


def _forces(H, twin: Twin, n: int = 10) -> list[tuple[int, ...]]:
    out = []
    for _ in range(n):
        twin.run_for(0.04)
        out.append(drivers.readspecial(H, 1).special)
    return out


def test_force_noise_makes_the_firmware_readings_noisy() -> None:
    twin, H = _booted(f"force-noise:40@{BOOT_S}")
    with twin:
        twin.run_for(0.1)
        noisy = _forces(H, twin)
        assert max(max(col) - min(col) for col in zip(*noisy, strict=True)) >= 10
        assert twin.master.supervisor.mode_name == "ready"
    twin, H = _booted()
    with twin:
        twin.run_for(0.1)
        clean = _forces(H, twin)
        assert max(max(col) - min(col) for col in zip(*clean, strict=True)) < 10


def test_force_stuck_freezes_the_foot_while_the_loads_change() -> None:
    twin, H = _booted(f"force-stuck:1@{BOOT_S}")
    with twin:
        twin.run_for(0.1)
        before = [drivers.readspecial(H, k).special for k in (1, 2)]
        twin.plant.set_trunk_force(15.0)     # lean on the feet: the real loads change
        twin.run_for(0.3)
        after = [drivers.readspecial(H, k).special for k in (1, 2)]
        twin.plant.set_trunk_force(0.0)
        assert after[0] == before[0]         # the stuck foot
        assert after[1] != before[1]         # the other foot sees the lean
        assert twin.master.supervisor.mode_name == "ready"


def test_slave_watchdog_holds_the_last_reference_and_says_so() -> None:
    twin, H = _booted()
    with twin:
        twin.run_for(0.05)
        twin.network.silence("master")
        twin.run_for(0.13)                   # > 5 ticks without an actuation packet
        for s in twin.slaves.values():
            assert s.can.watchdog and s.can.payload[0][0] & SFLAGS_WATCHDOG
            assert s.pic.pwm                 # the servos keep their pulses: the robot holds
        assert not twin.plant.truth().fell
        twin.network.silence("master", False)
        twin.run_for(0.05)
        assert not any(s.can.watchdog for s in twin.slaves.values())


# --- the CLI: exit codes 0 / 2 / 3 and the summary ------------------------------------------------
def _cli(*args: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_cli_exit_codes_and_summary(tmp_path) -> None:
    out = tmp_path / "x.rrd"
    bad = _cli("run", "stand", "--fault", "silent:9", "--out", str(out), cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "silent:9" in bad.stderr
    assert not out.exists()
    log = tmp_path / "x.asc"
    r = _cli("run", "stand", "--duration", "3.5", "--fault", "silent:3@3", "--fault", "can-drop:0.01",
             "--seed", "4", "--out", str(out), "--can-log", str(log), "--json", "--no-progress", cwd=tmp_path)
    assert r.returncode == 3, r.stderr
    s = json.loads(r.stdout.strip().splitlines()[-1])
    assert s["mode"] == "safe" and s["faults"][0]["name"] == "silent" and s["faults"][0]["node"] == 3
    assert [i["spec"] for i in s["injected"]] == ["silent:3@3", "can-drop:0.01"]
    assert out.stat().st_size > 0 and log.stat().st_size > 0
    ok = _cli("run", "stand", "--duration", "3", "--no-record", "--json", "--no-progress", cwd=tmp_path)
    assert ok.returncode == 0 and json.loads(ok.stdout.strip().splitlines()[-1])["mode"] == "ready"


# --- the recording: mode series, faults and injections as text events, a Supervisor view -------
def _names(container) -> list[str]:
    out = [getattr(container, "name", None)]
    for c in getattr(container, "contents", None) or []:
        out += _names(c)
    return [n for n in out if n]


def test_recording_has_the_mode_series_the_events_and_a_supervisor_view(tmp_path) -> None:
    from rerun.chunk import RrdReader

    from humanoid_twin.recording import read_rrd_scalars, rrd_has_blueprint
    from humanoid_twin.recording.blueprint import default_blueprint

    out = tmp_path / "f.rrd"
    s = run(RunOptions(scenario="stand", duration=3.4, progress=False, out=out,
                       faults=(parse_fault("silent:3@3"),)))
    assert s["mode"] == "safe"
    t, series = read_rrd_scalars(out, "supervisor/mode")
    mode, nfaults = series[:, 0], series[:, 1]
    assert list(dict.fromkeys(mode.tolist())) == [0.0, 1.0, 2.0, 3.0]
    assert t[-1] >= 3.3 and mode[-1] == 3.0 and nfaults[-1] == 1.0
    texts = []
    for c in RrdReader(out).stream():
        if c.entity_path == "/supervisor/events":
            rb = c.to_record_batch()
            tl = rb.column(rb.schema.names.index("sim_time")).cast("int64").to_numpy(zero_copy_only=False)
            for ts, txt in zip(tl, rb.column(rb.schema.names.index("TextLog:text")).to_pylist(), strict=True):
                texts.append((ts / 1e9, txt[0]))
    texts.sort()
    assert any(txt == "injected silent:3@3: start" and abs(ts - 3.0) < 1e-6 for ts, txt in texts)
    fault = [ts for ts, txt in texts if txt == "fault silent (node 3)"]
    assert fault and abs(fault[0] - s["faults"][0]["t_s"]) < 1e-6
    assert rrd_has_blueprint(out)
    assert "Supervisor" in _names(default_blueprint().root_container)


def test_fault_runs_are_seeded() -> None:
    specs = ("can-drop:0.05@2.9", "serial-noise:0.01@2.9", "force-noise:20@2.9")
    a = run_with("stand", *specs, duration=3.3, seed=3)
    b = run_with("stand", *specs, duration=3.3, seed=3)
    c = run_with("stand", *specs, duration=3.3, seed=4)
    keys = ("can_frames", "serial_frames", "faults", "cop_error_rms_mm", "mode")
    assert [a[k] for k in keys] == [b[k] for k in keys]
    assert [a[k] for k in keys] != [c[k] for k in keys]
