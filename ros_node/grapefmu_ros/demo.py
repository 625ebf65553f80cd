"""Run the simulator node (lockstep, recording) and the harvesting controller in separate processes, once open
loop and once gentle, and print what each did to the berries.

`python -m grapefmu_ros.demo [--out out/demo] [--scene SCENE.toml]`"""
from __future__ import annotations

import argparse
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PROG = "python -m grapefmu_ros.demo"
MODES = ("open_loop", "gentle")
#: how long a child process has to stop after SIGINT before it is killed, s: when the demo is interrupted, and
#: when the run is over (the node then finishes its recording, which must not be cut short)
STOP_GRACE_S, FINISH_GRACE_S = 3.0, 30.0


class Stopped(Exception):
    """SIGINT or SIGTERM reached the demo."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _on_signal(signum, _frame):
    for sig in (signal.SIGINT, signal.SIGTERM):  # the cleanup that follows is bounded: no second interruption
        signal.signal(sig, signal.SIG_IGN)
    raise Stopped(signum)


def _stop(*procs: subprocess.Popen | None, grace: float = STOP_GRACE_S) -> None:
    """SIGINT to each (the node then finishes its recording), then SIGKILL to any not ended in `grace` s."""
    running = [p for p in procs if p is not None and p.poll() is None]
    for p in running:
        p.send_signal(signal.SIGINT)
    deadline = time.monotonic() + grace
    for p in running:
        try:
            p.wait(timeout=max(deadline - time.monotonic(), 0.01))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _tail(fh) -> str:
    fh.seek(0)
    lines = [ln.strip() for ln in fh.read().decode(errors="replace").splitlines() if ln.strip()]
    return lines[-1] if lines else "no output"


def run_pair(mode: str, record: Path, scene: str | None, timeout: float = 600) -> dict:
    """One node and one controller; the controller's RESULT as a dict. A node that dies, a controller that
    fails or a run past `timeout` s ends the demo with one line saying which."""
    node_args = [sys.executable, "-m", "grapefmu_ros", "--ros-args", "-p", "mode:=lockstep", "-p", f"record:={record}"]
    if scene:
        node_args += ["-p", f"scene:={scene}"]
    ctl_args = [sys.executable, "-m", "grapefmu_ros.controller", "--ros-args", "-p", f"mode:={mode}"]
    node = ctl = None
    finished = False
    with tempfile.TemporaryFile() as node_log, tempfile.TemporaryFile() as ctl_out, tempfile.TemporaryFile() as ctl_err:
        try:
            node = subprocess.Popen(node_args, stdout=node_log, stderr=subprocess.STDOUT)
            ctl = subprocess.Popen(ctl_args, stdout=ctl_out, stderr=ctl_err)
            deadline = time.monotonic() + timeout
            while ctl.poll() is None:
                if node.poll() is not None:
                    raise SystemExit(f"{PROG}: the simulator node stopped (exit {node.returncode}) before the "
                                     f"{mode} controller finished: {_tail(node_log)}")
                if time.monotonic() > deadline:
                    raise SystemExit(f"{PROG}: the {mode} run took longer than {timeout:g} s; stopped")
                time.sleep(0.1)
            finished = True
        finally:
            _stop(ctl, node, grace=FINISH_GRACE_S if finished else STOP_GRACE_S)
        ctl_out.seek(0)
        m = re.search(r"RESULT (.*)", ctl_out.read().decode(errors="replace"))
        if ctl.returncode != 0 or not m:
            raise SystemExit(f"{PROG}: the {mode} controller failed (exit {ctl.returncode}): {_tail(ctl_err)}")
    return dict(kv.split("=") for kv in m.group(1).split())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=" ".join(__doc__.split("\n\n")[0].split()),
                                 epilog="The committed example recordings are regenerated with --out recordings "
                                        "(README.md, Maintainers). SIGINT or SIGTERM stops the demo and its "
                                        "processes within a few seconds.")
    ap.add_argument("--out", default="out/demo", metavar="DIR",
                    help="directory for open_loop.mcap and gentle.mcap (default: out/demo)")
    ap.add_argument("--scene", metavar="FILE", help="scene TOML (default: the packaged default scene)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    handlers = {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    done = []
    try:
        out.mkdir(parents=True, exist_ok=True)
        print(f"{PROG}: simulator node (lockstep, recording) and harvesting controller, {' then '.join(MODES)}; "
              f"recordings go to {out}/ (a few seconds each)", file=sys.stderr, flush=True)
        rows = []
        for mode in MODES:
            print(f"{PROG}: {mode}: starting the node and the controller, recording {out / f'{mode}.mcap'}",
                  file=sys.stderr, flush=True)
            rows.append(run_pair(mode, out / f"{mode}.mcap", a.scene))
            done.append(out / f"{mode}.mcap")
    except Stopped as e:
        kept = f"; finished: {', '.join(map(str, done))}" if done else ""
        print(f"{PROG}: stopped by {signal.Signals(e.signum).name}{kept}", file=sys.stderr, flush=True)
        return 128 + e.signum
    finally:
        for sig, h in handlers.items():
            signal.signal(sig, h)
    print(f"{'mode':<10} {'peak contact force (N)':>23} {'peak pedicel tension (N)':>25} {'collisions':>11} "
          f"{'move time (s)':>14}")
    for r in rows:
        print(f"{r['mode']:<10} {float(r['peak_contact_force']):>23.4f} {float(r['peak_pedicel_tension']):>25.4f} "
              f"{r['collisions']:>11} {float(r['move_time']):>14.3f}")
    print(f"recordings: {', '.join(str(out / f'{m}.mcap') for m in MODES)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
