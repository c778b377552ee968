#!/usr/bin/env bash
# Set up, then lint and run the whole test suite (what CI runs).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PYGAME_HIDE_SUPPORT_PROMPT=1 MPLBACKEND=Agg
.venv/bin/ruff check .
.venv/bin/python -m pytest -n 2 "$@"
