#!/usr/bin/env bash
# Run (or continue) the paper experiments of docs/RESULTS.md side by side on one GPU.
#
#   bash experiments/2026-11-23-paper-rounds-pre-v02/run_experiments.sh ROOT SECONDS [--resume]
#
# ROOT gets niche/, budget/, roi/, swarm200/ and logs/. Every run is stopped with SIGINT after
# SECONDS (it writes its checkpoint first) unless it finishes sooner; run the script again with
# --resume to continue every run in ROOT towards its 500 generations (swarm200: 50). To continue
# the committed runs: mkdir -p ROOT && tar xzf experiments/2026-11-23-paper-rounds-pre-v02/first-round-h100/runs.tar.gz -C ROOT, then --resume.
# EXTRA_OPTS (environment) is added to every new run's options, e.g.
# EXTRA_OPTS='--set cuda_graphs=true'. At the end ROOT/runs-small.tar.gz holds what make_results.py needs (no TensorBoard events).
set -u
ROOT=${1:?usage: run_experiments.sh ROOT SECONDS [--resume]}
SECONDS_LEFT=${2:?usage: run_experiments.sh ROOT SECONDS [--resume]}
RESUME=${3:-}
case "$RESUME" in ""|--resume) ;; *) echo "third argument must be --resume" >&2; exit 2;; esac
export OMP_NUM_THREADS=1 TORCHINDUCTOR_COMPILE_THREADS=1 PYTHONUNBUFFERED=1
mkdir -p "$ROOT"/{niche,budget,roi,swarm200,logs}
CLI="timeout -s INT $SECONDS_LEFT python3 -m swarmcode_torch.cli"
OPTS="--device cuda --checkpoint-every 25 --log-every 50 ${EXTRA_OPTS:-}"
if [ "$RESUME" = "--resume" ]; then
  for d in "$ROOT"/niche/* "$ROOT"/budget/budget-* "$ROOT"/roi/* "$ROOT"/swarm200/*; do
    [ -f "$d/checkpoint.pt" ] || continue
    gens=500; case "$d" in */swarm200/*) gens=50;; esac
    $CLI evolve --resume "$d" --generations $gens --checkpoint-every 25 --log-every 50 --render-every 0 \
      > "$ROOT/logs/$(basename "$d").log" 2>&1 &
  done
else
  for sc in one-niche two-niche four-niche; do for s in 0 1 2; do
    $CLI evolve --scenario $sc --population 50 --swarm-size 20 --generations 500 --seed $s \
      --logdir "$ROOT/niche" --render-every 0 $OPTS > "$ROOT/logs/$sc-$s.log" 2>&1 &
  done; done
  # one sweep process per budget into one directory (each rewrites table.md with its own row at
  # the end; make_results.py builds the whole table)
  for b in 2500 3000 4000 5000 6000 8000; do
    $CLI sweep --budgets $b --generations 500 --out "$ROOT/budget" $OPTS \
      > "$ROOT/logs/budget-$b.log" 2>&1 &
  done
  $CLI evolve --scenario budget --objective roi --generations 500 --logdir "$ROOT/roi" \
    --render-every 0 $OPTS > "$ROOT/logs/roi.log" 2>&1 &
  $CLI evolve --scenario swarm200 --swarm-size 200 --population 50 --generations 50 \
    --logdir "$ROOT/swarm200" --render-every 0 $OPTS > "$ROOT/logs/swarm200.log" 2>&1 &
fi
wait
for f in "$ROOT"/logs/*.log; do echo "$(basename "$f"): $(grep -v -i warn "$f" | tail -1)"; done
(cd "$ROOT" && find niche budget roi swarm200 logs -name checkpoint.pt -o -name summary.json \
   -o -name teams.jsonl -o -name config.toml -o -name '*.log' | tar czf runs-small.tar.gz -T -)
ls -la "$ROOT/runs-small.tar.gz"
