#!/usr/bin/env bash
# Submits mesa's stages over a dataset to Slurm: each per-scene stage (and `assets`) as one job
# array of ARRAY_SIZE tasks, each starting when the previous job has ended (afterany: a failed
# scene is recorded in its marker and does not block the others), and the merge stages
# (records, report, release) as one task each, in the order given.
#
#   scripts/slurm/run_all.sh /shared/datasets/mesa10k 64 assets lift retrieve place pack
#   # ... annotators return refined/<scene>.glb ...
#   scripts/slurm/run_all.sh --release-out /shared/mesa10k-release /shared/datasets/mesa10k 64 \
#       ingest check graph render tasks records report release
#
# Usage: run_all.sh [OPTIONS] DATASET ARRAY_SIZE STAGE...
#
# Options (each also read from the environment variable named; the flag wins):
#   --cpus N          CPUs per task, also mesa's --jobs    MESA_SLURM_CPUS       default 1
#   --mem SIZE        memory per task (sbatch --mem)       MESA_SLURM_MEM        default 2G
#   --time LIMIT      time limit per task (sbatch --time)  MESA_SLURM_TIME       default 02:00:00
#   --partition NAME  sbatch --partition                   MESA_SLURM_PARTITION  default: the cluster's
#   --account NAME    sbatch --account                     MESA_SLURM_ACCOUNT    default: none
#   --sbatch "ARGS"   more sbatch flags, split on spaces   MESA_SLURM_SBATCH     default: none
#                     (e.g. "--qos=low --constraint=avx2")
#   --logs DIR        job logs, DIR/<job name>-<job>_<task>.out
#                                                          MESA_SLURM_LOGS       default ./logs
#   --release-out DIR the folder `mesa release` writes     MESA_RELEASE_OUT      default DATASET/release
#   --after JOB       the first job waits for JOB to end (afterany), to chain two submissions
#   --wait            return only when every submitted job has ended; exit 1 naming the
#                     tasks that did not complete (failed, cancelled, timed out)
#   --dry-run         print the sbatch commands instead of running them
#
# The defaults fit a small node (one CPU and 2 GB per task, two hours): a job asking for more
# than any node of its partition has pends forever with reason PartitionConfig. mesa is
# $MESA (default: mesa on the PATH) and must be reachable from every node.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
cpus="${MESA_SLURM_CPUS:-1}"
mem="${MESA_SLURM_MEM:-2G}"
time_limit="${MESA_SLURM_TIME:-02:00:00}"
partition="${MESA_SLURM_PARTITION:-}"
account="${MESA_SLURM_ACCOUNT:-}"
extra="${MESA_SLURM_SBATCH:-}"
logs="${MESA_SLURM_LOGS:-logs}"
release_out="${MESA_RELEASE_OUT:-}"
after=""
wait_end=0
dry_run=0

die() {
  echo "run_all.sh: $*" >&2
  exit 2
}
value() {
  [ $# -ge 2 ] && [ -n "$2" ] || die "$1 needs a value"
}
while [ $# -gt 0 ]; do
  case "$1" in
    --cpus) value "$@"; cpus="$2"; shift 2 ;;
    --mem) value "$@"; mem="$2"; shift 2 ;;
    --time) value "$@"; time_limit="$2"; shift 2 ;;
    --partition) value "$@"; partition="$2"; shift 2 ;;
    --account) value "$@"; account="$2"; shift 2 ;;
    --sbatch) value "$@"; extra="$2"; shift 2 ;;
    --logs) value "$@"; logs="$2"; shift 2 ;;
    --release-out) value "$@"; release_out="$2"; shift 2 ;;
    --after) value "$@"; after="$2"; shift 2 ;;
    --wait) wait_end=1; shift ;;
    --dry-run) dry_run=1; shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    --) shift; break ;;
    -*) die "unknown option $1 (see --help)" ;;
    *) break ;;
  esac
done
[ $# -ge 3 ] || die "usage: run_all.sh [OPTIONS] DATASET ARRAY_SIZE STAGE... (see --help)"
dataset="$1"
tasks="$2"
shift 2
[ -d "$dataset" ] || die "$dataset: no such dataset folder"
dataset="$(cd "$dataset" && pwd)"
[[ "$tasks" =~ ^[1-9][0-9]*$ ]] || die "ARRAY_SIZE \"$tasks\" is not a positive number"
[[ "$cpus" =~ ^[1-9][0-9]*$ ]] || die "--cpus \"$cpus\" is not a positive number"
release_out="${release_out:-$dataset/release}"
for stage in "$@"; do
  case "$stage" in
    assets|lift|retrieve|place|pack|annotate|ingest|check|graph|render|tasks|records|report|release) ;;
    *) die "unknown stage \"$stage\" (expected assets lift retrieve place pack annotate ingest check graph render tasks records report release)" ;;
  esac
done

resources=(--cpus-per-task="$cpus" --mem="$mem" --time="$time_limit")
[ -n "$partition" ] && resources+=(--partition="$partition")
[ -n "$account" ] && resources+=(--account="$account")
# shellcheck disable=SC2206 # split on spaces, as documented
[ -n "$extra" ] && resources+=($extra)

[ "$dry_run" -eq 1 ] || mkdir -p "$logs"
logs="$(cd "$logs" 2>/dev/null && pwd || echo "$logs")"
dependency=()
[ -n "$after" ] && dependency=(--dependency="afterany:$after")
jobs=()
for stage in "$@"; do
  args=()
  case "$stage" in
    records|report|release)
      # Merge stages read every scene: one task, after all tasks of what came before.
      shape=(--output="$logs/%x-%j.out")
      [ "$stage" = release ] && args=("$release_out")
      ;;
    *)
      shape=(--array="0-$((tasks - 1))" --output="$logs/%x-%A_%a.out")
      ;;
  esac
  command=(sbatch --parsable --job-name="mesa-$stage" "${resources[@]}" "${shape[@]}"
    "${dependency[@]}" "$here/stage.sbatch" "$stage" "$dataset" "${args[@]}")
  if [ "$dry_run" -eq 1 ]; then
    echo "${command[*]}"
    job="DRY$stage"
  else
    job="$("${command[@]}")"
    job="${job%%;*}"
    case "$stage" in
      records|report|release) echo "submitted $stage: job $job" ;;
      *) echo "submitted $stage: job $job, array of $tasks tasks" ;;
    esac
  fi
  jobs+=("$job")
  dependency=(--dependency="afterany:$job")
done
[ "$dry_run" -eq 1 ] && exit 0

ids="$(IFS=,; echo "${jobs[*]}")"
echo "resources per task: ${resources[*]}"
echo "follow it:  squeue -j $ids"
echo "            mesa status $dataset"
echo "            tail -f $logs/mesa-<stage>-<job>_<task>.out"
echo "last job:   ${jobs[-1]} (pass --after ${jobs[-1]} to chain the next submission)"
if [ "$wait_end" -eq 1 ]; then
  while [ -n "$(squeue -h -j "$ids" -o %i 2>/dev/null)" ]; do
    sleep 2
  done
  # Every task's end state, while Slurm still remembers it (MinJobAge, 300 s by default).
  failed=0
  for job in "${jobs[@]}"; do
    while read -r line; do
      id="$(sed -n 's/.*JobId=\([0-9]*\).*/\1/p' <<<"$line")"
      task="$(sed -n 's/.*ArrayTaskId=\([0-9]*\).*/\1/p' <<<"$line")"
      name="$(sed -n 's/.*JobName=\([^ ]*\).*/\1/p' <<<"$line")"
      state="$(sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' <<<"$line")"
      if [ -n "$state" ] && [ "$state" != COMPLETED ]; then
        echo "run_all.sh: $name job $job${task:+ task $task} (id $id) ended $state" >&2
        failed=1
      fi
    done < <(scontrol -o show job "$job" 2>/dev/null || true)
  done
  echo "every job has ended; mesa status $dataset shows what is done"
  exit "$failed"
fi
