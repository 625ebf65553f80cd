"""The node is a ROS 2 package: colcon builds ros_node/ (ament_python) and the installed entry point runs
the node (here with the venv's Python, as `ros2 run grapefmu_ros grapefmu_node` would in a workspace)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_colcon_builds_the_package_and_its_entry_point_runs_the_node(tmp_path):
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent)) or shutil.which("colcon")
    if colcon is None:
        pytest.skip("colcon is not installed")
    src = tmp_path / "ws" / "src" / "grapefmu_ros"
    shutil.copytree(ROOT / "ros_node", src, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "interfaces"))
    shutil.copytree(ROOT / "ros_node" / "interfaces", src.parent / "interfaces")  # as docs/ros.md says
    env = {**os.environ, "CMAKE_PREFIX_PATH": sys.prefix, "AMENT_PREFIX_PATH": sys.prefix}  # the venv's ROS
    r = subprocess.run([colcon, "build", "--base-paths", str(src.parent), "--cmake-args",
                        f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"], cwd=tmp_path / "ws",
                       capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    # grapefmu_ros and grapefmu_msgs; interfaces/tf2_msgs (for this set-up only) is COLCON_IGNOREd
    assert "2 packages finished" in r.stdout
    assert next((tmp_path / "ws" / "install" / "grapefmu_msgs").rglob("Contacts.msg"), None)
    install = tmp_path / "ws" / "install" / "grapefmu_ros"
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / "grapefmu_ros").exists()
    assert (install / "share" / "grapefmu_ros" / "package.xml").exists()
    node = install / "lib" / "grapefmu_ros" / "grapefmu_node"
    site = next(install.glob("lib/python3*/site-packages"))
    env = {**os.environ, "PYTHONPATH": str(site), "ROS_DOMAIN_ID": "93"}  # the venv has grapefmu_msgs
    r = subprocess.run([sys.executable, str(node), "--ros-args", "-p", "mode:=bogus"], env=env, capture_output=True,
                       text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 2 and "parameter mode: expected 'realtime' or 'lockstep'" in r.stderr, r.stderr[-2000:]
