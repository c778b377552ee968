#!/usr/bin/env bash
# Create .venv and install drivelab with its test and documentation tools. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
# torch first, pinned: 2.13.0 is the CPU build; an unpinned torch would pull a CUDA build.
.venv/bin/python -m pip install --quiet "torch==2.13.0"
.venv/bin/python -m pip install --quiet -e ".[dev,docs]"
# the simulator compiles once per version (about a minute): here, not in the first command
PYGAME_HIDE_SUPPORT_PROMPT=1 .venv/bin/python scripts/warm_cache.py
