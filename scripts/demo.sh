#!/usr/bin/env bash
# Set up, then the main job: a short PPO training on highway and its evaluation.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PYGAME_HIDE_SUPPORT_PROMPT=1
name="demo-ppo-highway-$(date +%Y%m%d-%H%M%S)"
.venv/bin/drivelab train --algo ppo --env highway --obs kinematics --action meta \
  --reward highway --steps ${DEMO_STEPS:-1024} --seed 0 --name "$name"
.venv/bin/drivelab evaluate "runs/$name" --episodes ${DEMO_EPISODES:-5}
