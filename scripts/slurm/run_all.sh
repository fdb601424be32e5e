#!/usr/bin/env bash
# Submits the per-scene stages of mesa as one Slurm array each, chained so that each stage
# starts when the previous array has ended (afterany: a failed scene is recorded in its marker
# and does not block the others), then the merge stages once.
#
#   scripts/slurm/run_all.sh /shared/datasets/mesa10k 64 lift assets retrieve place pack
#
# Usage: run_all.sh DATASET ARRAY_SIZE STAGE...
set -euo pipefail
dataset="$1"
tasks="$2"
shift 2
here="$(cd "$(dirname "$0")" && pwd)"
mkdir -p logs
dependency=()
for stage in "$@"; do
  case "$stage" in
    records|report|release)
      # Merge stages read every scene: one task, after all shards of what came before.
      job=$(sbatch --parsable --job-name="mesa-$stage" "${dependency[@]}" \
        --wrap="${MESA:-mesa} $stage $dataset")
      ;;
    *)
      job=$(sbatch --parsable --job-name="mesa-$stage" --array="0-$((tasks - 1))" \
        "${dependency[@]}" "$here/stage.sbatch" "$stage" "$dataset")
      ;;
  esac
  echo "$stage: job $job"
  dependency=(--dependency="afterany:$job")
done
