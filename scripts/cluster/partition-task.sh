#!/usr/bin/env bash
# One partition of a partitioned conversion, as one task of a scheduler's job array:
#
#   partition-task.sh INPUT... -o OUTPUT [convert flags]
#
# runs `ingest convert INPUT... -o OUTPUT [flags] --partition I/N`. The task's index I and the
# count N come from the scheduler:
#   - Slurm job arrays (--array=0-N-1):  SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT;
#   - Kubernetes Indexed Jobs:           JOB_COMPLETION_INDEX, and PARTITION_COUNT from the
#                                        manifest (a Job does not tell its pods its size);
#   - anything else:                     PARTITION_INDEX and PARTITION_COUNT.
# INGEST names the ingest binary (default: `ingest` on PATH). When every task has succeeded,
# run `ingest finalize -o OUTPUT` once (slurm-submit.sh and k8s-finalize-job.yaml do).
# A failed task is rerun alone, with the same index.
set -euo pipefail
index=${PARTITION_INDEX:-${SLURM_ARRAY_TASK_ID:-${JOB_COMPLETION_INDEX:-}}}
count=${PARTITION_COUNT:-${SLURM_ARRAY_TASK_COUNT:-}}
if [ -z "$index" ] || [ -z "$count" ]; then
  echo "partition-task.sh: no task index or count: run it as a Slurm array task or a Kubernetes Indexed Job pod, or set PARTITION_INDEX and PARTITION_COUNT" >&2
  exit 2
fi
exec "${INGEST:-ingest}" convert "$@" --partition "$index/$count" --quiet
