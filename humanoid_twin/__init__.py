"""humanoid-twin: a physics-based digital twin of the University of Aveiro humanoid's legs and of
its 2006 distributed control system (PC -> RS-232 -> Master -> CAN -> 8 Slaves -> servos)."""

from humanoid_twin.core import install_source_first, pure_python_requested, source_if_stale

__version__ = "0.1.0"

if pure_python_requested():
    # the interpreted source even where the compiled core is installed (docs/architecture.md)
    install_source_first()
else:
    # an edited module not yet rebuilt: its source, never the old compiled code (a warning says so)
    source_if_stale()


def __getattr__(name: str) -> object:
    """Imported on first use (the package's import stays light for the CLI):
    ``humanoid_twin.Twin``, the in-process twin; ``humanoid_twin.open``, a run of a scenario to
    drive from Python (:func:`humanoid_twin.scenarios.open_run`), with ``humanoid_twin.RunOptions``
    (README.md, "From Python")."""
    if name == "Twin":
        from humanoid_twin.twin import Twin

        return Twin
    if name == "open":
        from humanoid_twin.scenarios import open_run

        return open_run
    if name in ("RunOptions", "Session"):
        from humanoid_twin import scenarios

        return getattr(scenarios, name)
    raise AttributeError(f"module 'humanoid_twin' has no attribute {name!r}")
