#!/usr/bin/env bash
# Every GPU measurement of issue 17 and of benchmarks/README.md "Still to run", in one call of
# under ten minutes on one H100/H200-class GPU. Each step has its own time limit, and no step
# starts past the overall deadline (GPU_ALL_SECONDS, default 540 s), so the whole script ends
# in time; the steps run in order of priority. Everything goes under the output folder:
#
#     bash benchmarks/gpu_all.sh [OUT]        # OUT: default $OUT, else benchmarks/results/gpu_all
#
#   $OUT/*.json           the benchmark scripts' JSON (device, torch, commit, command in each)
#   $OUT/logs/<step>.log  each step's stdout and stderr
#   $OUT/steps.tsv        step, exit status (124: hit its time limit; skipped: no time left),
#                         seconds, command
#   $OUT/env.txt          nvidia-smi, torch and CUDA versions, commit
#
# GPU_ALL_STEPS=name,name runs only those steps (e.g. a second call for what the first could
# not finish: GPU_ALL_STEPS=e2e_swarm200). GPU_ALL_DEVICE (default cuda) and GPU_ALL_TINY=1
# (tiny sizes) exist to check the script on a machine without a GPU:
#     GPU_ALL_DEVICE=cpu GPU_ALL_TINY=1 bash benchmarks/gpu_all.sh /tmp/x
set -u
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEST="${1:-${OUT:-$ROOT/benchmarks/results/gpu_all}}"
DEV="${GPU_ALL_DEVICE:-cuda}"
TINY="${GPU_ALL_TINY:-0}"
DEADLINE=$(( SECONDS + ${GPU_ALL_SECONDS:-540} ))
# every step's limit times this (a CPU check compiles the tick for minutes where a GPU host
# takes seconds; default 1, and 5 with GPU_ALL_TINY=1)
SCALE="${GPU_ALL_LIMIT_SCALE:-$( [[ "$TINY" == 1 ]] && echo 5 || echo 1 )}"
mkdir -p "$DEST/logs"
cd "$ROOT" || exit 1
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}"
export PYTHONUNBUFFERED=1
PY="${PYTHON:-python}"
B=benchmarks
printf 'step\trc\tseconds\tcommand\n' > "$DEST/steps.tsv"

# step NAME LIMIT_S COMMAND...: run COMMAND with at most LIMIT_S seconds (less if the deadline
# is nearer), its output in logs/NAME.log; skipped when under 20 s are left
step() {
    local name=$1 limit=$(( $2 * SCALE )); shift 2
    if [[ -n "${GPU_ALL_STEPS:-}" && ",$GPU_ALL_STEPS," != *",$name,"* ]]; then return; fi
    local left=$(( DEADLINE - SECONDS ))
    (( limit > left )) && limit=$left
    if (( limit < 20 )); then
        printf '%s\tskipped\t0\t%s\n' "$name" "$*" >> "$DEST/steps.tsv"
        echo "== $name: skipped (no time left)"
        return
    fi
    echo "== $name (at most ${limit} s): $*"
    local t0=$SECONDS
    timeout -k 15 "$limit" "$@" > "$DEST/logs/$name.log" 2>&1
    local rc=$?
    printf '%s\t%s\t%s\t%s\n' "$name" "$rc" "$(( SECONDS - t0 ))" "$*" >> "$DEST/steps.tsv"
    echo "   rc $rc, $(( SECONDS - t0 )) s"
    tail -n 4 "$DEST/logs/$name.log" | sed 's/^/   | /'
}

{
    nvidia-smi 2>&1 || echo "no nvidia-smi"
    "$PY" -c "import torch; print('torch', torch.__version__, 'cuda', torch.version.cuda, \
'available', torch.cuda.is_available())"
    git -C "$ROOT" rev-parse HEAD 2>/dev/null || echo "commit unknown"
    date -Is
} > "$DEST/env.txt" 2>&1

if [[ "$TINY" == 1 ]]; then   # sizes small enough for a CPU check of every command
    GEN_CFG=four-niche:6:8,swarm1000:600:2; GEN_X=(--generations 1 --trials 1 --ticks 5)
    BIG_CFG=swarm1000:60:4; BIG_X=(--generations 1 --warmup 0 --trials 1 --ticks 5)
    E2E_4=(--configs four-niche:6:8 --generations 3); E2E_200=(--configs swarm200:20:4 --generations 2)
    SIM_200=(--envs 4 --robots 30 --ticks 5 --repeats 1); SIM_1000=(--envs 2 --robots 600 --ticks 2 --repeats 1)
    PROF=(--configs 4:20 --ticks 5); VMAS=(--envs 4 --robots 30 --ticks 5 --repeats 1)
    TRITON_X=(--configs 2:20,1:600 --ticks 2 --repeats 1 --warmup 1 --settle 3)
else
    GEN_CFG=four-niche:20:50,swarm1000:1000:50; GEN_X=(--generations 1)
    BIG_CFG=swarm1000:10000:50; BIG_X=(--generations 1 --trials 1 --no-count)
    E2E_4=(--configs four-niche:20:50 --generations 500); E2E_200=(--configs swarm200:200:50 --generations 500)
    SIM_200=(--envs 400 --robots 200 --ticks 200); SIM_1000=(--envs 50,400 --robots 1000 --ticks 50)
    PROF=(--configs 400:20,400:200); VMAS=(--robots 200 --vmas-ticks 10 --repeats 2)
    TRITON_X=(--configs 400:200,50:1000,4:10000)
fi
GRAPHS=(); [[ "$DEV" == cuda ]] && GRAPHS=(--cuda-graphs)
E2E_SET=(); [[ "$DEV" == cuda ]] && E2E_SET=(--set cuda_graphs=true)

# 1. a generation of four-niche and of swarm1000 (cell-list broad phase): seconds, simulation
#    share, host syncs and kernel launches (rollout / rest), peak memory
step generation 120 "$PY" $B/bench_generation.py \
    --device "$DEV" --configs "$GEN_CFG" "${GEN_X[@]}" --out "$DEST/generation_cuda_counts.json"
# 2. four-niche, 500 generations, end to end incl. compile (target <= 60 s); projected if cut
step e2e_four_niche 150 "$PY" $B/bench_end_to_end.py --device "$DEV" "${E2E_4[@]}" \
    --time-limit 120 "${E2E_SET[@]}" --out "$DEST/end_to_end_four_niche.json"
# 3. the simulator at E = 400 x N = 200, compiled and CUDA graphs (target >= 150 M robot-ticks/s)
step sim_400x200 90 "$PY" $B/bench_sim.py --device "$DEV" "${SIM_200[@]}" --compile compile \
    "${GRAPHS[@]}" --out "$DEST/sim_cuda_400x200.json"
# 4. the N = 200 (and N = 20) tick profiled kernel by kernel under CUDA graphs
step profile_graphs 100 "$PY" $B/profile_tick.py --device "$DEV" "${PROF[@]}" "${GRAPHS[@]}" \
    --out "$DEST/profile_cuda_graphs.json"
# 5. the simulator at N = 1000 (broad phase), E = 50 and 400, compiled and CUDA graphs
step sim_1000 90 "$PY" $B/bench_sim.py --device "$DEV" "${SIM_1000[@]}" --compile compile \
    "${GRAPHS[@]}" --out "$DEST/sim_cuda_1000.json"
# 6. pytest -m gpu (the GPU tests, none of those added since 2026-11-23 has run on a GPU)
step pytest_gpu 120 "$PY" -m pytest -m gpu -q -p no:cacheprovider \
    --junitxml "$DEST/pytest_gpu.xml"
# 7. swarm 10,000 from population 50 (1 trial): seconds per generation and peak memory
step swarm10000 100 "$PY" $B/bench_generation.py --device "$DEV" --configs "$BIG_CFG" \
    "${BIG_X[@]}" --out "$DEST/generation_cuda_10000.json"
# 8. the Triton tick (issue 40, never run on a GPU): robot-ticks/s against the eager tick at
#    400 x 200, 50 x 1000 and 4 x 10000 (broad phase), the pair phases alone, agreement; on
#    the CPU (GPU_ALL_DEVICE=cpu) it runs in Triton's interpreter
step triton_tick 90 env "TRITON_INTERPRET=$([[ "$DEV" == cpu ]] && echo 1 || echo 0)" "$PY" \
    $B/bench_triton_tick.py "${TRITON_X[@]}" --out "$DEST/triton_tick_$DEV.json"
# 9. swarm200, 500 generations, end to end (target <= 120 s): what time is left, projected if cut
left=$(( DEADLINE - SECONDS - 25 ))
step e2e_swarm200 "$(( left / SCALE ))" "$PY" $B/bench_end_to_end.py --device "$DEV" "${E2E_200[@]}" \
    --time-limit "$(( left > 40 ? left - 15 : 25 ))" "${E2E_SET[@]}" \
    --out "$DEST/end_to_end_swarm200.json"
# 10. our side of the VMAS comparison at N = 200 (VMAS itself only if installed there), every
#     tick the project ships on this device side by side: eager, compiled, and the Triton tick
#     on CUDA (in Triton's interpreter on a CPU check) or the fused C++ tick on the CPU
VMAS_MODES=eager,compile,triton; [[ "$DEV" == cpu ]] && VMAS_MODES=eager,compile,fused
step vmas_200 45 env "TRITON_INTERPRET=$([[ "$DEV" == cpu ]] && echo 1 || echo 0)" "$PY" \
    $B/bench_vs_vmas.py --device "$DEV" "${VMAS[@]}" --modes "$VMAS_MODES" \
    --out "$DEST/vmas_cuda_200.json"
# 11. four-niche end to end with the Triton tick in the run (SWARMCODE_TICK=triton), as step 2
step e2e_four_niche_triton 90 env SWARMCODE_TICK=triton "$PY" $B/bench_end_to_end.py \
    --device "$DEV" "${E2E_4[@]}" --time-limit 60 --out "$DEST/end_to_end_four_niche_triton.json"

echo "== done in $SECONDS s; $DEST/steps.tsv:"
column -t -s $'\t' "$DEST/steps.tsv" 2>/dev/null | cut -c1-150 || cat "$DEST/steps.tsv"
