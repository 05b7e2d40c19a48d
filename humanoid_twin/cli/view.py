"""``humanoid-twin view FILE.rrd``: a recording in the rerun viewer shipped with rerun-sdk."""

from __future__ import annotations

import argparse

from humanoid_twin.cli.options import usage_error


def cmd_view(args: argparse.Namespace) -> int:
    """``humanoid-twin view FILE.rrd``: the rerun viewer shipped with rerun-sdk."""
    if not args.file.is_file():
        raise usage_error(f"no such recording: {args.file}")
    from humanoid_twin.recording.viewer import ViewerError, view

    if not 0 < args.port < 65536:
        raise usage_error(f"--port {args.port}: must be 1..65535")
    try:
        return view(args.file, web=args.web, web_port=args.port)
    except ViewerError as exc:
        raise usage_error(str(exc)) from None
