#!/usr/bin/env bash
# Converts a stack on a Slurm cluster in N partitions, then finalizes the store:
#
#   slurm-submit.sh N INPUT... -o OUTPUT [convert flags]
#
# Submits a job array of N tasks (partition-task.sh, one partition each) and a finalize job
# that starts when every task has succeeded (--dependency=afterok). OUTPUT is a folder on a
# file system every node sees, or s3://BUCKET/PREFIX. Resources per task come from the
# environment: SBATCH_CPUS (default 8), SBATCH_MEM (default 16G), SBATCH_TIME (default 4:00:00),
# and any sbatch variables (SBATCH_PARTITION, SBATCH_ACCOUNT, ...). A failed task is rerun
# alone with `sbatch --array=I ... partition-task.sh ...` (the same line, one index), then
# finalize with `ingest finalize -o OUTPUT`.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
n=$1; shift
output=""
prev=""
for a in "$@"; do
  if [ "$prev" = "-o" ] || [ "$prev" = "--output" ]; then output=$a; fi
  prev=$a
done
[ -n "$output" ] || { echo "slurm-submit.sh: no -o OUTPUT given" >&2; exit 2; }
endpoint=()
prev=""
for a in "$@"; do
  if [ "$prev" = "--s3-endpoint" ]; then endpoint=(--s3-endpoint "$a"); fi
  prev=$a
done
array=$(sbatch --parsable --job-name=ingest-partitions --array="0-$((n - 1))" \
  --cpus-per-task="${SBATCH_CPUS:-8}" --mem="${SBATCH_MEM:-16G}" --time="${SBATCH_TIME:-4:00:00}" \
  "$here/partition-task.sh" "$@" --threads "${SBATCH_CPUS:-8}")
final=$(sbatch --parsable --job-name=ingest-finalize --dependency="afterok:$array" \
  --cpus-per-task="${SBATCH_CPUS:-8}" --mem="${SBATCH_MEM:-16G}" --time="${SBATCH_TIME:-4:00:00}" \
  --wrap="${INGEST:-ingest} finalize -o '$output' ${endpoint[*]} --quiet")
echo "submitted array job $array ($n partitions) and finalize job $final"
