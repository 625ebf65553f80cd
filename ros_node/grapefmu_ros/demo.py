"""Run the simulator node (lockstep, recording) and the harvesting controller in separate processes,
once open loop and once gentle, and print what each did to the berries.

`python -m grapefmu_ros.demo [--out recordings] [--scene SCENE.toml]`"""
from __future__ import annotations

import argparse
import re
import signal
import subprocess
import sys
from pathlib import Path


def run_pair(mode: str, record: Path, scene: str | None, timeout: float = 600) -> dict:
    node_args = [sys.executable, "-m", "grapefmu_ros", "--ros-args", "-p", "mode:=lockstep", "-p", f"record:={record}"]
    if scene:
        node_args += ["-p", f"scene:={scene}"]
    node = subprocess.Popen(node_args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ctl = subprocess.run([sys.executable, "-m", "grapefmu_ros.controller", "--ros-args", "-p", f"mode:={mode}"],
                             capture_output=True, text=True, timeout=timeout)
    finally:
        node.send_signal(signal.SIGINT)
        node.wait(timeout=30)
    m = re.search(r"RESULT (.*)", ctl.stdout)
    if ctl.returncode != 0 or not m:
        raise SystemExit(f"controller ({mode}) failed:\n{ctl.stdout}\n{ctl.stderr}")
    return dict(kv.split("=") for kv in m.group(1).split())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="recordings", help="directory for open_loop.mcap and gentle.mcap")
    ap.add_argument("--scene", help="scene TOML (default: the packaged default scene)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for mode in ("open_loop", "gentle"):
        rows.append(run_pair(mode, out / f"{mode}.mcap", a.scene))
    print(f"{'mode':<10} {'peak contact force (N)':>23} {'peak pedicel tension (N)':>25} {'collisions':>11} "
          f"{'move time (s)':>14}")
    for r in rows:
        print(f"{r['mode']:<10} {float(r['peak_contact_force']):>23.4f} {float(r['peak_pedicel_tension']):>25.4f} "
              f"{r['collisions']:>11} {float(r['move_time']):>14.3f}")
    print(f"recordings: {', '.join(str(out / f'{m}.mcap') for m in ('open_loop', 'gentle'))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
