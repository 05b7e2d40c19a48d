"""The robot: the only code that touches MuJoCo state.

What each Slave board sees and does on its servo and sensor cables (seed 000 section 3, module
PIC2: ``servoActuation``, ``updateServoMeasures``, ``sampleExtraSensors``), implemented on the
MuJoCo model shipped in the package, ``humanoid_twin/models/`` (its README.md gives the source of
every number; docs/model.md). Ground truth (for recording and tests) is computed in
``plant/truth.py``, the drawing geometry and the viewer window in ``plant/drawing.py``; the
:class:`Plant` syncs its physics to its clock before it hands either out.

The boards' reads (``read_servos``, ``read_force_adc``, ``read_imu_adc``, about 550 times per
simulated second) and the physics sync before them (``advance_to``) are compiled: they are
inherited from :class:`~humanoid_twin.plant.sensors.BoardIO` (plant/sensors.py), and use
precomputed addresses and pre-drawn noise; ``advance_to`` runs all the physics steps due in one
``mj_step`` call.
"""

from __future__ import annotations

import contextlib
import math
import numbers
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from functools import partial
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from humanoid_twin import hardware
from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import DEG_PER_RAD as _DEG_PER_RAD
from humanoid_twin.plant import constants as C  # noqa: N812
from humanoid_twin.plant.drawing import WXYZ_TO_XYZW, Drawing, GeomInfo, ViewerWindow  # noqa: F401 (recorder)
from humanoid_twin.plant.imu import TrunkImu
from humanoid_twin.plant.sensors import BoardIO, PlantError, PlantInputError, SensorFrontEnd, _check_scu  # noqa: F401 (re-exported)
from humanoid_twin.plant.truth import FOOT_BODIES, GroundTruth, TruthProbe
from humanoid_twin.protocol.wire import N_SCU, POS_LIMIT_DEG

if TYPE_CHECKING:
    from humanoid_twin.clock import Clock

# The model ships inside the package (MuJoCo Menagerie / dm_control style) and is read with
# importlib.resources, so `pip install .` (a wheel), `pip install -e .` and a source tree all load
# the same files; the top-level `models/` of the repository is a symlink to this folder.
MODELS = resources.files("humanoid_twin") / "models"
DEFAULT_MODEL_NAME = "scene.xml"
DEFAULT_MODEL = Path(str(MODELS / DEFAULT_MODEL_NAME))   # where it is on disk (an installed package)

PAD_SUFFIXES: tuple[str, str, str, str] = ("fl", "fr", "rl", "rr")   # table 12 order
HOLD_LIFT_MM = 100.0               # compare --support stand: the trunk held this high above its stand pose
HOLD_ARMATURE = 1e9                # ... by an armature that makes its free joint immovable
TILT_MAX_DEG = 45.0                # the platform tilts at most this far (either way)
_TILT_MAX_DEG = TILT_MAX_DEG
# MuJoCo's instability warnings: (MjData.warning index, the quantity it found non-finite or huge)
_INSTABILITY = tuple((int(getattr(mujoco.mjtWarning, f"mjWARN_BAD{q}")), q) for q in ("QPOS", "QVEL", "QACC"))
_TILT_PROFILE_CHUNK_US = 10_000    # a tilt profile is re-evaluated at least every 10 ms


def model_assets() -> dict[str, bytes]:
    """Every file of the packaged model folder, by name (the ``assets`` of ``MjModel.from_xml_string``)."""
    return {f.name: f.read_bytes() for f in MODELS.iterdir() if f.is_file() and f.name.endswith(".xml")}


def _route_mujoco_warnings() -> None:
    """MuJoCo's default warning handler appends to ``MUJOCO_LOG.TXT`` in the current directory and
    prints on C stdout (after the run's last line). Unless the caller installed a handler of its
    own, send each warning to stderr as one line instead: nothing is left in the user's folder."""
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_warn_on_stderr)


# MuJoCo's instability warnings (a NaN, an infinite or a huge value in the state: it then resets
# the state) are not written while a run reports them itself (``quiet_instability_warnings``:
# ``scenarios.run`` ends with ``outcome: diverged`` and one line built from ``Plant.divergence``)
_UNSTABLE_TEXT = "simulation is unstable"
_quiet_instability = [0]


@contextlib.contextmanager
def quiet_instability_warnings() -> Iterator[None]:
    """Within the block, MuJoCo's instability warnings are not written to stderr: the caller reports
    the divergence itself (:meth:`Plant.divergence`)."""
    _quiet_instability[0] += 1
    try:
        yield
    finally:
        _quiet_instability[0] -= 1


def _warn_on_stderr(message: str) -> None:
    text = " ".join(message.split())
    if _quiet_instability[0] and _UNSTABLE_TEXT in text:
        return
    sys.stderr.write(f"humanoid-twin: MuJoCo warning: {text}\n")


def _load_model(path: Path | None, params: Mapping[str, float] | None = None
                ) -> tuple[mujoco.MjModel, list[str]]:
    """The model at ``path`` (None: the packaged one) as it is, or, with ``params`` (the model's
    non-default parameters, plant/model_params.py), edited through ``MjSpec`` before compiling."""
    if path is not None and not path.is_file():
        raise PlantError(f"MuJoCo model file not found: {path}")
    warnings: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(warnings.append)
    try:
        if params:
            from humanoid_twin.plant.model_params import apply_to_spec, packaged_spec

            spec = packaged_spec() if path is None else mujoco.MjSpec.from_file(str(path))
            apply_to_spec(spec, params)
            model = spec.compile()
        elif path is None:
            xml = (MODELS / DEFAULT_MODEL_NAME).read_text(encoding="utf-8")
            model = mujoco.MjModel.from_xml_string(xml, assets=model_assets())
        else:
            model = mujoco.MjModel.from_xml_path(str(path))
    except Exception as exc:  # mujoco raises ValueError with the compiler's message
        raise PlantError(f"cannot load MuJoCo model {path or DEFAULT_MODEL}: {exc}") from exc
    finally:
        mujoco.set_mju_user_warning(previous)
    return model, warnings


def _named_params(params: Mapping[str, float] | None
                  ) -> tuple[dict[str, float], dict[str, dict[str, float]], dict[str, float]]:
    """The named parameters checked (:class:`~humanoid_twin.params.ParamError` on a bad one): the
    non-default ones, by kind (kind -> target -> value), and the model's own (set through MjSpec)."""
    by_kind: dict[str, dict[str, float]] = {}
    model_values: dict[str, float] = {}
    if not params:
        return {}, by_kind, model_values
    from humanoid_twin.params import registry
    from humanoid_twin.plant.model_params import MODEL_KINDS

    reg = registry()
    non_defaults = reg.non_defaults(reg.check(params))
    for name, v in non_defaults.items():
        p = reg.get(name)
        by_kind.setdefault(p.kind, {})[p.target] = v
        if p.kind in MODEL_KINDS:
            model_values[name] = v
    return non_defaults, by_kind, model_values


def _need(m: Any, path: Path, kind: mujoco.mjtObj, name: str) -> int:
    """The id of the ``kind`` named ``name`` in model ``m`` (read from ``path``); PlantError when
    it has none."""
    idx = mujoco.mj_name2id(m, kind, name)
    if idx < 0:
        raise PlantError(f"{path}: the model has no {kind.name[6:].lower()} named {name!r}")
    return idx


def _check_pulses(scu: int, pulses_us: Sequence[int | None]) -> None:
    """Three pulse widths, each :data:`_PULSE_MIN_US`..:data:`_PULSE_MAX_US` us or None."""
    try:
        n = len(pulses_us)
    except TypeError:
        n = -1
    if n != hardware.N_SERVOS:
        raise PlantInputError(f"SCU {scu}: need a sequence of 3 pulses, got {pulses_us!r}")
    lo = _PULSE_MIN_US
    hi = _PULSE_MAX_US
    for p in pulses_us:
        if p is not None and (isinstance(p, bool) or not isinstance(p, numbers.Real)
                              or not lo <= p <= hi):
            raise PlantInputError(f"SCU {scu}: pulse width must be {lo}..{hi} us or None, got {p!r}")


class Plant(BoardIO):
    """The MuJoCo robot as the Slave boards see it (servo cables and foot sensors).

    ``Plant()`` loads the packaged ``humanoid_twin/models/scene.xml`` and resets to the ``stand``
    keyframe with every PWM off (limp servos, as at power-up). ``seed`` fixes the potentiometer
    offsets (drawn once per plant) and the sensor noise streams (restarted by ``reset``).
    ``clock`` (or ``bind_clock``) puts physics time under the twin's clock: the plant then steps
    itself before any access. ``params``: named parameters (humanoid_twin/params.py, names or
    globs -> values; :class:`~humanoid_twin.params.ParamError` on a bad one): the model's set
    through ``MjSpec`` before it is compiled, the sensors' on their electronics; none (or every
    one at its default): the packaged model exactly as it is. :attr:`params` keeps the
    non-default ones.
    """

    def __init__(self, model_path: str | Path | None = None, *, seed: int = 0, clock: Clock | None = None,
                 params: Mapping[str, float] | None = None) -> None:
        _route_mujoco_warnings()
        given = Path(model_path) if model_path is not None else None
        path = given if given is not None else DEFAULT_MODEL
        self.model_path = path
        self.params, by_kind, model_values = _named_params(params)
        self.model, self.load_warnings = _load_model(given, model_values)
        self.data = mujoco.MjData(self.model)
        self.seed = int(seed)
        m = self.model
        ts_us = m.opt.timestep * US_PER_S
        self.timestep_us: int = round(ts_us)
        if self.timestep_us <= 0 or abs(ts_us - self.timestep_us) > 1e-6:
            raise PlantError(f"{path}: timestep {m.opt.timestep} s is not a whole number of microseconds")
        self.t_us: int = 0
        self._clock: Clock | None = clock
        self.step_ns_total = 0      # wall time spent in mj_step (boards subtract it from their task time)

        need = partial(_need, m, path)
        self._find_servos(need)
        self._powered = [True] * m.nu
        self._find_feet(need)
        self._truth = self._truth_probe()
        self._drawing = Drawing(m, self.data, self._pad_of_geom)
        # the boards' ADC front end (compiled): reads these MjData arrays in C
        d = self.data
        self._sense = SensorFrontEnd(d.qpos, d.qvel, d.actuator_force, d.sensordata)
        self._qpos = d.qpos         # MjData's own arrays (fixed for its life): the truth's cache key
        self._qvel = d.qvel

        # the hardware: potentiometer offsets, drawn once per plant (what calibration estimates)
        ss = np.random.SeedSequence(self.seed)
        s_hw, self._s_pot, self._s_force = ss.spawn(3)
        offsets = np.random.default_rng(s_hw).uniform(-C.POT_OFFSET_RANGE_DEG, C.POT_OFFSET_RANGE_DEG,
                                                      size=(N_SCU, hardware.N_SERVOS))
        self.pot_b_true_deg: dict[int, tuple[float, float, float]] = {
            scu: tuple(hardware.POT_B_NOMINAL_DEG + float(o) for o in offsets[scu - 1])  # type: ignore[misc]
            for scu in hardware.SERVO_JOINTS
        }
        self._set_sensor_params(by_kind, need)
        self._tilt_deg = 0.0
        self._tilt_profile: Callable[[float], float] | None = None
        # injected faults (humanoid_twin/faults.py, docs/supervisor.md): extra force noise,
        # frozen force sensors, jammed servos
        self._force_fault = False
        self._force_noise_counts = 0
        self._force_fault_rng = np.random.default_rng(ss.spawn(1)[0])
        # the body board's inclinometer and gyroscope, with their biases (imu.*_bias_*)
        bias = tuple(by_kind.get(f"imu.{b}", {}).get("", 0.0) for b in _IMU_BIASES)
        self._imu = TrunkImu(m, ss.spawn(1)[0], self._sense, bias=bias if any(bias) else None)  # type: ignore[arg-type]  # four biases
        self._force_stuck: dict[int, list[int] | None] = {}
        self._stuck_actuators: set[int] = set()
        self.reset()

    def _find_servos(self, need: Callable[[mujoco.mjtObj, str], int]) -> None:
        """Each SCU's three servos in the model: (qpos adr, dof adr, actuator id, sign, stall,
        damping) x 3, and each actuator's gain."""
        m, path = self.model, self.model_path
        self._servo: dict[int, tuple[tuple[int, int, int, int, float, float], ...]] = {}
        self._kp = np.zeros(m.nu)
        for scu, joints in hardware.SERVO_JOINTS.items():
            rows = []
            for joint in joints:
                j = need(mujoco.mjtObj.mjOBJ_JOINT, joint)
                a = need(mujoco.mjtObj.mjOBJ_ACTUATOR, f"{joint}_act")
                if m.actuator_trnid[a, 0] != j:
                    raise PlantError(f"{path}: actuator {joint}_act does not drive joint {joint}")
                stall = float(m.actuator_forcerange[a, 1])
                if not m.actuator_forcelimited[a] or stall <= 0:
                    raise PlantError(f"{path}: actuator {joint}_act needs a forcerange (stall torque)")
                self._kp[a] = m.actuator_gainprm[a, 0]
                rows.append((int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j]), a, C.SERVO_SIGN[joint],
                             stall, float(m.dof_damping[m.jnt_dofadr[j]])))
            self._servo[scu] = tuple(rows)

    def _find_feet(self, need: Callable[[mujoco.mjtObj, str], int]) -> None:
        """The trunk, the platform (a mocap body), and the feet: body, sole site, pad geoms and
        touch sensor addresses (table 12 order)."""
        m, path = self.model, self.model_path
        self._trunk = need(mujoco.mjtObj.mjOBJ_BODY, "trunk")
        self._platform_mocap = int(m.body_mocapid[need(mujoco.mjtObj.mjOBJ_BODY, "platform")])
        if self._platform_mocap < 0:
            raise PlantError(f"{path}: body 'platform' must be a mocap body")
        self._sole_site: dict[str, int] = {}
        self._touch_adr: dict[str, tuple[int, int, int, int]] = {}
        self._pad_of_geom: dict[int, tuple[int, int]] = {}
        for f, foot in enumerate(FOOT_BODIES):
            need(mujoco.mjtObj.mjOBJ_BODY, foot)
            self._sole_site[foot] = need(mujoco.mjtObj.mjOBJ_SITE, f"{foot}_sole")
            adrs = []
            for p, suffix in enumerate(PAD_SUFFIXES):
                g = need(mujoco.mjtObj.mjOBJ_GEOM, f"{foot}_pad_{suffix}")
                self._pad_of_geom[g] = (f, p)
                s = need(mujoco.mjtObj.mjOBJ_SENSOR, f"{foot}_{suffix}_touch")
                adrs.append(int(m.sensor_adr[s]))
            self._touch_adr[foot] = tuple(adrs)  # type: ignore[assignment]

    def _truth_probe(self) -> TruthProbe:
        """The ground truth's probe on the model: the soles, the pads, the hinge joints."""
        m = self.model
        self._sole_sites = [self._sole_site[foot] for foot in FOOT_BODIES]
        self._foot_touch_of_scu = {scu: self._touch_adr[foot] for scu, foot in hardware.FOOT_OF_SCU.items()}
        hinges = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        self._joint_names = [m.joint(j).name for j in hinges]
        self._joint_qadr = np.array([m.jnt_qposadr[j] for j in hinges], dtype=np.int64)
        # pad index 0..7 (foot * 4 + table-12 index) of every geom, -1 for the other geoms
        pad_list: list[int] = [-1] * m.ngeom
        for g, (f, k) in self._pad_of_geom.items():
            pad_list[g] = 4 * f + k
        return TruthProbe(m, self.data, trunk=self._trunk, sole_sites=self._sole_sites,
                          pad_list=pad_list, joint_names=self._joint_names, joint_qadr=self._joint_qadr)

    def _set_sensor_params(self, by_kind: dict[str, dict[str, float]],
                           need: Callable[[mujoco.mjtObj, str], int]) -> None:
        """The named parameters of the sensors: potentiometer offsets (added to the draw), the
        force sensors' gains and zeros."""
        pot_offsets = by_kind.get("pot.offset_deg", {})     # pot.JOINT.offset_deg: added to the draw
        if pot_offsets:
            for scu, joints in hardware.SERVO_JOINTS.items():
                self.pot_b_true_deg[scu] = tuple(  # type: ignore[assignment]  # 3 servos
                    b + pot_offsets.get(j, 0.0)
                    for b, j in zip(self.pot_b_true_deg[scu], joints, strict=True))
        gains, zeros = by_kind.get("fsr.gain", {}), by_kind.get("fsr.offset_counts", {})
        for site in {*gains, *zeros}:                      # fsr.SITE.gain / offset_counts
            s = need(mujoco.mjtObj.mjOBJ_SENSOR, f"{site}_touch")
            self._sense.set_force_calibration(int(self.model.sensor_adr[s]), gains.get(site, 1.0),
                                              zeros.get(site, 0.0))

    # --- state --------------------------------------------------------------------------------
    def reset(self, keyframe: str = "stand") -> None:
        """Reset to ``keyframe`` at t = 0, every PWM off, platform level, noise restarted."""
        m = self.model
        k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, keyframe)
        if k < 0:
            names = [m.key(i).name for i in range(m.nkey)]
            raise PlantInputError(f"unknown keyframe {keyframe!r}; the model has {names}")
        mujoco.mj_resetDataKeyframe(m, self.data, k)
        self._epoch = getattr(self, "_epoch", 0) + 1
        self._truth_key: tuple | None = None
        self.data.time = 0.0
        self.t_us = 0
        for a in range(m.nu):
            self._set_powered(a, False)
        self._tilt_profile = None
        self._tilt_grid_us: int | None = None
        self._apply_tilt(0.0)
        self._pot_rng = np.random.default_rng(self._s_pot)
        self._force_rng = np.random.default_rng(self._s_force)
        self._pot_noise: list[float] = []
        self._force_noise: list[float] = []
        if hasattr(self, "_imu"):
            self._imu.reset()
        mujoco.mj_forward(m, self.data)

    def bind_clock(self, clock: Clock | None) -> None:
        """Put physics time under ``clock`` (anything with ``now_us``): from now on every read or
        write of the plant first runs the physics due up to ``clock.now_us``, in this one place.

        The result is the same as stepping physics as clock events, without a Python call per
        physics step: nobody outside the plant drags it along by hand.
        """
        self._clock = clock

    @property
    def clock(self) -> Any:
        """The clock that owns physics time (None: stepped only by explicit ``advance_to``)."""
        return self._clock

    def _advance_with_profile(self, k: int) -> None:
        """``advance_to``'s ``k`` steps under a tilt profile: on its 10 ms grid of physics time."""
        grid = _TILT_PROFILE_CHUNK_US
        ts = self.timestep_us
        while k > 0:
            g = self.t_us - self.t_us % grid
            if self._tilt_grid_us != g:
                self._apply_tilt(self._tilt_profile(g / US_PER_S))  # type: ignore[misc]  # set with the profile
                self._tilt_grid_us = g
            n = min(k, max(1, -(-(g + grid - self.t_us) // ts)))
            mujoco.mj_step(self.model, self.data, nstep=n)
            self.t_us += n * ts
            k -= n

    # --- the platform -----------------------------------------------------------------------------
    def set_tilt_deg(self, deg: float) -> None:
        """Tilt the platform about the world lateral (y) axis, toes up positive (cancels a profile)."""
        self._sync()
        self._tilt_profile = None
        self._apply_tilt(deg)

    def set_tilt_profile(self, fn: Callable[[float], float] | None) -> None:
        """Tilt the platform as ``fn(t_s) -> deg`` (evaluated in ``advance_to``); None stops it."""
        self._sync()
        if fn is not None and not callable(fn):
            raise PlantInputError(f"tilt profile must be a callable t_s -> deg, got {fn!r}")
        self._tilt_profile = fn
        self._tilt_grid_us = None

    @property
    def tilt_deg(self) -> float:
        """Current platform tilt (degrees, toes up positive)."""
        return self._tilt_deg

    def _apply_tilt(self, deg: float) -> None:
        try:
            deg = float(deg)
        except (TypeError, ValueError):
            raise PlantInputError(f"tilt must be a number of degrees, got {deg!r}") from None
        if not math.isfinite(deg) or abs(deg) > _TILT_MAX_DEG:
            raise PlantInputError(f"tilt must be within +-{_TILT_MAX_DEG} deg, got {deg}")
        half = -math.radians(deg) / 2.0     # toes up = rotation about -y
        self.data.mocap_quat[self._platform_mocap] = (math.cos(half), 0.0, math.sin(half), 0.0)
        self._tilt_deg = deg

    # --- what a Slave board sees and does ----------------------------------------------------------
    @staticmethod
    def scu_joint_names(scu: int) -> tuple[str, str, str]:
        """The joints driven by servos 0..2 of board ``scu`` (hardware.SERVO_JOINTS)."""
        _check_scu(scu)
        return hardware.SERVO_JOINTS[scu]

    def _set_powered(self, a: int, on: bool) -> None:
        kp = self._kp[a] if on else 0.0
        self.model.actuator_gainprm[a, 0] = kp
        self.model.actuator_biasprm[a, 1] = -kp
        self._powered[a] = on

    def set_pwm(self, scu: int, pulses_us: Sequence[int | None]) -> None:
        """PWM high time of the three servos of ``scu`` (PIC2 ``servoActuation``/``statusPWM``).

        A pulse of 600..2400 us commands -90..90 degrees (``hardware.deg_from_pulse``); ``None``
        switches that servo's PWM off (the servo goes limp: no actuator torque, only its gear
        friction and damping remain).
        """
        self._sync()
        rows = self._servo.get(scu) if type(scu) is int else None
        if rows is None:
            _check_scu(scu)
        _check_pulses(scu, pulses_us)
        ctrl = self.data.ctrl
        powered = self._powered
        stuck = self._stuck_actuators
        for (_, _, a, sign, _, _), p in zip(rows, pulses_us, strict=True):  # type: ignore[arg-type]  # the servo table's rows
            if stuck and a in stuck:
                continue
            if p is None:
                if powered[a]:
                    self._set_powered(a, False)
                continue
            ctrl[a] = sign * (p - hardware.PULSE_CENTER_US) * _RAD_PER_US
            if not powered[a]:
                self._set_powered(a, True)

    def trunk_attitude_deg(self) -> tuple[float, float, float, float]:
        """Ground truth: the trunk's roll, pitch (deg) and body rates (deg/s) at the IMU site."""
        self._sync()
        return self._imu.true_attitude()

    # --- injected faults (humanoid_twin/faults.py) --------------------------------------------------
    def _faulty_forces(self, scu: int, out: list[int]) -> list[int]:
        if scu in self._force_stuck:
            held = self._force_stuck[scu]
            if held is None:
                self._force_stuck[scu] = held = list(out)
            return list(held)
        n = self._force_noise_counts
        if n:
            top = hardware.FORCE_ADC_MAX
            extra = self._force_fault_rng.integers(-n, n + 1, size=len(out))
            out = [min(max(v + int(e), 0), top) for v, e in zip(out, extra, strict=True)]
        return out

    def _update_force_fault(self) -> None:
        self._force_fault = bool(self._force_noise_counts or self._force_stuck)

    def set_force_noise(self, counts: int) -> None:
        """Fault injection: add uniform noise of +-``counts`` 8-bit ADC counts to every force
        sensor reading (seeded by the plant's seed); 0 removes it."""
        self._sync()
        top = hardware.FORCE_ADC_MAX
        if isinstance(counts, bool) or not isinstance(counts, int) or not 0 <= counts <= top:
            raise PlantInputError(f"force noise must be 0..{hardware.FORCE_ADC_MAX} counts, got {counts!r}")
        self._force_noise_counts = counts
        self._update_force_fault()

    def set_force_stuck(self, scu: int, stuck: bool = True) -> None:
        """Fault injection: the four force sensors of the foot of ``scu`` freeze at their next
        reading (True) or work again (False)."""
        self._sync()
        if scu not in self._foot_touch_of_scu:
            feet = sorted(self._foot_touch_of_scu)
            raise PlantInputError(f"SCU {scu!r} has no force-sensing foot ({feet})")
        if stuck:
            self._force_stuck.setdefault(scu, None)
        else:
            self._force_stuck.pop(scu, None)
        self._update_force_fault()

    def set_servo_stuck(self, scu: int, i: int, stuck: bool = True) -> None:
        """Fault injection: servo ``i`` (0..2) of ``scu`` jams where its shaft is now (its pulses
        are ignored; it keeps holding that angle) until ``stuck`` is False."""
        self._sync()
        _check_scu(scu)
        if not isinstance(i, int) or not 0 <= i < hardware.N_SERVOS:
            raise PlantInputError(f"servo index must be 0..{hardware.N_SERVOS - 1}, got {i!r}")
        qadr, _, a, _, _, _ = self._servo[scu][i]
        if stuck:
            self.data.ctrl[a] = float(self.data.qpos[qadr])
            self._stuck_actuators.add(a)
        else:
            self._stuck_actuators.discard(a)

    def set_trunk_force(self, forward_n: float) -> None:
        """Fault injection: a horizontal force (N) on the trunk's centre of mass, world forward
        (+x; negative: backward); 0 removes it."""
        self._sync()
        f = float(forward_n)
        if not math.isfinite(f):
            raise PlantInputError(f"trunk force must be finite, got {forward_n!r}")
        self.data.xfrc_applied[self._trunk, :] = 0.0
        self.data.xfrc_applied[self._trunk, 0] = f

    def hold_trunk(self, lift_mm: float = HOLD_LIFT_MM) -> None:
        """Hold the trunk in the air, as on a test stand (``compare --support stand``): the trunk
        is raised by ``lift_mm`` (the feet clear the floor) and its free joint given an armature of
        :data:`HOLD_ARMATURE` (kg, kg.m2) on each of its six degrees of freedom, so that whatever
        the legs do the trunk does not move (its acceleration is the forces over 1e9: under a
        micrometre in a minute). Call before the first step; it stays held."""
        self._sync()
        m, d = self.model, self.data
        j = int(m.body_jntadr[self._trunk])
        if j < 0 or m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            raise PlantError("hold_trunk: the model's trunk has no free joint")
        q, v = int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
        m.dof_armature[v:v + 6] = HOLD_ARMATURE
        d.qpos[q + 2] += float(lift_mm) / 1000.0
        d.qvel[v:v + 6] = 0.0
        mujoco.mj_forward(m, d)

    def servo_angle_deg(self, scu: int, i: int) -> float:
        """True shaft angle of servo ``i`` (0..2) of ``scu``, servo frame, degrees (ground truth)."""
        self._sync()
        _check_scu(scu)
        if not isinstance(i, int) or not 0 <= i < hardware.N_SERVOS:
            raise PlantInputError(f"servo index must be 0..{hardware.N_SERVOS - 1}, got {i!r}")
        qadr, _, _, sign, _, _ = self._servo[scu][i]
        return sign * float(self.data.qpos[qadr]) * _DEG_PER_RAD

    def set_external_torque(self, joint: str, torque_nm: float) -> None:
        """Apply a constant external torque (N.m, about the joint axis) to ``joint``: a load on
        its servo for bench experiments and fault injection. 0 removes it."""
        self._sync()
        j = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, joint) if isinstance(joint, str) else -1
        if j < 0 or self.model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            raise PlantInputError(f"no servo joint named {joint!r}")
        torque = float(torque_nm)
        if not math.isfinite(torque):
            raise PlantInputError(f"external torque must be finite, got {torque_nm!r}")
        self.data.qfrc_applied[self.model.jnt_dofadr[j]] = torque

    def servo_powered(self, scu: int, i: int) -> bool:
        """Whether servo ``i`` of ``scu`` currently receives PWM."""
        self._sync()
        _check_scu(scu)
        return self._powered[self._servo[scu][i][2]]

    def keyframe_pulses(self, keyframe: str = "stand") -> dict[int, list[int]]:
        """PWM pulses (us, per SCU) that hold the joint angles of ``keyframe`` (whole degrees)."""
        m = self.model
        k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, keyframe)
        if k < 0:
            raise PlantInputError(f"unknown keyframe {keyframe!r}")
        qpos = m.key_qpos[k]
        return {
            scu: [hardware.pulse_from_deg(round(sign * math.degrees(qpos[qadr])))
                  for qadr, _, _, sign, _, _ in rows]
            for scu, rows in self._servo.items()
        }

    # --- ground truth ------------------------------------------------------------------------------
    def truth(self) -> GroundTruth:
        """Ground truth of the current state.

        Pad forces and CoPs come from the MuJoCo contact forces of the pad/ground contacts (their
        normal component, as ``mj_contactForce`` gives it), not from the touch sensors. Computed
        once per physics instant (the monitor and the recorder ask at the same instants).
        """
        self._sync()
        key = (self.t_us, self._tilt_deg, self._epoch, self._qpos.tobytes(), self._qvel.tobytes())
        if self._truth_key == key:
            return self._truth_cached  # type: ignore[has-type]  # set with _truth_key
        self._truth_cached = self._truth.compute(self.t_us, self._tilt_deg)
        self._truth_key = key
        return self._truth_cached

    def divergence(self) -> str | None:
        """Why the physics is no longer a simulation, or None while it is one: MuJoCo found a NaN,
        an infinite or a huge value in the positions, velocities or accelerations (its instability
        warning; it then resets the state, which is no continuation of the run: its counters in
        ``MjData.warning`` stay), or the state holds a non-finite number. A few counters and one
        finiteness test: the monitor asks once per 20 ms sample, never per event."""
        self._sync()
        warning = self.data.warning
        for kind, what in _INSTABILITY:
            w = warning[kind]
            if w.number:
                return (f"MuJoCo: NaN, Inf or huge value in {what} at DOF {w.lastinfo} (its instability "
                        "warning; the state was reset)")
        if not (np.isfinite(self.data.qpos).all() and np.isfinite(self.data.qvel).all()):
            return "a non-finite position or velocity in the state"
        return None

    def soles_on_surface_mm(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Where each foot's sole origin is on the platform, in the platform's own frame (mm,
        x forward along its surface, y left, and its height above the surface; ``FOOT_BODIES``
        order): a foot sliding on the platform moves in x, y; a platform tilting under a still
        foot does not move it (``slip_mm`` of a run)."""
        self._sync()
        return self._truth.soles_on_surface_mm(self._tilt_deg)

    def foot_cop_mm(self, foot: str) -> np.ndarray | None:
        """Ground-truth CoP of one foot (foot frame, mm), None when unloaded: the part of
        :meth:`truth` a per-tick comparison needs, without the rest."""
        cop = self.foot_cop_xy_mm(foot)
        return None if cop is None else np.array(cop)

    def foot_cop_xy_mm(self, foot: str) -> tuple[float, float] | None:
        """:meth:`foot_cop_mm` as two floats (x, y), no array made: for a caller that computes
        with them (the run monitor compares them with the firmware's at every leg-board tick)."""
        self._sync()
        f = _FOOT_INDEX.get(foot) if isinstance(foot, str) else None
        if f is None:
            raise PlantInputError(f"unknown foot {foot!r}; the feet are {', '.join(FOOT_BODIES)}")
        return self._truth.foot_cop_xy(f)

    # --- drawing ----------------------------------------------------------------------------------
    def body_poses(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """Names, world positions (n, 3) and quaternions (n, 4, xyzw) of every body but the world."""
        self._sync()
        return self._drawing.body_poses()

    def body_pose_views(self) -> tuple[np.ndarray, np.ndarray]:
        """Live views (no copy) of the world positions (n, 3) and quaternions (n, 4, MuJoCo's order
        w x y z; ``[:, WXYZ_TO_XYZW]`` gives x y z w) of every body but the world, in
        :meth:`body_poses` order: they follow the plant as it steps, so a caller copies them at
        the instant it wants (with the plant synced to its clock: after :meth:`truth`, say)."""
        return self._drawing.body_pose_views()

    def geometry(self) -> list[GeomInfo]:
        """The geoms to draw: visual geoms (group 2), force-sensor pads, platform and floor.

        Poses are local to the body (``body_poses`` gives the body's world pose); the floor and
        the other world geoms are in the world body ``world``.
        """
        return self._drawing.geometry()

    def open_viewer(self) -> ViewerWindow:
        """MuJoCo's passive viewer window on this plant (``humanoid-twin run --viewer``): its
        :meth:`~ViewerWindow.draw` shows the robot with the physics run up to the clock's now.
        :class:`~humanoid_twin.plant.drawing.ViewerWindowError` when no window can be opened."""
        return ViewerWindow(self.model, self.data, self._sync)

    # --- frames --------------------------------------------------------------------------------------
    def _sole(self, side: str) -> int:
        foot = _SIDES.get(side)
        if foot is None:
            raise PlantInputError(f"foot side must be one of {sorted(_SIDES)}, got {side!r}")
        return self._sole_site[foot]

    def foot_frame_to_world(self, side: str, xy_mm: Sequence[float]) -> np.ndarray:
        """World point (m, (3,)) of a point ``xy_mm`` of the foot frame (on the sole plane)."""
        s = self._sole(side)
        local = np.array([xy_mm[0], xy_mm[1], 0.0], dtype=float) / 1000.0
        return self.data.site_xpos[s] + self.data.site_xmat[s].reshape(3, 3) @ local

    def world_to_foot_frame(self, side: str, p_world: Sequence[float]) -> np.ndarray:
        """Foot-frame xy (mm, (2,)) of a world point (m), projected on the sole plane."""
        s = self._sole(side)
        rel = np.asarray(p_world, dtype=float)[:3] - self.data.site_xpos[s]
        return (rel @ self.data.site_xmat[s].reshape(3, 3))[:2] * 1000.0


_RAD_PER_US = math.radians(1.0) / hardware.PULSE_US_PER_DEG
_PULSE_MIN_US = hardware.pulse_from_deg(-POS_LIMIT_DEG)
_PULSE_MAX_US = hardware.pulse_from_deg(POS_LIMIT_DEG)
_FOOT_INDEX = {foot: f for f, foot in enumerate(FOOT_BODIES)}
# the IMU's bias parameters (imu.NAME), in TrunkImu's order
_IMU_BIASES = ("roll_bias_deg", "pitch_bias_deg", "roll_rate_bias_dps", "pitch_rate_bias_dps")
_SIDES = {"r": "r_foot", "right": "r_foot", "r_foot": "r_foot",
          "l": "l_foot", "left": "l_foot", "l_foot": "l_foot"}
