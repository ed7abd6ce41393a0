"""The file system a benchmark writes to, in words for its report, and a journaled ext4 to
write to where the machine's own lacks a journal.

    python3 benchmarks/file_system.py describe DIR
    sudo python3 benchmarks/file_system.py journaled-ext4 IMAGE MOUNTPOINT [--size 24G]

Why it matters: ext4 without a journal (this development machine's root) checks every inode
it is about to hand out against the inode table for one deleted in the last minute, or the last
six minutes where that block of the table is dirty (`recently_deleted` in fs/ext4/ialloc.c), so a benchmark that removes one run's output before
the next pays a scan per file and folder it creates; a journaled ext4 (what `mkfs.ext4` makes
by default) skips that check, and instead pays a journal commit for each `fsync`. Both costs
fall on every tool in proportion to the files it makes and syncs, so the report names the file
system it measured on.

`journaled-ext4` makes (once) an ext4 image file with mkfs.ext4's defaults and loop-mounts it
at MOUNTPOINT; run again, it leaves a mounted one as it is. The image is sparse; 24G holds
`ingest_bench.py --sizes 512,2048 --rounds 5 --flame` with every run's output kept to the end.
"""

import argparse
import pathlib
import subprocess
import sys


def mount_of(path: pathlib.Path) -> dict:
    """findmnt's SOURCE, FSTYPE and OPTIONS of the mount holding `path`."""
    out = subprocess.run(["findmnt", "-n", "-o", "SOURCE,FSTYPE,TARGET", "-T", str(path)],
                         capture_output=True, text=True, check=True).stdout.split()
    return {"source": out[0], "fstype": out[1], "target": out[2]}


def has_journal(source: str) -> bool | None:
    """Whether the ext4 file system on `source` has a journal, from the kernel's own record
    (`/sys/fs/ext4/DEVICE/journal_task` names jbd2's thread, or `<none>`); None when unknown."""
    task = pathlib.Path("/sys/fs/ext4") / pathlib.Path(source).name / "journal_task"
    try:
        return task.read_text().strip() != "<none>"
    except OSError:
        return None


def describe(path: pathlib.Path) -> str:
    """For example "ext4 with a journal (/dev/loop0 at /mnt/bench)"."""
    m = mount_of(path)
    what = m["fstype"]
    if m["fstype"].startswith("ext"):
        journal = has_journal(m["source"])
        what += {True: " with a journal", False: " without a journal", None: ""}[journal]
    return f"{what} ({m['source']} at {m['target']})"


def journaled_ext4(image: pathlib.Path, mountpoint: pathlib.Path, size: str) -> None:
    """Makes `image` (once) and mounts it at `mountpoint` (unless something is mounted there)."""
    mountpoint.mkdir(parents=True, exist_ok=True)
    if mount_of(mountpoint)["target"] == str(mountpoint.resolve()):
        print(f"{mountpoint}: already mounted, {describe(mountpoint)}")
        return
    if not image.exists():
        image.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(["truncate", "-s", size, str(image)], check=True)
        subprocess.run(["mkfs.ext4", "-q", "-F", str(image)], check=True)
    subprocess.run(["mount", "-o", "loop", str(image), str(mountpoint)], check=True)
    print(f"{mountpoint}: {describe(mountpoint)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    d = sub.add_parser("describe", help="the file system holding DIR, in words")
    d.add_argument("dir", type=pathlib.Path)
    j = sub.add_parser("journaled-ext4", help="make and mount a journaled ext4 image")
    j.add_argument("image", type=pathlib.Path)
    j.add_argument("mountpoint", type=pathlib.Path)
    j.add_argument("--size", default="24G", help="the image's size (truncate's syntax)")
    args = ap.parse_args()
    if args.command == "describe":
        print(describe(args.dir))
    else:
        journaled_ext4(args.image, args.mountpoint, args.size)


if __name__ == "__main__":
    sys.exit(main())
