"""The options ``run`` and ``serve`` share, from the command line to typed options.

One definition per option (:func:`add_rig_options`, :func:`add_host_controller_options`), one
check of what ``run`` and ``serve`` share (:func:`check_rig_inputs`: a bad value is one line on
stderr and exit 2, before anything is written), and the conversion of an argparse namespace to
the library's typed options (:func:`rig_fields`, :func:`run_options`): below ``cli/`` the library
takes :class:`~humanoid_twin.rig.RigOptions` / :class:`~humanoid_twin.scenarios.RunOptions` and
never reads a namespace.
"""

from __future__ import annotations

import argparse
import os
import socket
import sys
from pathlib import Path
from typing import Any

from humanoid_twin.cli.argtypes import checked, degrees
from humanoid_twin.cli.messages import usage_error
from humanoid_twin.seeds import SEED_MAX

CAN_INTERFACES = ("humanoid_twin", "virtual", "socketcan")


def cannot_write_in(directory: Path) -> str | None:
    """Why a file cannot be created in ``directory`` (an empty one is created and removed: a
    read-only mount, ``/proc``, ``/sys``, a permission), or None when it can. Checked before the
    free space, so that an unwritable place is never reported as a full disk."""
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(prefix=".humanoid-twin-probe-", dir=directory)
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:
        pass
    return None


# -- definitions -----------------------------------------------------------------------------------
def scenario_arg(text: str) -> str:
    """An argparse type for a scenario: a built-in name, an entry point's name, or a reference
    ``FILE.py:NAME`` / ``MODULE:NAME`` (imported and checked later, with the other inputs)."""
    from humanoid_twin.scenarios import (
        ENTRY_POINT_GROUP,
        REGISTRY,
        did_you_mean,
        entry_point_names,
        is_reference,
    )

    if text in REGISTRY or is_reference(text) or text in entry_point_names():
        return text
    raise argparse.ArgumentTypeError(
        f"invalid choice: {text!r} (choose from {', '.join(REGISTRY)}; or FILE.py:NAME, MODULE:NAME, "
        f"or an entry point of {ENTRY_POINT_GROUP}; docs/scenarios.md){did_you_mean(text)}")


def add_can_options(p: argparse.ArgumentParser) -> None:
    """``--can-interface``, ``--can-channel``."""
    p.add_argument("--can-interface", choices=CAN_INTERFACES, default="humanoid_twin",
                   help="python-can interface of the CAN wire (default humanoid_twin: the project's own, "
                   "frames in virtual time; socketcan needs --can-channel, e.g. vcan0, for candump)")
    p.add_argument("--can-channel", help="python-can channel (default: a fresh one; socketcan: vcan0)")
    add_pic_option(p)       # the boards' clock: --pic-mhz (humanoid_twin/cycles.py)


def add_pic_option(p: argparse.ArgumentParser) -> None:
    """``--pic-mhz F`` on ``run`` and ``serve`` (and so a ``sweep --param``)."""
    from humanoid_twin.cycles import DEFAULT_PIC_MHZ, check_pic_mhz

    def pic_mhz(text: str) -> float:
        try:
            return check_pic_mhz(float(text))
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    p.add_argument("--pic-mhz", type=pic_mhz, default=DEFAULT_PIC_MHZ, metavar="F",
                   help=f"the Slave boards' PIC18 clock in MHz (default {DEFAULT_PIC_MHZ:g}: 10 MIPS; "
                   "docs/firmware.md, cycle budget)")


def add_rig_options(p: argparse.ArgumentParser, out_help: str) -> None:
    """The options of the twin and its instruments (:class:`~humanoid_twin.rig.Rig`), the same
    for ``run`` and ``serve``: ``--out``, ``--can-log``, ``--serial-log``, ``--tilt``, ``--seed``,
    the CAN wire, ``--fault`` / ``--host-link`` and ``--law``."""
    from humanoid_twin.cli.fault_options import add_fault_options

    p.add_argument("--out", type=Path, help=out_help)
    p.add_argument("--can-log", type=Path, help="CAN log to write; format by suffix (.asc .blf .log "
                   ".csv .trc ...), python-can writers")
    p.add_argument("--serial-log", type=Path, metavar="FILE", help="log every RS-232 byte each way with its "
                   "virtual time (text); replay it with humanoid-twin replay FILE (docs/buses.md)")
    from humanoid_twin.plant.plant import TILT_MAX_DEG

    p.add_argument("--tilt", type=degrees, default=0.0, help="tilt the floor platform slowly (1 deg/s, "
                   "once the robot has booted) about the lateral axis to DEG (toes up positive; "
                   f"within +-{TILT_MAX_DEG:g})")
    p.add_argument("--seed", type=int, default=0, help="random seed (sensor noise, servo offsets, "
                   "board phases)")
    add_can_options(p)
    add_fault_options(p)
    from humanoid_twin.cli.params import add_params_options

    add_params_options(p)       # --params FILE.toml, --set NAME=VALUE (docs/parameters.md)
    add_law_option(p)


def add_law_option(p: argparse.ArgumentParser, help_more: str = "") -> None:
    """``--law TYPE=MODULE:CLASS`` (repeatable): ``run``, ``serve`` and ``replay``."""
    p.add_argument("--law", action="append", default=[], metavar="TYPE=MODULE:CLASS",
                   help="run your firmware control law for one control type (none, locomotion, reaction, "
                   "balance) on every Slave; MODULE:CLASS or an entry point of group humanoid_twin.laws; "
                   "repeatable" + help_more)


_period_ms = checked(float, "a number of milliseconds", lambda v: 1 <= v <= 10_000, "must be 1..10000 ms")


def add_host_controller_options(p: argparse.ArgumentParser) -> None:
    """``--host-controller`` and ``--host-period-ms`` (``run``; docs/controllers.md)."""
    from humanoid_twin.controllers import DEFAULT_HOST_PERIOD_MS

    p.add_argument("--host-controller", metavar="MODULE:FUNCTION",
                   help="call FUNCTION(ctx) every --host-period-ms of simulated time with the host toolbox "
                   "bound to the twin's port and the ground-truth monitor")
    p.add_argument("--host-period-ms", type=_period_ms, default=DEFAULT_HOST_PERIOD_MS, metavar="N",
                   help="period of --host-controller in ms of simulated time "
                   f"(default {DEFAULT_HOST_PERIOD_MS})")


# -- checks (one line, exit 2, before anything is written) -----------------------------------------
def check_rig_inputs(args: argparse.Namespace, load: bool = True) -> dict[str, Any]:
    """Every option ``run`` and ``serve`` share, checked the same way for both: the seed, the
    tilt, how the ``--fault`` s compose, the CAN wire, ``--out``'s suffix, ``--can-log``'s format,
    and the ``--law`` s (imported and made once). Returns the loaded controllers (the
    ``laws``, and ``run``'s ``host_controller`` and ``host_period_ms``; ``load`` False: not
    loaded again, nothing returned)."""
    from humanoid_twin.cli.params import params_from_args
    from humanoid_twin.fault_compose import check_composition
    from humanoid_twin.faults import FaultSpecError
    from humanoid_twin.plant.plant import TILT_MAX_DEG

    args.param_values = params_from_args(args)     # --params, --set: the named parameters
    try:
        check_composition(args.fault)
    except FaultSpecError as exc:
        raise usage_error(str(exc)) from None
    if not 0 <= args.seed <= SEED_MAX:
        raise usage_error(f"--seed {args.seed}: must be 0..{SEED_MAX}")
    if abs(args.tilt) > TILT_MAX_DEG:
        raise usage_error(f"--tilt {args.tilt:g}: the platform tilts within +-{TILT_MAX_DEG:g} degrees")
    _check_can_interface(args.can_interface, args.can_channel)
    check_recording_outputs(args)
    return load_controllers(args) if load else {}


def check_recording_outputs(args: argparse.Namespace) -> None:
    """``--out``'s suffix and ``--can-log``'s format (``run``, ``serve``, ``replay``)."""
    if args.out is not None and args.out.suffix != ".rrd":
        raise usage_error(f"--out {args.out}: a rerun recording must end in .rrd")
    if args.can_log is not None:
        from humanoid_twin.recording.can_log import CanLogError, check_log_path

        try:
            check_log_path(args.can_log)
        except CanLogError as exc:
            raise usage_error(f"--can-log: {exc}") from None
        except OSError:
            pass                          # the writability check of the outputs says it in one line


def _check_can_interface(interface: str, channel: str | None) -> None:
    if interface != "socketcan":
        return
    if not channel:
        raise usage_error("--can-interface socketcan needs --can-channel (e.g. vcan0)")
    if not hasattr(socket, "AF_CAN"):
        raise usage_error("--can-interface socketcan: this system has no SocketCAN (AF_CAN)")
    try:
        with socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW) as s:
            s.bind((channel,))
    except OSError as exc:
        raise usage_error(f"--can-interface socketcan --can-channel {channel}: cannot open it: "
                          f"{exc.strerror or exc} (create it: ip link add dev vcan0 type vcan)") from None


def _cwd_importable() -> None:
    """As ``python -m`` does, the current directory is importable (``--law balance=mylaw:MyLaw``
    finds ``./mylaw.py``; ``run mypkg.scenarios:push`` finds ``./mypkg``)."""
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())


def load_controllers(args: argparse.Namespace) -> dict[str, Any]:
    """The controller fields of the options: ``--law`` s (and ``run``'s ``--host-controller``),
    imported and checked before the run starts (so a bad value writes nothing); a bad one is a
    usage error."""
    from humanoid_twin.controllers import (
        ControllerError,
        LawError,
        load_host_controller,
        load_law,
        parse_law_option,
    )

    ctl = vars(args).get("host_controller")
    if args.law or ctl:
        _cwd_importable()
    laws: list[tuple[int, Any]] = []
    try:
        for text in args.law:
            ctype, ref = parse_law_option(text)
            laws.append((ctype, load_law(ref)))
        step = load_host_controller(ctl) if ctl else None
    except (LawError, ControllerError) as exc:
        raise usage_error(str(exc)) from None
    out: dict[str, Any] = {"laws": tuple(laws)}
    if "host_controller" in vars(args):
        out.update(host_controller=step, host_period_ms=args.host_period_ms)
    return out


def load_scenario_arg(ref: str) -> Any:
    """The scenario of ``run`` / ``sweep``'s argument (:func:`humanoid_twin.scenarios.load_scenario`);
    one that cannot be loaded is a usage error naming it."""
    from humanoid_twin.scenarios import ScenarioLoadError, is_reference, load_scenario, split_reference

    if is_reference(ref) and not split_reference(ref)[0].endswith(".py"):
        _cwd_importable()
    try:
        return load_scenario(ref)
    except ScenarioLoadError as exc:
        raise usage_error(str(exc)) from None


# -- conversion ------------------------------------------------------------------------------------
def rig_fields(args: argparse.Namespace, controllers: dict[str, Any]) -> dict[str, Any]:
    """The :class:`~humanoid_twin.rig.RigOptions` fields of a parsed ``run`` or ``serve``
    (``controllers``: :func:`check_rig_inputs`'s result); the outputs are set by the caller
    (they are written under temporary names)."""
    from humanoid_twin.cli.fault_options import supervisor_config

    return dict(seed=args.seed, tilt=args.tilt, can_interface=args.can_interface,
                can_channel=args.can_channel, faults=tuple(args.fault), supervisor=supervisor_config(args),
                laws=controllers["laws"], pic_mhz=args.pic_mhz, params=args.param_values)


def run_options(args: argparse.Namespace, controllers: dict[str, Any], files: dict[str, Any]) -> Any:
    """The :class:`~humanoid_twin.scenarios.RunOptions` of a parsed ``run`` (``files``: the
    output fields, the temporary names the outputs are written under:
    :meth:`humanoid_twin.cli.checked_outputs.CheckedOutputs.open_all`)."""
    from humanoid_twin.scenarios import RunOptions

    return RunOptions(
        **rig_fields(args, controllers), **files, scenario=args.scenario, duration=args.duration,
        T=args.T, motion=args.motion, perna=args.perna,
        control=args.control, progress=not args.no_progress, host_controller=controllers["host_controller"],
        host_period_ms=controllers["host_period_ms"], wall_timeout=args.wall_timeout,
        scenario_fields=dict(vars(args).get("scenario_fields") or {}),
    )
