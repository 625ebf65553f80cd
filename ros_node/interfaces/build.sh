#!/usr/bin/env bash
# Build into the venv the ROS message packages that the package index does not serve: tf2_msgs (for /tf
# and /tf_static) and grapefmu_msgs (contacts, collision events), with rosidl's generators from the index:
# C, C++ and Python type support, as a colcon build of the same package.xml/CMakeLists.txt would. Run by
# scripts/bootstrap.sh; a package already built (and unchanged) is skipped.
#   bash ros_node/interfaces/build.sh VENV
set -euo pipefail
venv="$(cd "$1" && pwd)"
py="$venv/bin/python"
here="$(cd "$(dirname "$0")" && pwd)"
for pkg in tf2_msgs grapefmu_msgs; do
  digest="$(cat "$here/pypi_wheels.cmake" "$here/$pkg"/package.xml "$here/$pkg"/CMakeLists.txt "$here/$pkg"/msg/*.msg | sha1sum | cut -c1-12)"
  stamp="$venv/share/$pkg/.built-$digest"
  [ -f "$stamp" ] && "$py" -c "import $pkg.msg" 2>/dev/null && continue
  command -v cmake >/dev/null || { echo "build.sh: needs cmake and a C/C++ compiler to build $pkg" >&2; exit 1; }
  build="$(mktemp -d)"
  if ! { cmake -S "$here/$pkg" -B "$build" -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" \
           -DPython3_EXECUTABLE="$py" -DBUILD_TESTING=OFF \
         && cmake --build "$build" -j2 && cmake --install "$build"; } > "$build/log" 2>&1; then
    tail -40 "$build/log" >&2
    echo "build.sh: building $pkg failed (log above)" >&2
    exit 1
  fi
  rm -rf "$build"
  "$py" -c "import $pkg.msg"
  touch "$stamp"
  echo "built $pkg into $venv"
done
