#!/usr/bin/env bash
# The benchmarks recorded under "The CUDA backend on a lent GPU" (docs/benchmarks.md), in one run:
# each step on cuda and on the machine's CPU cores, logs (JSON lines) under $1 (default ./gpu_out).
#
#     bash benchmarks/gpu_suite.sh OUT_DIR [STEP...]
#
# Steps: cold (the bundled cantilever's cold start, twice: the first fills the kernel cache),
# nu (the 128^3 held shell at nu 0.3 and 0.4999, after a 32^3 run that fills the kernel cache), accuracy (the staggered method's time to error on the
# Lame shell and the ball, the three finest sizes), shell256 (the 256^3 shell). Each step has its own time limit
# so that one slow step leaves the others their time.
set -u
out=${1:-gpu_out}; shift || true
steps=${*:-cold nu accuracy}
mkdir -p "$out"
export TI_SKIP_VERSION_CHECK=ON PYTHONUNBUFFERED=1
py=${PYTHON:-python3}
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader >"$out/machine.txt" 2>&1
nproc >>"$out/machine.txt"
"$py" -c "import numpy, scipy, gstaichi; print('numpy', numpy.__version__, 'scipy', scipy.__version__, 'gstaichi', gstaichi.__version__)" >>"$out/machine.txt" 2>&1

step() {  # step NAME LIMIT_S COMMAND...: run, log, keep going whatever it returns
    local name=$1 limit=$2; shift 2
    echo "== $name: $*" | tee -a "$out/steps.log"
    local t0=$SECONDS
    timeout "$limit" "$@" >>"$out/$name.log" 2>&1
    echo "   exit $? after $((SECONDS - t0)) s" | tee -a "$out/steps.log"
}

for s in $steps; do
    case $s in
    cold)
        for arch in ${COLD_ARCHS:-cuda cpu}; do
            step "cold_$arch" 240 "$py" -m benchmarks.cold_start --arch "$arch"  # fills the kernel cache
            step "cold_$arch" 120 "$py" -m benchmarks.cold_start --arch "$arch" --stages
            step "cold_$arch" 120 "$py" -m benchmarks.cold_start --arch "$arch"
        done ;;
    nu)
        for arch in cuda cpu; do
            step "nu_warmup_$arch" 200 "$py" -m benchmarks.staggered --resolution 32 --nu 0.3 0.4999 --arch "$arch"
            step "nu_$arch" 300 "$py" -m benchmarks.staggered --resolution 128 --nu 0.3 0.4999 --arch "$arch" \
                --json "$out/nu_$arch.json"
        done ;;
    accuracy)
        for arch in cuda cpu; do
            step "accuracy_$arch" 300 "$py" -m benchmarks accuracy --problems lame,ball --methods staggered --finest 3 \
                --repeats 1 --arch "$arch" --timeout 120 --out "$out/accuracy_$arch"
        done ;;
    shell256)
        for arch in cuda cpu; do
            step "shell256_$arch" 300 "$py" -m benchmarks.staggered --resolution 256 --arch "$arch" \
                --json "$out/shell256_$arch.json"
        done ;;
    *) echo "unknown step $s" >&2; exit 2 ;;
    esac
done
