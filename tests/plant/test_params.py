"""The robot's named parameters (humanoid_twin/params.py, docs/parameters.md): the registry and
its defaults (read from the MJCF, never typed twice), their application (MjSpec, the sensors,
the boards' clock), the command line (``--params``, ``--set``, ``params``), what every output
records (summary, recording, CAN log, serial log and its replay), and bad input (exit 2, nothing
written). Real MuJoCo, rerun, python-can throughout."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
from helpers import cli

from humanoid_twin.cycles import DEFAULT_PIC_MHZ
from humanoid_twin.params import (
    Param,
    ParamError,
    load_params_file,
    non_defaults,
    params_digest,
    parse_set,
    registry,
)
from humanoid_twin.plant.plant import MODELS, Plant, model_assets
from humanoid_twin.twin import Twin

SPEC_NAMES = ("servo.r_knee.kp", "servo.r_knee.damping", "servo.r_knee.frictionloss", "servo.r_knee.armature",
              "servo.r_knee.torque_max", "pot.r_knee.offset_deg", "fsr.l_foot_rr.gain",
              "fsr.l_foot_rr.offset_counts", "floor.friction", "body.trunk.mass_scale", "pic_mhz")


def _plain_model() -> mujoco.MjModel:
    xml = (MODELS / "scene.xml").read_text()
    return mujoco.MjModel.from_xml_string(xml, assets=model_assets())


def _array_diff(a: mujoco.MjModel, b: mujoco.MjModel) -> list[str]:
    """The MjModel arrays that differ between ``a`` and ``b``."""
    out = []
    for name in dir(a):
        x = getattr(a, name, None)
        if name.startswith("_") or not isinstance(x, np.ndarray):
            continue
        y = getattr(b, name)
        if x.shape != y.shape or not np.array_equal(x, y, equal_nan=True):
            out.append(name)
    return out


# -- the registry ---------------------------------------------------------------------------------
def test_the_names_of_the_contract_are_there_with_unit_bounds_and_doc() -> None:
    reg = registry()
    for name in SPEC_NAMES:
        p = reg.get(name)
        assert isinstance(p, Param) and p.unit and p.doc and p.min <= p.default <= p.max
    assert len(reg.names()) == len(set(reg.names())) > 150
    assert registry() is reg                     # cached


def test_defaults_are_the_models_and_the_firmwares_own_numbers() -> None:
    """Each default is what the packaged model (compiled as the plant compiles it) and the code
    use today: read from them, not typed a second time."""
    reg, m = registry(), _plain_model()
    for joint in ("r_knee", "l_ankle_roll", "neck_pitch"):
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{joint}_act")
        dof = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)]
        assert reg.get(f"servo.{joint}.kp").default == m.actuator_gainprm[a, 0]
        assert reg.get(f"servo.{joint}.torque_max").default == m.actuator_forcerange[a, 1]
        assert reg.get(f"servo.{joint}.damping").default == m.dof_damping[dof]
        assert reg.get(f"servo.{joint}.frictionloss").default == m.dof_frictionloss[dof]
        assert reg.get(f"servo.{joint}.armature").default == m.dof_armature[dof]
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "platform")
    assert reg.get("floor.friction").default == m.geom_friction[g, 0]
    assert reg.get("pic_mhz").default == DEFAULT_PIC_MHZ
    bodies = {m.body(b).name for b in range(1, m.nbody)} - {"platform"}
    assert {n.split(".")[1] for n in reg.names() if n.startswith("body.")} == bodies


def test_check_expands_globs_and_refuses_bad_names_and_values() -> None:
    reg = registry()
    assert reg.check({"servo.*_knee.kp": 40}) == {"servo.r_knee.kp": 40.0, "servo.l_knee.kp": 40.0}
    assert reg.match("fsr.l_foot_*.gain") == [f"fsr.l_foot_{s}.gain" for s in ("fl", "fr", "rl", "rr")]
    with pytest.raises(ParamError, match=r"unknown parameter 'servo.r_kne.kp'; did you mean servo.r_knee.kp"):
        reg.check({"servo.r_kne.kp": 40})
    with pytest.raises(ParamError, match="matches no parameter"):
        reg.check({"servo.*_elbo.kp": 1})
    with pytest.raises(ParamError, match="outside its bounds"):
        reg.check({"floor.friction": 50})
    for bad in (math.nan, math.inf, "abc", True, None):
        with pytest.raises(ParamError):
            reg.check({"floor.friction": bad})
    assert parse_set("servo.*_knee.kp=40") == ("servo.*_knee.kp", 40.0)
    for bad in ("servo.r_knee.kp", "=3", "x=", "floor.friction=nan"):
        with pytest.raises(ParamError):
            parse_set(bad)


def test_non_defaults_and_digest() -> None:
    kp = registry().get("servo.r_knee.kp").default
    assert non_defaults({"servo.r_knee.kp": kp, "floor.friction": 0.5}) == {"floor.friction": 0.5}
    assert params_digest({"servo.r_knee.kp": kp}) == params_digest({})
    assert params_digest({"floor.friction": 0.5}) != params_digest({"floor.friction": 0.6})
    assert len(params_digest({"floor.friction": 0.5})) == 16


def test_a_params_file_quoted_names_tables_and_globs(tmp_path: Path) -> None:
    f = tmp_path / "robot.toml"
    f.write_text('"servo.*_knee.kp" = 40\n"floor.friction" = 0.8\n[body.trunk]\nmass_scale = 1.1\n')
    assert load_params_file(f) == {"servo.r_knee.kp": 40.0, "servo.l_knee.kp": 40.0, "floor.friction": 0.8,
                                   "body.trunk.mass_scale": 1.1}
    with pytest.raises(ParamError, match="no such file"):
        load_params_file(tmp_path / "missing.toml")
    (tmp_path / "broken.toml").write_text("floor.friction = = 1\n")
    with pytest.raises(ParamError, match="not TOML"):
        load_params_file(tmp_path / "broken.toml")
    (tmp_path / "text.toml").write_text('"floor.friction" = "slippery"\n')
    with pytest.raises(ParamError, match="not a number"):
        load_params_file(tmp_path / "text.toml")


# -- applied ---------------------------------------------------------------------------------------
def test_defaults_change_nothing_in_the_model() -> None:
    """Every parameter given at its default: the packaged model exactly (the run is today's)."""
    every = {p.name: p.default for p in registry()}
    plant = Plant(params=every)
    assert plant.params == {}
    assert _array_diff(plant.model, Plant().model) == []        # both with every servo unpowered


def test_a_servo_gain_through_mjspec_is_the_xml_edited_by_hand(tmp_path: Path) -> None:
    """``servo.*.kp`` = the model with humanoid.xml's kp edited by hand (the issue's measurement)."""
    for f in MODELS.iterdir():
        if f.name.endswith(".xml"):
            (tmp_path / f.name).write_bytes(f.read_bytes())
    xml = (tmp_path / "humanoid.xml").read_text()
    assert xml.count('kp="46.2614"') == 1
    (tmp_path / "humanoid.xml").write_text(xml.replace('kp="46.2614"', 'kp="55.51368"'))
    by_hand = mujoco.MjModel.from_xml_path(str(tmp_path / "scene.xml"))
    plant = Plant(params={"servo.*.kp": 55.51368})
    for a in range(by_hand.nu):          # as Plant does at power-up: every servo unpowered (kp 0)
        by_hand.actuator_gainprm[a, 0] = by_hand.actuator_biasprm[a, 1] = 0.0
    assert _array_diff(plant.model, by_hand) == []
    assert list(plant._kp) == [55.51368] * by_hand.nu       # the gain a powered servo gets


def test_model_parameters_set_masses_friction_and_the_gear_train() -> None:
    m0 = Plant().model
    p = Plant(params={"body.trunk.mass_scale": 1.5, "floor.friction": 0.4, "servo.l_knee.damping": 0.5,
                      "servo.l_knee.torque_max": 2.0})
    m = p.model
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "trunk")
    assert m.body_mass[b] == pytest.approx(1.5 * m0.body_mass[b])
    assert m.body_inertia[b] == pytest.approx(1.5 * m0.body_inertia[b])
    for name in ("platform", "r_foot_pad_fl", "l_foot_pad_rr"):       # both sides of the contact
        assert m.geom_friction[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name), 0] == 0.4
    dof = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "l_knee")]
    assert m.dof_damping[dof] == 0.5
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "l_knee_act")
    assert list(m.actuator_forcerange[a]) == [-2.0, 2.0]
    assert "actuator_gainprm" not in _array_diff(m, m0)      # the servos' gains left as they were


def test_sensor_parameters_reach_what_the_boards_read() -> None:
    """A force sensor's gain and zero, a pot's offset and the IMU's bias: on the boards' ADCs."""
    base = Plant(seed=0)
    p = Plant(seed=0, params={"fsr.r_foot_fl.offset_counts": 7, "fsr.r_foot_rr.gain": 2.0,
                              "pot.r_knee.offset_deg": 5.0, "imu.pitch_bias_deg": 4.0})
    assert p.pot_b_true_deg[1][2] == base.pot_b_true_deg[1][2] + 5.0
    assert p.pot_b_true_deg[1][:2] == base.pot_b_true_deg[1][:2]
    assert base.read_force_adc(1) == [0, 0, 0, 0]        # standing on nothing yet: unloaded
    assert p.read_force_adc(1) == [7, 0, 0, 0]           # the zero offset reads when unloaded
    for plant in (base, p):
        plant.advance_to(300_000)                       # the robot settles on its pads
    f0, f1 = base.read_force_adc(1), p.read_force_adc(1)
    assert f0[3] > 5 and abs(f1[3] - 2 * f0[3]) <= 3    # the rear-right sensor reads twice as much
    assert abs(f1[0] - (f0[0] + 7)) <= 3
    pitch = [plant.read_imu_adc(5)[1] for plant in (base, p)]
    assert 6 <= pitch[1] - pitch[0] <= 10               # 4 deg at 0.5 deg a count: 8 counts


def test_twin_takes_params_and_pic_mhz_is_one() -> None:
    with Twin(seed=0, params={"pic_mhz": 20}) as tw:
        assert tw.pic_mhz == 20.0 and tw.params == {"pic_mhz": 20.0}
    with Twin(seed=0, pic_mhz=10.0) as tw:
        assert tw.params == {"pic_mhz": 10.0}           # the flag's clock is a non-default too
    with Twin(seed=0) as tw:
        assert tw.params == {}
    with pytest.raises(ParamError):
        Twin(seed=0, params={"servo.nope.kp": 1})


# -- the command line and the outputs ----------------------------------------------------------------
def test_params_command_lists_shows_and_diffs(tmp_path: Path) -> None:
    r = cli("params", "--json")
    assert r.returncode == 0 and r.stdout.count("\n") == 1
    table = json.loads(r.stdout)
    assert table["servo.r_knee.kp"]["default"] == registry().get("servo.r_knee.kp").default
    assert set(table["floor.friction"]) == {"default", "unit", "min", "max", "doc"}
    r = cli("params")
    assert r.returncode == 0 and "servo.r_knee.kp" in r.stdout and "N·m/rad" in r.stdout
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.write_text('"servo.*_knee.kp" = 40\n')
    b.write_text('"servo.r_knee.kp" = 40\n"floor.friction" = 0.5\n')
    r = cli("params", "show", str(a), "--json")
    assert json.loads(r.stdout) == {"servo.r_knee.kp": 40.0, "servo.l_knee.kp": 40.0}
    r = cli("params", "diff", str(a), str(b), "--json")
    kp = registry().get("servo.l_knee.kp").default
    assert json.loads(r.stdout) == {"floor.friction": {"a": 1.0, "b": 0.5},
                                    "servo.l_knee.kp": {"a": 40.0, "b": kp}}
    r = cli("params", "show", str(tmp_path / "none.toml"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "no such file" in r.stderr


@pytest.fixture(scope="module")
def weak_knee_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """``run flexao`` with a params file and a --set, every output asked for (4 s: the boot and
    the start of the squat, whose joint reads the weaker knees change)."""
    d = tmp_path_factory.mktemp("weak")
    (d / "weak.toml").write_text('"servo.*_knee.kp" = 30\n"floor.friction" = 0.7\n')
    r = cli("run", "flexao", "--duration", "4", "--params", "weak.toml", "--set", "servo.l_knee.kp=35",
            "--out", "w.rrd", "--can-log", "w.asc", "--serial-log", "w.serial", "--json", "--no-progress",
            cwd=d)
    assert r.returncode == 0, r.stderr
    return d, json.loads(r.stdout)


def test_the_summary_names_the_non_defaults(weak_knee_run: tuple[Path, dict]) -> None:
    d, summary = weak_knee_run
    want = {"floor.friction": 0.7, "servo.l_knee.kp": 35.0, "servo.r_knee.kp": 30.0}   # --set after the file
    assert summary["params"] == want
    assert summary["params_digest"] == params_digest(want)
    keys = list(summary)
    assert keys.index("seed") < keys.index("params") < keys.index("params_digest") < keys.index("mode")


def test_the_recording_and_the_can_log_name_them(weak_knee_run: tuple[Path, dict]) -> None:
    from humanoid_twin.recording.readback import _chunks

    d, summary = weak_knee_run
    texts, props = [], {}
    for c in _chunks(d / "w.rrd"):
        path = str(c.entity_path)
        for row in c.to_record_batch().to_pylist():
            if path == "/params":
                texts += row["TextDocument:text"]
            elif path == "/__properties/params":
                props = {k: v[0] for k, v in row.items() if not k.startswith("rerun.")}
    assert "`servo.r_knee.kp` | 30 | 46.2614" in texts[0]
    assert props == {**summary["params"], "params_digest": summary["params_digest"]}
    head = (d / "w.asc").read_text().splitlines()[:8]
    assert f"humanoid-twin params: {json.dumps(summary['params'], sort_keys=True)}" in "\n".join(head)


def test_a_replay_rebuilds_the_same_twin(weak_knee_run: tuple[Path, dict]) -> None:
    """The serial log's meta carries the parameters: its replay answers byte for byte; the same
    log with the parameters taken out of its meta does not (they change what the robot answers)."""
    d, summary = weak_knee_run
    log = d / "w.serial"
    meta = json.loads(log.read_text().splitlines()[2].removeprefix("# meta "))
    assert meta["params"] == summary["params"]
    replay = [sys.executable, "-m", "humanoid_twin.bus.serial_log", "replay"]
    r = subprocess.run([*replay, str(log)], capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    lines = log.read_text().splitlines()
    lines[2] = "# meta " + json.dumps({k: v for k, v in meta.items() if k != "params"})
    (d / "stripped.serial").write_text("\n".join(lines) + "\n")
    r = subprocess.run([*replay, str(d / "stripped.serial")], capture_output=True, text=True, timeout=180)
    assert r.returncode == 1 and "differ" in r.stderr


@pytest.mark.parametrize("args, message", [
    (["--set", "servo.r_kne.kp=3"], "did you mean servo.r_knee.kp"),
    (["--set", "servo.*_kne.kp=3"], "matches no parameter"),
    (["--set", "floor.friction=9"], "outside its bounds"),
    (["--set", "floor.friction=nan"], "not a finite number"),
    (["--set", "floor.friction"], "expected NAME=VALUE"),
    (["--params", "missing.toml"], "no such file"),
    (["--params", "broken.toml"], "not TOML"),
    (["--pic-mhz", "20", "--set", "pic_mhz=10"], "disagree"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_replaced(tmp_path: Path, args: list[str],
                                                           message: str) -> None:
    (tmp_path / "broken.toml").write_text("[x\n")
    (tmp_path / "out.rrd").write_bytes(b"keep me")
    r = cli("run", "flexao", "--out", "out.rrd", "--can-log", "c.asc", *args, cwd=tmp_path)
    assert r.returncode == 2 and message in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert (tmp_path / "out.rrd").read_bytes() == b"keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.toml", "out.rrd"]


def test_serve_takes_them_too(tmp_path: Path) -> None:
    r = cli("serve", "--set", "servo.r_kne.kp=3", cwd=tmp_path)
    assert r.returncode == 2 and "did you mean servo.r_knee.kp" in r.stderr
    r = cli("serve", "--set", "scenario.every_s=1", cwd=tmp_path)
    assert r.returncode == 2 and "only run" in r.stderr


def test_serve_records_them_in_its_serial_log(serve, tmp_path: Path) -> None:  # noqa: ANN001 - fixture
    log = tmp_path / "s.serial"
    proc, port = serve("--tcp", "0", "--set", "floor.friction=0.5", "--serial-log", str(log))
    assert port.startswith("socket://")
    serve.stop(proc)
    meta = json.loads(log.read_text().splitlines()[2].removeprefix("# meta "))
    assert meta["params"] == {"floor.friction": 0.5}
