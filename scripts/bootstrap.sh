#!/usr/bin/env bash
# Set up .venv/ from nothing but Python 3.11, then run the main job or the tests.
#   bash scripts/bootstrap.sh main   -> simulate the default scene: out/default.png, out/default.mcap, out/default.csv
#   bash scripts/bootstrap.sh test   -> the whole test suite
set -euo pipefail
cd "$(dirname "$0")/.."
job="${1:-main}"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null || { echo "bootstrap: need Python 3.11 ($PY not found)" >&2; exit 1; }
stamp=.venv/.installed-$(sha1sum pyproject.toml | cut -c1-12)
if [ ! -f "$stamp" ]; then
  "$PY" -m venv .venv
  .venv/bin/python -m pip install --quiet --upgrade pip
  .venv/bin/python -m pip install --quiet -e ".[test]"
  touch "$stamp"
fi
bash ros_node/interfaces/build.sh .venv   # tf2_msgs and grapefmu_msgs, which the index does not serve
case "$job" in
  main)
    mkdir -p out
    .venv/bin/grapefmu simulate --plot out/default.png --out out/default.mcap
    .venv/bin/grapefmu simulate --out out/default.csv >/dev/null
    echo "see out/default.png (figure), out/default.mcap (recording), out/default.csv (samples)"
    ;;
  test)
    shift || true
    exec .venv/bin/python -m pytest "$@"
    ;;
  *) echo "usage: bash scripts/bootstrap.sh main|test [pytest args]" >&2; exit 2 ;;
esac
