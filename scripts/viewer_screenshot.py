"""Screenshot of a recording as the Rerun viewer opens it (run by hand, never in CI).

Starts a virtual display (Xvfb started with ``-extension Composite``, which turns the
Composite extension off: with it on, the viewer's window stays black), opens the
recording with the ``rerun``
executable of rerun-sdk (software Vulkan rendering through Mesa's lavapipe),
waits for it to draw and saves a PNG of the whole screen::

    python scripts/viewer_screenshot.py results/paper/recordings/base.s000000.rrd \
        --out docs/img/viewer.png --colors 128

Needs (Debian/Ubuntu): ``apt-get install xvfb mesa-vulkan-drivers imagemagick``
(``import`` grabs the screen). Every process it starts is stopped at the end.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path


def _need(exe: str, package: str) -> str:
    path = shutil.which(exe)
    if path is None:
        sys.exit(f"error: `{exe}` not found; install it with `apt-get install {package}`")
    return path


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def screenshot(
    rrd: Path,
    out: Path,
    *,
    display: str,
    width: int,
    height: int,
    wait_s: float,
    colors: int = 0,
) -> None:
    """Open ``rrd`` in the viewer on a fresh virtual display and save ``out`` (PNG).

    ``colors`` > 0 quantises the image to that many colours (a palette PNG,
    about half the size; the viewer's flat dark theme loses nothing visible).
    """
    xvfb = _need("Xvfb", "xvfb")
    rerun = _need("rerun", "rerun-sdk (pip)")
    grab = _need("import", "imagemagick")
    env = {**os.environ, "DISPLAY": display}
    env.pop("WAYLAND_DISPLAY", None)
    server = subprocess.Popen(
        [xvfb, display, "-screen", "0", f"{width}x{height}x24", "-extension", "Composite"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    viewer: subprocess.Popen[bytes] | None = None
    try:
        time.sleep(1.5)
        if server.poll() is not None:
            sys.exit(f"error: Xvfb did not start on {display} (display in use? try --display)")
        viewer = subprocess.Popen(
            [
                rerun,
                "--renderer",
                "vulkan",
                "--window-size",
                f"{width}x{height}",
                "--hide-welcome-screen",
                str(rrd),
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        time.sleep(wait_s)
        if viewer.poll() is not None:
            sys.exit(f"error: the viewer exited early (code {viewer.returncode})")
        out.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(
            [grab, "-display", display, "-window", "root", str(out)], check=True, env=env
        )
        if colors > 0:
            convert = _need("convert", "imagemagick")
            subprocess.run(
                [convert, str(out), "-strip", "-colors", str(colors), f"PNG8:{out}"], check=True
            )
    finally:
        if viewer is not None:
            _stop(viewer)
        _stop(server)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rrd", type=Path, help="recording (.rrd) to open")
    parser.add_argument("--out", type=Path, default=Path("viewer.png"), help="PNG to write")
    parser.add_argument("--display", default=":99", help="X display for Xvfb (default :99)")
    parser.add_argument("--size", default="1600x1000", help="screen size WxH (default 1600x1000)")
    parser.add_argument("--wait", type=float, default=20.0, help="seconds to let it draw")
    parser.add_argument(
        "--colors", type=int, default=0, help="quantise to N colours (smaller file; 0: keep all)"
    )
    args = parser.parse_args(argv)
    if not args.rrd.is_file():
        sys.exit(f"error: {args.rrd}: no such file")
    width, height = (int(v) for v in args.size.lower().split("x"))
    screenshot(
        args.rrd,
        args.out,
        display=args.display,
        width=width,
        height=height,
        wait_s=args.wait,
        colors=args.colors,
    )
    print(args.out)


if __name__ == "__main__":
    main()
