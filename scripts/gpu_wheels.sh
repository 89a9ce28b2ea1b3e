#!/usr/bin/env bash
# Fetch, here, the wheels that scripts/gpu_check.sh installs on a GPU machine that cannot reach
# any package index (the workplace's device machine: Python 3.12, x86-64, with numpy, scipy,
# h5py, matplotlib, numba, tqdm, absl-py, etils and pytest already there).
#
# The wheels (about 175 MiB: warp-lang alone is 149 MiB) go to .whl/ and are
# packed into parts of at most PART_MIB (default 48) MiB each, .whl/part1, .whl/part2, ..., big
# files split into pieces, because one device call carries at most 64 MiB. Stage the parts on
# one warm machine, one call each, back to back (a machine goes back after 30 s idle):
#
#   run(carry=[".whl/part1"], command="mkdir -p /tmp/whl && cp .whl/part1/* /tmp/whl/")
#   run(carry=[".whl/part2"], command="cp .whl/part2/* /tmp/whl/")
#   ...                                        (one call per part; this script lists them)
#   run(command="bash scripts/gpu_check.sh", timeout_s=600)
#
# Usage: bash scripts/gpu_wheels.sh          (then add /.whl/ to .git/info/exclude; it is)
set -euo pipefail
cd "$(dirname "$0")/.."
PART_MIB=${PART_MIB:-48}
PYTHON=${PYTHON:-python3}
grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo '/.whl/' >> .git/info/exclude
rm -rf .whl && mkdir -p .whl/all
platforms=()
for p in manylinux_2_17_x86_64 manylinux2014_x86_64 manylinux_2_24_x86_64 manylinux_2_27_x86_64 \
    manylinux_2_28_x86_64 manylinux_2_31_x86_64 manylinux_2_34_x86_64 manylinux_2_35_x86_64; do
    platforms+=(--platform "$p")
done
# The project's dependencies missing on the device image, the sim extra, and the warp extra
# (pinned to the versions this repository was checked with). mujoco's viewer packages
# (mujoco-studio, glfw, pyopengl) are left out: nothing here renders.
"$PYTHON" -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp "${platforms[@]}" -d .whl/all \
    trimesh manifold3d rtree python-fcl clarabel coacd \
    mujoco==4.0.0 mujoco-core==4.0.0 dm-control dm-env dm-tree labmaze gymnasium \
    farama-notifications mujoco-warp==4.0.0 warp-lang==1.19.0
# dm-control's wheel is 56 MiB of task assets; the scene needs only its Python modules (mjcf and
# what it imports): they travel as a tar of those folders, unpacked by gpu_check.sh.
"$PYTHON" - .whl/all/dm_control-*.whl .whl/all/dm_control_modules.tar <<'PY'
import sys, tarfile, zipfile, io
keep = ("__init__.py", "_render/", "autowrap/", "mjcf/", "mujoco/", "rl/", "utils/")
with zipfile.ZipFile(sys.argv[1]) as wheel, tarfile.open(sys.argv[2], "w") as tar:
    for name in wheel.namelist():
        if name.startswith("dm_control/") and name[len("dm_control/"):].startswith(keep):
            data = wheel.read(name)
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
PY
rm .whl/all/dm_control-*.whl
# Pack into parts of at most PART_MIB MiB (files larger than that are split into pieces that
# gpu_check.sh joins again: NAME.whl.part-aa, -ab, ...).
limit=$((PART_MIB * 1024 * 1024))
part=1 used=0
mkdir -p ".whl/part$part"
place() {  # place FILE SIZE: into the current part, or a new one when it would overflow
    if (( used + $2 > limit )); then part=$((part + 1)) used=0; mkdir -p ".whl/part$part"; fi
    mv "$1" ".whl/part$part/" && used=$((used + $2))
}
for f in $(ls -S .whl/all); do
    path=".whl/all/$f" size=$(stat -c %s ".whl/all/$f")
    if (( size > limit )); then
        split -b "$limit" "$path" "$path.part-" && rm "$path"
        for piece in "$path".part-*; do place "$piece" "$(stat -c %s "$piece")"; done
    else
        place "$path" "$size"
    fi
done
rmdir .whl/all
echo "wheels in $part parts under .whl/ (at most $PART_MIB MiB each):"
for d in .whl/part*; do echo "  $d: $(du -sh "$d" | cut -f1)"; done
echo "stage them on one warm device machine, one call each, then run scripts/gpu_check.sh:"
echo "  run(carry=[\".whl/part1\"], command=\"mkdir -p /tmp/whl && cp .whl/part1/* /tmp/whl/\")"
for ((k = 2; k <= part; k++)); do
    echo "  run(carry=[\".whl/part$k\"], command=\"cp .whl/part$k/* /tmp/whl/\")"
done
echo "  run(command=\"bash scripts/gpu_check.sh\", timeout_s=600)"
