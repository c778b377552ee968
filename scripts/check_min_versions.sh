#!/usr/bin/env bash
# Install drivelab's declared minimum dependency versions into a temporary venv, then import every
# drivelab module and run a few fast tests there: proves the floors in pyproject.toml hold.
# Downloads the floor releases from the package index (a few minutes). Usage: scripts/check_min_versions.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
VENV=$(mktemp -d "${TMPDIR:-/tmp}/drivelab-min-XXXXXX")
trap 'rm -rf "$VENV"' EXIT
"$PYTHON" -m venv "$VENV"
PY="$VENV/bin/python"
"$PY" -m pip install --quiet --upgrade pip
# torch first, as scripts/setup.sh does: 2.13.0 is the CPU build and the floor pyproject declares.
"$PY" -m pip install --quiet "torch==2.13.0"
# every other dependency at exactly its floor (">=X" becomes "==X"; exact pins stay).
"$PY" - > "$VENV/floors.txt" <<'PYEOF'
import re, tomllib
project = tomllib.load(open("pyproject.toml", "rb"))["project"]
for requirement in project["dependencies"] + ["pytest>=8"]:
    name, rest = re.match(r"([A-Za-z0-9_.-]+)\s*(.*)", requirement).groups()
    if name == "torch":
        continue
    floor = re.search(r"(?:>=|==)\s*([^,;\s]+)", rest)
    print(f"{name}=={floor.group(1)}" if floor else name)
PYEOF
echo "floors:"; sed 's/^/  /' "$VENV/floors.txt"
"$PY" -m pip install --quiet -r "$VENV/floors.txt"
"$PY" -m pip install --quiet --no-deps -e .
"$PY" -m pip check
"$PY" - <<'PYEOF'
import importlib, pkgutil
import drivelab
names = [m.name for m in pkgutil.walk_packages(drivelab.__path__, "drivelab.")]
for name in names:
    importlib.import_module(name)
print(f"imported {len(names)} drivelab modules")
PYEOF
"$PY" -m pip freeze | grep -iE "^(torch|typer|click|gymnasium|stable.baselines3|numpy|scipy|numba|pandas|highway.env|matplotlib|opencv)" | sed 's/^/installed: /'
MPLBACKEND=Agg PYGAME_HIDE_SUPPORT_PROMPT=1 "$PY" -m pytest -p no:cacheprovider \
  tests/training/test_stats.py tests/training/test_compare.py tests/envs/test_vector.py \
  tests/envs/test_pickle.py tests/test_config.py "tests/sim/test_fast.py::test_whole_traffic_matches_highway_env"
