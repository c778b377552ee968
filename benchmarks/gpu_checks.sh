#!/usr/bin/env bash
# The checks that need a CUDA GPU, in parts that each fit a GPU machine's 10-minute command:
#
#   bash benchmarks/gpu_checks.sh [tests] [update] [update-extra] [train]     (default: all four)
#
# tests         the CUDA tests: RLAD's fast update (eager, channels-last, CUDA graphs, bf16)
#               against the plain update on the same GPU, and SB3 training on the GPU (~1-2 min);
# update        benchmarks/rlad_update.py at 84 and 256 px: plain, fast, fast with CUDA graphs,
#               written to benchmarks/results/rlad_update_gpu.{md,json} (235 s on an H100, 190 s of it compiling);
# update-extra  the same for channels-last and CUDA graphs + bf16, to rlad_update_gpu_extra (~5 min:
#               the graphs compile for ~50 s at 84 px and ~150 s at 256 px);
# train         benchmarks/rlad_gpu_training.py: RLAD and DrQ x 3 seeds training at once on the town
#               (6 processes sharing the GPU, Table II's settings, the fast update with CUDA graphs)
#               for $TRAIN_S seconds (default 160), to results/rlad_gpu_training.{md,json}: each run's
#               steps per second once updates begin, the number that sizes rlad_ablation.py's runs.
#
# Each part has its own time limit (PART_S_<part>, seconds) and a part that fails does not stop the
# next. Logs go to $OUT when set (the device tool's folder), else benchmarks/runs/gpu-checks; on a
# machine without gymnasium, stable-baselines3 or highway-env, put their wheels (and pygame-ce's) in
# .whl/: the script installs them into /tmp/site first.
set -u
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 MPLBACKEND=Agg PYGAME_HIDE_SUPPORT_PROMPT=1
cd "$(dirname "$0")/.."
py=${PYTHON:-python3}
out=${OUT:-benchmarks/runs/gpu-checks}
mkdir -p "$out"
parts=("$@")
[ ${#parts[@]} -eq 0 ] && parts=(tests update update-extra train)
for part in "${parts[@]}"; do
    case $part in tests | update | update-extra | train) ;; *) echo "error: unknown part '$part' (tests, update, update-extra, train)" >&2; exit 2 ;; esac
done
if ! $py -c "import gymnasium, stable_baselines3, highway_env" 2>/dev/null && ls .whl/*.whl >/dev/null 2>&1; then
    $py -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
    export PYTHONPATH=/tmp/site:$PWD
else
    export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
fi
if ! $py -c "import torch, sys; sys.exit(0 if torch.cuda.is_available() else 1)"; then
    echo "error: these checks need a CUDA GPU, and torch sees none here" >&2
    exit 2
fi
log=$out/log.txt
{
    date -u
    nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
    $py -c "import platform, torch; print('python', platform.python_version(), 'torch', torch.__version__, 'cores', __import__('os').cpu_count())"
} >>"$log" 2>&1

run_part() { # name, default seconds, command...
    local name=$1 seconds=$2 status
    shift 2
    local var="PART_S_${name//-/_}"
    seconds=${!var:-$seconds}
    echo "== $name (at most ${seconds} s) $(date -u +%T)" | tee -a "$log"
    local start=$SECONDS
    timeout -s KILL "$seconds" "$@" >>"$log" 2>&1
    status=$?
    echo "== $name: exit $status after $((SECONDS - start)) s" | tee -a "$log"
}

for part in "${parts[@]}"; do
    case $part in
        tests)
            run_part tests 150 $py -m pytest -p no:cacheprovider -o addopts="" -q -n 3 -rs \
                tests/agents/test_rlad_fast.py tests/agents/test_rlad.py tests/agents/test_rlad_memory.py \
                tests/test_bad_input.py::test_device_cuda_trains_sb3_on_the_gpu
            ;;
        update)
            run_part update 300 $py benchmarks/rlad_update.py --device cuda --size 84 256 \
                --variants plain fast cuda-graphs --updates 10 --repeats 5 --profile --profile-updates 5
            cp benchmarks/results/rlad_update_gpu.* "$out"/ 2>/dev/null
            ;;
        update-extra)
            run_part update-extra 360 $py benchmarks/rlad_update.py --device cuda --size 84 256 \
                --variants fast fast-nhwc cuda-graphs-bf16 --updates 10 --repeats 5 --out rlad_update_gpu_extra
            cp benchmarks/results/rlad_update_gpu_extra.* "$out"/ 2>/dev/null
            ;;
        train)
            run_part train $((${TRAIN_S:-160} + 60)) $py benchmarks/rlad_gpu_training.py --seconds "${TRAIN_S:-160}"
            cp benchmarks/results/rlad_gpu_training.* "$out"/ 2>/dev/null
            ;;
    esac
done
date -u >>"$log"
