#!/usr/bin/env bash
# The GPU numbers of benchmarks/README.md, in one run on a machine with a GPU and
# jax[cuda], equinox, optimistix and lineax installed (jaxcable from this checkout):
#
#     OUT=results_dir bash benchmarks/gpu_suite.sh
#
# 1. the two-pass kernel on 1e5 cables x 2000 samples (float32 and float64);
# 2. the Monte-Carlo of 1e5 draws x 8 cables x 2000 samples;
# 3. fit_each of 1024 specimens (benchmarks/fit_each.py's problem).
# Each step has its own time limit, so that one slow step leaves the others' results.
set -u
OUT=${OUT:-gpu_results}
mkdir -p "$OUT"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
python3 -c "import jax; print(jax.__version__, jax.devices())" 2>&1 | tee "$OUT/devices.txt"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 | tee -a "$OUT/devices.txt"
run() {
    local name=$1 limit=$2
    shift 2
    echo "== $name: $*"
    local t0=$SECONDS
    timeout "$limit" python3 "$@" --json-out "$OUT/$name.json" >"$OUT/$name.log" 2>&1
    echo "rc $? in $((SECONDS - t0)) s"
    tail -n 25 "$OUT/$name.log"
}
run throughput_f32 100 benchmarks/throughput.py --batches 1,1024,100000 --lengths 2000 \
    --length-batches 1 --numpy-batches 1 --grad-batch 1024 --repeats 3 --max-seconds 30
run throughput_f64 100 benchmarks/throughput.py --x64 --batches 1,100000 --lengths 2000 \
    --length-batches 1 --numpy-batches 1 --grad-batch 1024 --repeats 3 --max-seconds 30
run montecarlo 120 benchmarks/montecarlo.py --draws 100000 --cables 8 --samples 2000 \
    --baseline-draws 256 --no-progress
run fit_each 150 benchmarks/fit_each.py --specimens 1024 --loop-specimens 2 \
    --scipy-specimens 1
