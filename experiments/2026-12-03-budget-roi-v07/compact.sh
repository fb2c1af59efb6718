#!/usr/bin/env bash
# The committed form of this study from its raw runs, from the repository root:
#   bash experiments/2026-12-03-budget-roi-v07/compact.sh SWEEP_DIR ROI_LOGDIR
# SWEEP_DIR: the `swarmcode-torch sweep` directory (table.md, table.csv, budget.png, one run per
# budget and seed); ROI_LOGDIR: the --logdir of the three ROI runs (one run directory per seed).
set -euo pipefail
SWEEP=$1
ROI=$2
HERE=experiments/2026-12-03-budget-roi-v07
cp "$SWEEP/table.md" "$SWEEP/table.csv" "$SWEEP/budget.png" "$HERE/"
for run in "$SWEEP"/budget-*_seed-*; do
    python experiments/tools/compact_run.py "$run" "$HERE/$(basename "$run")"
done
python experiments/tools/budget_cost.py "$SWEEP"/budget-*_seed-* --json "$HERE/cost_windows.json" \
    > "$HERE/cost_windows.md"
for run in "$ROI"/*/; do
    seed=$(python -c "import sys; from swarmcode_torch.app.runs import read_config; print(read_config(sys.argv[1]).seed)" "$run")
    python experiments/tools/compact_run.py "$run" "$HERE/roi-seed-$seed"
done
