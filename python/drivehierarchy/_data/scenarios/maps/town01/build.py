#!/usr/bin/env python3
"""Builds town01.net.xml from the hand-written sources with the netconvert of eclipse-sumo.

Run from anywhere: ``python scenarios/maps/town01/build.py``. The output is committed, so
this is only needed after editing the sources.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def find_netconvert() -> str:
    exe = shutil.which("netconvert")
    if exe:
        return exe
    try:
        import sumo  # eclipse-sumo wheel

        cand = Path(sumo.SUMO_HOME) / "bin" / "netconvert"
        if cand.exists():
            return str(cand)
    except ImportError:
        pass
    sys.exit("netconvert not found: pip install eclipse-sumo")


def main() -> None:
    cmd = [
        find_netconvert(),
        "--node-files",
        "town01.nod.xml",
        "--edge-files",
        "town01.edg.xml",
        "--output-file",
        "town01.net.xml",
        # Keep the source coordinates (no shift to the origin) so README positions hold.
        "--offset.disable-normalization",
        "true",
        "--no-turnarounds",
        "true",
        "--crossings.guess",
        "true",
        "--walkingareas",
        "true",
        "--junctions.corner-detail",
        "5",
        "--junctions.limit-turn-speed",
        "5.5",
        "--tls.default-type",
        "static",
        "--default.lanewidth",
        "3.2",
        "--no-warnings",
        "false",
    ]
    env = dict(os.environ)
    subprocess.run(cmd, cwd=HERE, check=True, env=env)
    print(f"wrote {HERE / 'town01.net.xml'}")


if __name__ == "__main__":
    main()
