"""Partitioned conversion as a cluster runs it: N `ingest convert --partition I/N` processes at
once (the array logic of scripts/cluster/), then `ingest finalize`. The store must be byte for
byte the one a single `ingest convert` writes, for odd shapes, shards, several channels, float
samples and OME-Zarr 0.4; a failed partition is rerun alone; errors say what is missing."""

import os
import subprocess

import pytest
import zarr

from support.binaries import run_ingest, run_partitions
from support.paths import BIN, ROOT
from support.stores import files

CLUSTER = ROOT / "scripts" / "cluster"


@pytest.fixture(scope="module")
def samples(tmp_path_factory):
    """Inputs of odd shapes: a sparse u16 stack, a 3-channel fluorescence stack (u16 and u8,
    stored as u16), a float32 simulation."""
    d = tmp_path_factory.mktemp("inputs")
    out = {}
    for kind, size in [("sparse", "45,40,36"), ("fluorescence", "37,50,44"), ("dense", "29,30,31")]:
        run_ingest("sample", "-o", d / kind, "--kind", kind, "--size", size, "--quiet")
        out[kind] = sorted((d / kind).glob("*.tif"))
    return out


CASES = {
    "sparse-bricks-4": ("sparse", ["--chunk", "4"]),
    "sparse-odd-slabs": ("sparse", ["--chunk", "3,8,8"]),
    "fluorescence-sharded": ("fluorescence", ["--chunk", "8,16,16", "--shard", "16,32,32"]),
    "fluorescence-anisotropic-0.4": ("fluorescence", ["--chunk", "6", "--voxel-size", "4,1,1",
                                                      "--ome-zarr-version", "0.4"]),
    "dense-float": ("dense", ["--chunk", "4"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("n", [1, 2, 3, 7])
def test_n_partitions_write_the_store_one_process_writes(samples, tmp_path, case, n):
    kind, flags = CASES[case]
    whole = tmp_path / "whole" / "x.ome.zarr"
    run_ingest("convert", *samples[kind], "-o", whole, *flags, "--quiet")
    parted = tmp_path / "parted" / "x.ome.zarr"
    run_partitions(samples[kind], parted, n, *flags)
    # Nothing is a store until finalize: no root metadata, only the temporary folder.
    assert not parted.exists()
    done = run_ingest("finalize", "-o", parted, "--quiet")
    assert done.stdout.startswith(f"wrote {parted} (")
    assert files(parted) == files(whole)
    assert sorted(p.name for p in parted.parent.iterdir()) == ["x.ome.zarr"]


def test_partitions_cut_on_whole_slabs_and_say_what_they_wrote(samples, tmp_path):
    out = tmp_path / "x.ome.zarr"
    p = run_ingest("convert", *samples["sparse"], "-o", out, "--chunk", "4", "--quiet",
                   "--partition", "1/7")
    first = p.stdout.splitlines()[0]
    assert first == (f"wrote partition 1/7 into {tmp_path}/.x.ome.zarr.partial: level-0 planes "
                     "4..12, levels 0 to 0, bricks written 180, empty (not written) 0")
    two = run_ingest("convert", *samples["sparse"], "-o", tmp_path / "y.ome.zarr", "--chunk", "4",
                     "--quiet", "--partition", "1/2")
    assert two.stdout.splitlines()[0].endswith(
        "level-0 planes 32..45, levels 0 to 3, bricks written 423, empty (not written) 0")


def test_a_failed_partition_is_rerun_alone(samples, tmp_path):
    flags = ["--chunk", "4"]
    whole = tmp_path / "whole" / "x.ome.zarr"
    run_ingest("convert", *samples["sparse"], "-o", whole, *flags, "--quiet")
    out = tmp_path / "parted" / "x.ome.zarr"
    run_partitions(samples["sparse"], out, 3, *flags)
    partial = out.parent / ".x.ome.zarr.partial"
    # Partition 1 "failed": its hand-over file never came, and some of its bricks are missing.
    (partial / ".partitions" / "1-of-3").unlink()
    level0 = sorted((partial / "0" / "c" / "0").iterdir(), key=lambda p: int(p.name))
    for brick_plane in level0[5:7]:
        for f in brick_plane.rglob("*"):
            if f.is_file():
                f.unlink()
    failed = run_ingest("finalize", "-o", out, check=False)
    assert failed.returncode == 1
    assert failed.stderr == (
        f"error: {out}: partitions 1 of 3 have not finished (no .partitions/I-of-3); run them, "
        "then finalize\n")
    assert not out.exists()
    run_partitions(samples["sparse"], out, 3, *flags, only=[1])
    run_ingest("finalize", "-o", out, "--quiet")
    assert files(out) == files(whole)
    # zarr-python reads it like any store.
    assert zarr.open_group(str(out), mode="r")["0"].shape == (1, 45, 40, 36)


def test_finalize_says_what_is_wrong(samples, tmp_path):
    out = tmp_path / "x.ome.zarr"
    none = run_ingest("finalize", "-o", out, check=False)
    assert none.returncode == 1
    assert none.stderr == (
        f"error: {out}: no partition has finished (no hand-over file in .partitions/; run "
        f"`ingest convert --partition I/N -o {out}` first)\n")
    run_ingest("convert", *samples["sparse"], "-o", out, "--chunk", "4", "--quiet",
               "--partition", "0/2")
    # A partition of another conversion is refused before it writes anything.
    refusal = (f"error: {out}: its temporary folder {tmp_path}/.x.ome.zarr.partial holds "
               "partitions of a conversion with other inputs, options or partition count; rerun "
               "with the same command line, or remove that folder to start over\n")
    for chunk, partition in [("8", "1/2"), ("4", "0/3")]:
        other = run_ingest("convert", *samples["sparse"], "-o", out, "--chunk", chunk, "--quiet",
                           "--partition", partition, check=False)
        assert (other.returncode, other.stderr) == (1, refusal)
    # Should the record be lost, finalize still refuses partitions that disagree.
    (tmp_path / ".x.ome.zarr.partial" / ".partitions" / "plan").unlink()
    run_ingest("convert", *samples["sparse"], "-o", out, "--chunk", "8", "--quiet",
               "--partition", "1/2")
    mixed = run_ingest("finalize", "-o", out, check=False)
    assert mixed.returncode == 1
    assert mixed.stderr == (
        f"error: {tmp_path}/.x.ome.zarr.partial/.partitions/1-of-2: partition 1/2 was converted "
        "with other inputs or options than partition 0/2 (rerun it with the same command line)\n")
    bad = run_ingest("convert", *samples["sparse"], "-o", out, "--partition", "2/2", check=False)
    assert bad.returncode == 2
    assert ("invalid value '2/2' for '--partition <I/N>': --partition 2/2: expected I/N, "
            "partition I (counted from 0) of N, with I below N (0/N to N-1/N)") in bad.stderr
    # A finished store is not replaced without --overwrite.
    run_partitions(samples["sparse"], tmp_path / "done.ome.zarr", 1, "--chunk", "4")
    run_ingest("finalize", "-o", tmp_path / "done.ome.zarr", "--quiet")
    again = run_ingest("convert", *samples["sparse"], "-o", tmp_path / "done.ome.zarr",
                       "--partition", "0/1", check=False)
    assert again.returncode == 1
    assert again.stderr == (f"error: {tmp_path}/done.ome.zarr: output already exists "
                            "(pass --overwrite to replace it)\n")


def test_the_cluster_task_script_runs_slurm_and_kubernetes_arrays(samples, tmp_path):
    """scripts/cluster/partition-task.sh as Slurm array tasks and as Kubernetes Indexed Job
    pods would run it (their variables, four tasks at once), then finalize."""
    flags = ["--chunk", "4"]
    whole = tmp_path / "whole" / "x.ome.zarr"
    run_ingest("convert", *samples["sparse"], "-o", whole, *flags, "--quiet")
    base = {k: v for k, v in os.environ.items()
            if not k.startswith(("SLURM_", "JOB_COMPLETION", "PARTITION_"))}
    base["INGEST"] = str(BIN / "ingest")
    schedulers = {
        "slurm": lambda i: {"SLURM_ARRAY_TASK_ID": str(i), "SLURM_ARRAY_TASK_COUNT": "4"},
        "kubernetes": lambda i: {"JOB_COMPLETION_INDEX": str(i), "PARTITION_COUNT": "4"},
    }
    for name, task_env in schedulers.items():
        out = tmp_path / name / "x.ome.zarr"
        tasks = [subprocess.Popen([str(CLUSTER / "partition-task.sh"), *map(str, samples["sparse"]),
                                   "-o", str(out), *flags], env={**base, **task_env(i)},
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for i in range(4)]
        for i, t in enumerate(tasks):
            stdout, stderr = t.communicate(timeout=300)
            assert t.returncode == 0, stderr
            assert stdout.startswith(f"wrote partition {i}/4 into "), stdout
        run_ingest("finalize", "-o", out, "--quiet")
        assert files(out) == files(whole), name
    lost = subprocess.run([str(CLUSTER / "partition-task.sh"), "in.tif", "-o", "x.ome.zarr"],
                          env=base, capture_output=True, text=True)
    assert (lost.returncode, lost.stderr) == (2, (
        "partition-task.sh: no task index or count: run it as a Slurm array task or a Kubernetes "
        "Indexed Job pod, or set PARTITION_INDEX and PARTITION_COUNT\n"))


def test_the_kubernetes_manifests_agree_with_each_other():
    import yaml
    parts = yaml.safe_load((CLUSTER / "k8s-partitions-job.yaml").read_text())
    final = yaml.safe_load((CLUSTER / "k8s-finalize-job.yaml").read_text())
    spec = parts["spec"]
    pod = spec["template"]["spec"]["containers"][0]
    count = next(e["value"] for e in pod["env"] if e["name"] == "PARTITION_COUNT")
    assert spec["completionMode"] == "Indexed"
    assert spec["completions"] == spec["parallelism"] == int(count)
    assert pod["command"][0] == "partition-task.sh"
    output = pod["command"][pod["command"].index("-o") + 1]
    command = final["spec"]["template"]["spec"]["containers"][0]["command"]
    assert command[:2] == ["ingest", "finalize"]
    assert command[command.index("-o") + 1] == output


FAKE_SBATCH = """#!/usr/bin/env bash
# Runs what sbatch is given here and now: an --array's tasks at once, with Slurm's variables,
# or a --wrap command; records each call's arguments. As sbatch reads them: options up to the
# script, the script's own arguments after it.
echo "$*" >> "$SBATCH_CALLS"
array=""; wrap=""; script=()
for a in "$@"; do
  if [ ${#script[@]} -gt 0 ]; then script+=("$a"); continue; fi
  case "$a" in
    --array=*) array=${a#--array=} ;;
    --wrap=*) wrap=${a#--wrap=} ;;
    --*) ;;
    *) script+=("$a") ;;
  esac
done
if [ -n "$wrap" ]; then
  bash -c "$wrap" >> "$SBATCH_OUT" || exit 1
  echo 1002
else
  lo=${array%-*}; hi=${array#*-}; pids=()
  for i in $(seq "$lo" "$hi"); do
    SLURM_ARRAY_TASK_ID=$i SLURM_ARRAY_TASK_COUNT=$((hi - lo + 1)) "${script[@]}" >> "$SBATCH_OUT" &
    pids+=($!)
  done
  for p in "${pids[@]}"; do wait "$p" || exit 1; done
  echo 1001
fi
"""


def test_the_slurm_submission_script_submits_the_array_then_finalize(samples, tmp_path):
    """scripts/cluster/slurm-submit.sh against a stand-in `sbatch` that runs the job array's
    tasks locally and then the finalize job."""
    bindir = tmp_path / "bin"
    bindir.mkdir()
    (bindir / "sbatch").write_text(FAKE_SBATCH)
    (bindir / "sbatch").chmod(0o755)
    (bindir / "ingest").symlink_to(BIN / "ingest")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "PARTITION_"))}
    env.update(PATH=f"{bindir}:{env['PATH']}", SBATCH_CALLS=str(tmp_path / "calls"),
               SBATCH_OUT=str(tmp_path / "out"))
    out = tmp_path / "cluster" / "x.ome.zarr"
    p = subprocess.run([str(CLUSTER / "slurm-submit.sh"), "3", *map(str, samples["sparse"]),
                        "-o", str(out), "--chunk", "4"], env=env, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert p.stdout == "submitted array job 1001 (3 partitions) and finalize job 1002\n"
    calls = (tmp_path / "calls").read_text().splitlines()
    assert len(calls) == 2
    assert calls[0].startswith("--parsable --job-name=ingest-partitions --array=0-2 ")
    assert "--dependency=afterok:1001" in calls[1]
    outputs = (tmp_path / "out").read_text()
    assert sorted(l.split(" into ")[0] for l in outputs.splitlines() if " into " in l) == [
        f"wrote partition {i}/3" for i in range(3)]
    whole = tmp_path / "whole" / "x.ome.zarr"
    run_ingest("convert", *samples["sparse"], "-o", whole, "--chunk", "4", "--quiet")
    assert files(out) == files(whole)
