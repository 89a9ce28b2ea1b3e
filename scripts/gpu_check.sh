#!/usr/bin/env bash
# MuJoCo Warp on a GPU, in one command: install, check against C MuJoCo, measure. Every result
# goes to $OUT (the device tool's output folder; runs/gpu elsewhere):
#
#   env.json         GPU, driver, versions
#   details.txt      every stage's printed output: nvidia-smi, tests/test_warp.py on the GPU
#                    (DG16M_WARP_DEVICE: Warp against C MuJoCo), the benches' reports
#   throughput.json  bench/warp_throughput.py: trials/s per world count, memory, vs one C core
#   agreement.json   bench/warp_agreement.py: a seeded sample of benchmark rows (all arms)
#                    labelled by both engines, Warp run twice (non-determinism)
#   rebuild.json     the procedural v2 benchmark rebuilt on the GPU (8 processes) in the time
#                    left: wall time, objects done; when it finishes, its labels against the
#                    shipped file's (rebuild_agreement.json)
#   log.txt          what ran, with times
# (at most 7 files: the device tool returns 8 at the most)
#
# Wheels: on the workplace's device machine nothing can be downloaded; scripts/gpu_wheels.sh
# (run here) fetches them and says how to stage them in /tmp/whl. Elsewhere, with the
# packages installed (pip install -e '.[warp]'), this script uses them as they are.
#
# Budget: TOTAL_S (default 560 s, inside the device tool's 10 minutes per command). Each stage
# has its own timeout and the rebuild gets what is left; a stage that times out leaves what it
# measured. Environment: DEVICE (default cuda:0), STAGE (default /tmp/whl), OUT, PYTHON; QUICK=1
# shrinks every stage (a dry run of the script itself, e.g. DEVICE=cpu on a machine without a
# GPU).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-runs/gpu}
DEVICE=${DEVICE:-cuda:0}
STAGE=${STAGE:-/tmp/whl}
PYTHON=${PYTHON:-python3}
TOTAL_S=${TOTAL_S:-560}
if [ "${QUICK:-0}" = 1 ]; then
    THROUGHPUT=(--objects 1 --trials 36 --worlds 32 --cpu-trials 18)
    AGREEMENT=(--rows 4 --repeat)
else
    THROUGHPUT=(--objects 2 --worlds 1024 4096 8192 --cpu-trials 90)
    AGREEMENT=(--objects 4 --repeat)
fi
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
export MUJOCO_GL=${MUJOCO_GL:-disable}  # nothing here renders (pyopengl is not carried)
log() { echo "[$(date +%T)] $*" | tee -a "$OUT/log.txt"; }
TMP=$(mktemp -d)
keep() { { echo; echo "===== $1 ====="; cat "$TMP/$1.txt"; } >> "$OUT/details.txt"; }

# 1. Install the staged wheels (joining split pieces first).
if [ -d "$STAGE" ]; then
    for first in "$STAGE"/*.part-aa; do
        [ -e "$first" ] || continue
        whole=${first%.part-aa}
        cat "$whole".part-* > "$whole" && rm "$whole".part-*
    done
    log "installing $(ls "$STAGE"/*.whl | wc -l) wheels from $STAGE"
    "$PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site "$STAGE"/*.whl >> "$OUT/log.txt" 2>&1 || { log "install failed"; exit 1; }
    tar -xf "$STAGE"/dm_control_modules.tar -C /tmp/site  # dm-control's Python modules only
    export PYTHONPATH=/tmp/site:$PWD
else
    export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
fi
nvidia-smi > "$TMP/nvidia-smi.txt" 2>&1; keep nvidia-smi
"$PYTHON" - "$DEVICE" > "$OUT/env.json" 2>> "$OUT/log.txt" <<'EOF'
import json, platform, sys
import warp as wp
wp.config.quiet = True
wp.config.log_level = wp.LOG_WARNING  # no start-up banner in the JSON
import mujoco, mujoco_warp
device = wp.get_device(sys.argv[1])
print(json.dumps({
    "device": str(device), "name": device.name, "total_memory_gib": device.total_memory / 2**30,
    "python": platform.python_version(), "mujoco": mujoco.__version__,
    "mujoco_warp": mujoco_warp.__version__, "warp": wp.config.version,
}, indent=2))
EOF
log "environment: $(tr -d '\n' < "$OUT/env.json")"

# 2. Correctness on the GPU (also compiles and caches the kernels for the stages below).
log "tests/test_warp.py on $DEVICE"
DG16M_WARP_DEVICE=$DEVICE timeout 200 "$PYTHON" -m pytest -q -p no:cacheprovider -m warp \
    tests/test_warp.py > "$TMP/pytest.txt" 2>&1
log "pytest exit $? ($(tail -1 "$TMP/pytest.txt"))"; keep pytest

# 3. Throughput: trials/s per world count against one C MuJoCo core, memory.
log "throughput"
timeout 120 "$PYTHON" bench/warp_throughput.py --device "$DEVICE" "${THROUGHPUT[@]}" \
    --json "$OUT/throughput.json" > "$TMP/throughput.txt" 2>&1
log "throughput exit $? ($(grep -E 'meets|misses|Error' "$TMP/throughput.txt" | tail -1))"
keep throughput

# 4. Agreement with C MuJoCo on a seeded sample of rows, Warp run twice.
log "agreement"
timeout 120 "$PYTHON" bench/warp_agreement.py --device "$DEVICE" "${AGREEMENT[@]}" \
    --json "$OUT/agreement.json" > "$TMP/agreement.txt" 2>&1
log "agreement exit $? ($(grep -E 'meets|misses|Error' "$TMP/agreement.txt" | tail -1))"
keep agreement

# 5. The procedural v2 rebuild on the GPU (8 processes share it; sampling runs on their cores).
REBUILD_S=$((TOTAL_S - SECONDS - 45))
if [ "$REBUILD_S" -lt 30 ]; then REBUILD_S=30; fi
log "rebuild (at most $REBUILD_S s)"
rm -rf /tmp/v2_warp  # a fresh build, not a resume
timeout "$REBUILD_S" "$PYTHON" - "$DEVICE" "$OUT" <<'EOF' >> "$OUT/log.txt" 2>&1
import json, sys, time
from pathlib import Path
from dg16m_env.benchmark import BenchmarkParameters, build_benchmark, procedural_benchmark_sources
from dg16m_env.physics.simulator import Simulator

device, out = sys.argv[1], Path(sys.argv[2])
start = time.perf_counter()
path = build_benchmark(
    procedural_benchmark_sources(), "/tmp/v2_warp", BenchmarkParameters(), workers=8,
    progress=False, simulator=Simulator(name="warp", device=device),
)
(out / "rebuild.json").write_text(json.dumps({"wall_s": time.perf_counter() - start,
                                             "file": str(path), "finished": True}))
EOF
status=$?
done_objects=$(ls /tmp/v2_warp/objects 2>/dev/null | wc -l)
if [ ! -s "$OUT/rebuild.json" ]; then
    echo "{\"finished\": false, \"limit_s\": $REBUILD_S, \"objects_done\": $done_objects}" \
        > "$OUT/rebuild.json"
fi
log "rebuild exit $status: $(cat "$OUT/rebuild.json") ($done_objects objects written)"
if [ -s /tmp/v2_warp/benchmark.h5 ]; then
    timeout 40 "$PYTHON" bench/warp_agreement.py --against /tmp/v2_warp/benchmark.h5 \
        --json "$OUT/rebuild_agreement.json" > "$TMP/rebuild_agreement.txt" 2>&1
    log "rebuild labels vs the shipped file: $(grep -E 'meets|misses|expected' \
        "$TMP/rebuild_agreement.txt" | tail -1)"
    keep rebuild_agreement
fi
log "done"
