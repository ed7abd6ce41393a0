# Shared by the scripts run on the lent machine (vdi.sh, server.sh): sourced, not run.

# unpack_bins DIR EXE...: the binaries prepare.sh gzipped into .gpu-bin, unpacked into DIR.
unpack_bins() {
    local dir=$1
    shift
    mkdir -p "$dir"
    for exe in "$@"; do
        gunzip -c ".gpu-bin/$exe.gz" > "$dir/$exe"
        chmod +x "$dir/$exe"
    done
}
