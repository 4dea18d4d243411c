#!/usr/bin/env bash
# The GPU acceptance checks of ccjax in one run (docs/gpu.md), each figure printed as it is measured:
#
#   1. benchmarks/gamut.py at 8 / 64 / 1024 surfaces: scenes/s, FLOP/s, bytes/s and the fraction
#      of the float32 peak of CRULE-AVE, ECRULE-SCWIA-12, ECRULE-MV and ND-ECRULE-MV, then each MV
#      method's throughput over CRULE-AVE's (target: at least 0.5);
#   2. `python -m ccjax compare` with an empty cache (target: <= 15 s) and its breakdown
#      (import / fit / compile / run, programs built);
#   3. the same with fits and compiled programs cached but --recompute (target: <= 5 s);
#   4. the default test suite (target: 0 failures), in the time left of the budget.
#
# Usage: benchmarks/gpu_check.sh OUTDIR
#   Run in the repository root with ccjax importable (an installed ccjax, or on the GPU machine
#   after activating the virtual environment (`. .venv/bin/activate`)). Logs go to OUTDIR. Environment:
#     PYTHON=python3          the interpreter
#     GPU_CHECK_QUICK=1       small sizes (a few minutes on a CPU): checks the script, not the targets
#     GPU_CHECK_BUDGET=300    seconds for the whole run; the test suite gets what is left
#                             (default 1200 with GPU_CHECK_QUICK=1, for slow CPUs)
#     GPU_CHECK_WORKERS=6     pytest-xdist workers for the suite
# On a machine without a GPU it runs the same steps on the CPU (the figures are then the CPU's).
set -uo pipefail

if [ $# -ne 1 ]; then
    echo "usage: $0 OUTDIR" >&2
    exit 2
fi
OUT=$1
mkdir -p "$OUT" || exit 2
PYTHON=${PYTHON:-python3}
if [ "${GPU_CHECK_QUICK:-0}" = 1 ]; then
    BUDGET=${GPU_CHECK_BUDGET:-1200}
else
    BUDGET=${GPU_CHECK_BUDGET:-300}
fi
WORKERS=${GPU_CHECK_WORKERS:-6}
START=$SECONDS
HERE=$(cd "$(dirname "$0")" && pwd)

if [ "${GPU_CHECK_QUICK:-0}" = 1 ]; then
    BENCH=(--surfaces 8,64 --blocks 2 --repeats 1 --labels CRULE-AVE,ECRULE-MV)
    COMPARE=(--methods GW,CRULE-AVE,ND-ECRULE-MV --surfaces 8 --scenes 50)
    SUITE=(tests/test_precision.py -k checker)
else
    BENCH=(--surfaces 8,64,1024 --labels CRULE-AVE,ECRULE-SCWIA-12,ECRULE-MV,ND-ECRULE-MV)
    COMPARE=()
    SUITE=(tests)
fi

say() { echo "[gpu_check $((SECONDS - START)) s] $*"; }

say "python: $PYTHON; device: $("$PYTHON" -c 'import jax; d = jax.devices()[0]; print(d.device_kind, jax.default_backend())')"

# 1. Throughput (every row printed as it is measured), then the MV ratios.
say "gamut benchmark ${BENCH[*]}"
"$PYTHON" "$HERE/gamut.py" "${BENCH[@]}" --oracle-scenes 0 --images 0 --sweep-scenes 0 2>&1 \
    | tee "$OUT/gamut.log" | grep --line-buffered -E "surfaces:|^jax|^block"
"$PYTHON" - "$OUT/gamut.log" <<'EOF'
import re, sys
rates = {}
for line in open(sys.argv[1]):
    match = re.match(r"\s+(\S+)\s+(\d+) surfaces:\s+(\d+) scenes/s wall", line)
    if match:
        rates[(match[1], int(match[2]))] = float(match[3])
for (label, n), rate in sorted(rates.items(), key=lambda item: item[0][1]):
    base = rates.get(("CRULE-AVE", n))
    if label.endswith("-MV") and base:
        verdict = "ok" if rate >= 0.5 * base else "MISS"
        print(f"[gpu_check] {label} / CRULE-AVE at {n} surfaces: {rate / base:.2f} ({verdict}, target >= 0.5)")
EOF

# 2 and 3. The main job, cold and cached.
CACHE="$OUT/compare-cache"
rm -rf "$CACHE"
for run in cold recompute; do
    extra=()
    target=15
    if [ "$run" = recompute ]; then
        extra=(--recompute)
        target=5
    fi
    begin=$SECONDS
    CCJAX_CACHE="$CACHE" "$PYTHON" -m ccjax compare "${COMPARE[@]}" "${extra[@]}" --no-progress \
        >"$OUT/compare-$run.log" 2>&1
    status=$?
    wall=$((SECONDS - begin))
    verdict=$([ "$status" = 0 ] && [ "$wall" -le "$target" ] && echo ok || echo MISS)
    say "compare $run: exit $status, ${wall} s wall ($verdict, target <= $target s)"
    grep -E "^done in" "$OUT/compare-$run.log" | sed 's/^/[gpu_check]   /'
done

# 4. The default suite in the time left.
left=$((BUDGET - (SECONDS - START)))
if [ "$left" -lt 30 ]; then
    say "test suite: skipped, ${left} s of the ${BUDGET} s budget left"
else
    say "test suite (${SUITE[*]}, -n $WORKERS, up to ${left} s)"
    xdist=()
    "$PYTHON" -c "import xdist" 2>/dev/null && xdist=(-n "$WORKERS")
    timeout "$left" "$PYTHON" -m pytest -q -p no:cacheprovider "${xdist[@]}" "${SUITE[@]}" >"$OUT/pytest.log" 2>&1
    status=$?
    say "test suite: exit $status; $(tail -n 1 "$OUT/pytest.log")"
fi
say "done; logs in $OUT"
