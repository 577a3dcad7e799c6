#!/usr/bin/env bash
# One GPU, about 25 minutes: the shipped-model recipe at GPU sizes (drivewm/recipes/worldmodel.yaml,
# profile gpu: 22 minutes of training budgets, train.budget_minutes per stage), its fp16 export (files of at most 16 MB, a MANIFEST with sha256 and compute spent),
# and the GPU throughput benchmarks of issue 13, all into one output folder:
#
#   scripts/gpu-recipe.sh RUN        # rerun to resume: every stage and every training run resumes
#
# Compare RUN/eval/generated/metrics.json with drivewm/weights/MODEL_CARD.md before replacing the
# shipped weights (only with better ones): drivewm worldmodel export RUN --out drivewm/weights
set -euo pipefail
RUN=${1:?usage: scripts/gpu-recipe.sh RUN}
cd "$(dirname "$0")/.."
mkdir -p "$RUN"
python -c "import torch, sys; sys.exit(0 if torch.cuda.is_available() else 'gpu-recipe.sh: no CUDA device (use --profile cpu)')"
nvidia-smi --query-gpu=name,memory.total --format=csv | tee "$RUN/gpu.txt"
start=$(date +%s)
drivewm worldmodel train --profile gpu --out "$RUN" 2>&1 | tee -a "$RUN/recipe.log"
echo "recipe wall seconds: $(( $(date +%s) - start ))" | tee -a "$RUN/gpu.txt"
drivewm worldmodel export "$RUN" --out "$RUN/weights"
python benchmarks/bench_dit.py --size full --mfu-size base | tee "$RUN/bench_dit.txt"
python benchmarks/bench_tokenizer.py | tee "$RUN/bench_tokenizer.txt"
python benchmarks/bench_optimizer.py --presets base | tee "$RUN/bench_optimizer.txt"
