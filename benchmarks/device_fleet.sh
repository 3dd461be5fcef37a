#!/usr/bin/env bash
# Fleet throughput on a GPU machine that has JAX with CUDA but no network (benchmarks/README.md,
# "Fleet throughput", "On a GPU"). Run from the repository root:
#
#   benchmarks/device_fleet.sh WHEELS OUT PINNED RECORDS:SIZES [RECORDS:SIZES ...]
#
# WHEELS: folder of wheels to install without dependencies (dtwin's own wheel, npTDMS, pyuff);
# OUT: folder for the JSON lines (fleet.jsonl) and logs;
# PINNED: folder of the diffrax/equinox/optimistix/lineax wheels the project was measured with
#   on the CPU, used only when the machine's own versions fail on the first size ("-": none);
# RECORDS:SIZES: a fleet pickle written beforehand on another machine by
#   `python benchmarks/bench_fleet.py --sizes N --records-file RECORDS [--duration D]` (so the
#   GPU machine does not simulate it) and the batch sizes to time on it, e.g. fleet.pkl:3,32,256.
set -u
WHEELS=$1 OUT=$2 PINNED=$3
shift 3
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm --format=csv | tee "$OUT/gpu.txt"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/dtwin_site \
    "$WHEELS"/*.whl || exit 1
export PYTHONPATH=/tmp/dtwin_site JAX_ENABLE_X64=1 PYTHONUNBUFFERED=1
versions='import jax, diffrax, optimistix, equinox, lineax, numpy, scipy
print("jax", jax.__version__, "diffrax", diffrax.__version__, "optimistix", optimistix.__version__,
      "equinox", equinox.__version__, "lineax", lineax.__version__, "numpy", numpy.__version__,
      "scipy", scipy.__version__, jax.devices())
import jax.numpy as jnp
from dtwin.identify.fit import batch_mode
print("dtype", jnp.zeros(1).dtype, "batch", batch_mode())'
python3 -P -c "$versions" 2>&1 | tee -a "$OUT/gpu.txt"
bench() {  # RECORDS SIZES
    echo "== $1: sizes $2 ($(date -u +%T))" | tee -a "$OUT/log.txt"
    python3 benchmarks/bench_fleet.py --no-loop --records-file "$1" --out "$OUT/fleet.jsonl" \
        --sizes "$2" 2>&1 | grep -v '^E[0-9]\{4\} ' | tee -a "$OUT/log.txt"
    return "${PIPESTATUS[0]}"
}
spec=$1
shift
records=${spec%%:*} sizes=${spec#*:}
first=${sizes%%,*}
if ! bench "$records" "$first" && [ "$PINNED" != "-" ]; then
    echo "== the machine's packages failed: again with the pinned ones" | tee -a "$OUT/log.txt"
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target \
        /tmp/dtwin_pinned "$PINNED"/*.whl || exit 1
    export PYTHONPATH=/tmp/dtwin_pinned:/tmp/dtwin_site
    python3 -P -c "$versions" 2>&1 | tee -a "$OUT/gpu.txt"
    bench "$records" "$first" || exit 1
fi
[ "${sizes#*,}" != "$sizes" ] && bench "$records" "${sizes#*,}"
for spec in "$@"; do
    bench "${spec%%:*}" "${spec#*:}"
done
exit 0
