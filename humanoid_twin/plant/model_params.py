"""The plant's named parameters (humanoid_twin/params.py, docs/parameters.md): their defaults
read from the packaged MJCF through MuJoCo's model-editing API (``MjSpec``), and their values
applied to an ``MjSpec`` before it is compiled.

The model's own numbers (a servo's ``kp``, ``damping``, ``frictionloss``, ``armature``, stall
torque; a body's mass; the floor's friction) are read here from ``humanoid.xml`` / ``scene.xml``,
never typed a second time. The sensors' parameters (a potentiometer's offset, a force sensor's
gain and zero, the IMU's bias) are added to today's numbers: their default is the identity.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import mujoco

from humanoid_twin import hardware
from humanoid_twin.params import Param
from humanoid_twin.plant import constants as C  # noqa: N812

__all__ = ["plant_params", "packaged_spec", "apply_to_spec", "MODEL_KINDS", "FLOOR_GEOMS", "FSR_SITES"]

# parameter kinds applied to the MjSpec (the others are the plant's sensors and the firmware's)
MODEL_KINDS = frozenset({"servo.kp", "servo.damping", "servo.frictionloss", "servo.armature",
                         "servo.torque_max", "floor.friction", "body.mass_scale"})
FLOOR_GEOMS = ("platform", "floor")         # the surfaces the feet stand on (scene.xml)
PAD_SUFFIXES = ("fl", "fr", "rl", "rr")      # table 12 order (plant.PAD_SUFFIXES)
FEET = ("r_foot", "l_foot")
FSR_SITES: tuple[str, ...] = tuple(f"{foot}_{s}" for foot in FEET for s in PAD_SUFFIXES)
SCALE_MIN, SCALE_MAX = 0.1, 10.0            # the bounds of a scale (x) and of a gain around its default
POT_OFFSET_MAX_DEG = 30.0
IMU_BIAS_MAX_DEG = 20.0
IMU_RATE_BIAS_MAX_DPS = 50.0


def packaged_spec() -> mujoco.MjSpec:
    """A fresh ``MjSpec`` of the packaged model (``scene.xml`` with ``humanoid.xml``)."""
    from humanoid_twin.plant.plant import DEFAULT_MODEL_NAME, MODELS, model_assets

    xml = (MODELS / DEFAULT_MODEL_NAME).read_text(encoding="utf-8")
    return mujoco.MjSpec.from_string(xml, include=model_assets())


def _bound(x: float) -> float:
    """A bound derived from a default, to 6 significant digits (462.614, not 462.61400000000003)."""
    return float(f"{x:.6g}")


def _servo_joints() -> list[str]:
    return [j for joints in hardware.SERVO_JOINTS.values() for j in joints]


def _robot_bodies(spec: mujoco.MjSpec) -> list[str]:
    """The robot's bodies, trunk first, in the model's order (not the world, not the platform)."""
    trunk = spec.body("trunk")
    return ["trunk"] + [b.name for b in trunk.find_all(mujoco.mjtObj.mjOBJ_BODY) if b.name]


@functools.cache
def plant_params() -> tuple[Param, ...]:
    """The plant's parameters, defaults read from the packaged model (once per process)."""
    spec = packaged_spec()
    out: list[Param] = []
    for j in _servo_joints():
        act, joint = spec.actuator(f"{j}_act"), spec.joint(j)
        kp, stall = float(act.gainprm[0]), float(act.forcerange[1])
        damping = float(joint.damping[0])      # the linear term (MuJoCo 4's damping is a polynomial)
        friction, armature = float(joint.frictionloss), float(joint.armature)
        rows = (
            ("kp", "N·m/rad", kp, 0.0, _bound(SCALE_MAX * kp),
             f"{j}: servo position gain, the stall torque at 3 deg of error (models/README.md section 5)"),
            ("damping", "N·m·s/rad", damping, 0.0, _bound(SCALE_MAX * damping),
             f"{j}: gear and back-EMF damping, (stall - friction) / no-load speed (HS-805BB datasheet)"),
            ("frictionloss", "N·m", friction, 0.0, _bound(SCALE_MAX * friction),
             f"{j}: gear-train dry friction (estimate, ~8 % of the stall torque)"),
            ("armature", "kg·m²", armature, 0.0, _bound(SCALE_MAX * armature),
             f"{j}: the motor's rotor inertia seen at the joint (estimate)"),
            ("torque_max", "N·m", stall, _bound(SCALE_MIN * stall), _bound(SCALE_MAX * stall),
             f"{j}: stall torque, the servo's force range (HS-805BB datasheet: 24.7 kg·cm at 6 V)"),
        )
        for field, unit, default, lo, hi, doc in rows:
            out.append(Param(f"servo.{j}.{field}", unit, default, lo, hi, doc, kind=f"servo.{field}",
                             target=j))
    for j in _servo_joints():
        out.append(Param(f"pot.{j}.offset_deg", "deg", 0.0, -POT_OFFSET_MAX_DEG, POT_OFFSET_MAX_DEG,
                         f"{j}'s potentiometer mounting offset, added to the seeded draw of "
                         f"+-{C.POT_OFFSET_RANGE_DEG:g} deg the calibration estimates (seed 000 table 8)",
                         kind="pot.offset_deg", target=j))
    for site in FSR_SITES:
        spec.site(site)         # the site exists (a model without it fails here, loudly)
        out.append(Param(f"fsr.{site}.gain", "×", 1.0, SCALE_MIN, SCALE_MAX,
                         f"{site} force sensor's scale on its {1 / hardware.FORCE_N_PER_COUNT:g} counts/N "
                         "(seed 000 table 12; hardware.FORCE_N_PER_COUNT)", kind="fsr.gain", target=site))
        out.append(Param(f"fsr.{site}.offset_counts", "counts", 0.0, -float(hardware.FORCE_ADC_MAX),
                         float(hardware.FORCE_ADC_MAX),
                         f"{site} force sensor's zero, 8-bit ADC counts added to every reading, loaded or "
                         "not (estimate; the Slave's calibration removes it, seed 000 table 12)",
                         kind="fsr.offset_counts", target=site))
    platform = spec.geom(FLOOR_GEOMS[0])
    out.append(Param("floor.friction", "1", float(platform.friction[0]), 0.01, 5.0,
                     "sliding friction between the robot and the platform or floor (scene.xml's "
                     "platform geom; set on both sides of every contact; estimate)", kind="floor.friction"))
    for b in _robot_bodies(spec):
        out.append(Param(f"body.{b}.mass_scale", "×", 1.0, SCALE_MIN, SCALE_MAX,
                         f"{b}'s mass ({float(spec.body(b).mass):g} kg in humanoid.xml; seed 000 table 13 "
                         "for the legs), its inertia scaled with it", kind="body.mass_scale", target=b))
    imu = (("roll_bias_deg", "deg", IMU_BIAS_MAX_DEG, "inclinometer roll"),
           ("pitch_bias_deg", "deg", IMU_BIAS_MAX_DEG, "inclinometer pitch"),
           ("roll_rate_bias_dps", "deg/s", IMU_RATE_BIAS_MAX_DPS, "gyroscope roll rate"),
           ("pitch_rate_bias_dps", "deg/s", IMU_RATE_BIAS_MAX_DPS, "gyroscope pitch rate"))
    for axis, unit, hi, what in imu:
        out.append(Param(f"imu.{axis}", unit, 0.0, -hi, hi,
                         f"the body board's {what} bias, added to its input (estimate; seed 002 slide 3, "
                         "docs/firmware.md)", kind=f"imu.{axis}"))
    return tuple(out)


def apply_to_spec(spec: mujoco.MjSpec, values: Mapping[str, float]) -> None:
    """Set the model's parameters among ``values`` (checked names) on ``spec`` (before compiling)."""
    from humanoid_twin.params import registry

    reg = registry()
    for name, v in values.items():
        p = reg.get(name)
        kind, target = p.kind, p.target
        if kind == "servo.kp":
            act = spec.actuator(f"{target}_act")
            act.gainprm[0] = v
            act.biasprm[1] = -v
        elif kind == "servo.torque_max":
            spec.actuator(f"{target}_act").forcerange = [-v, v]
        elif kind == "servo.damping":
            spec.joint(target).damping[0] = v      # the linear term (MuJoCo 4's damping is a polynomial)
        elif kind in ("servo.frictionloss", "servo.armature"):
            setattr(spec.joint(target), kind.split(".")[1], v)
        elif kind == "body.mass_scale":
            body = spec.body(target)
            body.mass = body.mass * v
            body.inertia = [x * v for x in body.inertia]
        elif kind == "floor.friction":
            _set_floor_friction(spec, v)


def _set_floor_friction(spec: mujoco.MjSpec, mu: float) -> None:
    """Sliding friction ``mu`` on the floor geoms and every robot geom that collides with them
    (MuJoCo takes the larger of the two geoms' friction: both sides get it)."""
    floors = [spec.geom(g) for g in FLOOR_GEOMS]
    mask = 0
    for g in floors:
        g.friction[0] = mu
        mask |= int(g.conaffinity)
    for g in spec.worldbody.find_all(mujoco.mjtObj.mjOBJ_GEOM):
        if int(g.contype) & mask:
            g.friction[0] = mu
