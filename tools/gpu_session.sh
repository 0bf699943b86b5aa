#!/usr/bin/env bash
# GPU checks and benchmarks on a lent NVIDIA machine (no network there): the Python packages it
# lacks travel as wheels in .whl/ (ignored by git), fetched here with
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#       --platform manylinux_2_27_x86_64 -d .whl taichi==1.7.4 dill cma SALib multiprocess \
#       gymnasium farama-notifications
# (the taichi wheel, 56 MB, fits the 64 MiB transfer only without taichi/_lib/c_api, which the
# Python package does not use: unzip, delete that folder and its RECORD lines, zip again).
# Once the tracked tree outgrew what is left of the 64 MiB, the same wheels travel unpacked and
# xz-compressed instead (25 MB): .gpu_site/site.tar.xz (ignored by git), made here with
#   mkdir site && for w in .whl/*.whl; do unzip -q -o "$w" -d site; done
#   tar -cJf .gpu_site/site.tar.xz -C site .
# and used when present (carry .gpu_site instead of .whl).
# Usage: bash tools/gpu_session.sh PHASE
#   correctness  the engine-vs-reference, determinism, sensitivities-vs-differences and GPU-vs-CPU
#                tests with --arch gpu (junit.xml holds the GPU-vs-CPU sensitivities' largest
#                difference), and the Fig. 4c study on the GPU compared with results/fig4c.csv
#   layouts      the layout and block-size alternatives at B = 8192 (paper, f64, Newton)
#   bench        the GPU benchmark into $OUT (results/bench_gpu.csv when committed), one part
#                per call: PRESETS=paper|accurate, PRECISIONS=f64|f32, SIZES=..., LIMIT=seconds,
#                JACOBIANS (default newton,chord) and DURATION (the accurate preset's simulated
#                seconds, default one period)
#   compare      the B sweep of PRESETS (default paper; f64, SIZES) with this checkout,
#                then with a baseline commit's source exported into .base/ (ignored by git):
#                  mkdir .base && git archive BASE taichi_star studies | tar -x -C .base
#                back to back on the same card, LIMIT seconds each
#   ab           a change against .base/ (as for compare) at one size, alternated: ROUNDS rounds
#                (default 2) of this checkout then .base/, each one `bench` of PRESETS (default
#                paper), SIZES (default 65536), JACOBIANS (default newton), f64; each run's table
#                goes to $OUT as r<round>_after.csv, r<round>_before.csv (+ sidecars) as soon as
#                it is written, so a run cut short keeps what it measured (its log is the
#                call's output: the device returns at most eight files, so at most 2 rounds)
#   occupancy    Nsight Compute's launch and occupancy figures of the accurate preset's two step
#                kernels (adaptive and fixed steps, tools/gpu_kernels.py at BATCH instances)
# The tracked tree with results/ is larger than the device's 64 MiB transfer: call the device
# tool with results/ out of git's index but for results/fig4c.csv, which correctness reads (no
# other phase reads results/), and put it back after:
#   git rm -r -q --cached results && git reset -q results/fig4c.csv \
#       && echo /results/ >> .git/info/exclude                               # before
#   git reset -q results && sed -i '\#^/results/$#d' .git/info/exclude      # after
# Correctness runs at most LIMIT seconds of tests (default 300) and FIG4C=0 skips its study.
# Everything it writes is packed into $OUT/PHASE.tar.gz (the device returns few files).
set -o pipefail
phase=${1:?phase}
# installed once per machine: later phases of the same lease reuse it
if [ ! -d /tmp/site/taichi ]; then
    if [ -f .gpu_site/site.tar.xz ]; then
        mkdir -p /tmp/site && tar -xJf .gpu_site/site.tar.xz -C /tmp/site || exit 1
    else
        python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
            --target /tmp/site .whl/*.whl || exit 1
    fi
fi
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
work=$(mktemp -d)
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$work/gpu.txt"
git rev-parse HEAD 2>/dev/null | tee -a "$work/gpu.txt"
case "$phase" in
correctness)
    timeout "${LIMIT:-300}" python3 -m pytest -q -p no:cacheprovider --arch gpu \
        --junitxml "$work/junit.xml" tests/model/test_gpu.py tests/model/test_sensitivities.py \
        tests/model/test_determinism.py tests/model/test_engine.py \
        -k "reference or alone or bitwise or batch_position or gpu or equal_finite or bdf2_with" \
        2>&1 | tee "$work/pytest.log"
    [ "${FIG4C:-1}" = 1 ] || { tar -czf "$OUT/$phase.tar.gz" -C "$work" .; exit 0; }
    /usr/bin/time -v python3 -m studies fig4c --arch gpu --out "$work/fig4c_gpu" 2>&1 \
        | tail -30 | tee "$work/fig4c.log"
    python3 - "$work/fig4c_gpu/fig4c.csv" <<'PY' | tee "$work/fig4c_compare.txt"
import sys
import pandas as pd
gpu, cpu = pd.read_csv(sys.argv[1]), pd.read_csv("results/fig4c.csv")
for column in ("sim_speed_mm_s", "sim_signed_speed_mm_s"):
    relative = ((gpu[column] - cpu[column]).abs() / cpu[column].abs()).max()
    print(f"fig4c {column}: GPU vs CPU max relative difference {relative:.3e}")
print(pd.DataFrame({"gait": cpu.gait, "cpu": cpu.sim_speed_mm_s, "gpu": gpu.sim_speed_mm_s}))
PY
    ;;
layouts)
    python3 -m studies bench --arch gpu --batch-sizes 8192 --precisions f64 --jacobians newton \
        --layouts instance_minor,instance_major --gpu-block-dims "${BLOCKS:-32,64,128}" \
        --scenarios none --workers-list none --no-cache-probe --repeats 2 --steps 60 \
        --out "$work/layouts" 2>&1 | tee "$work/layouts.log"
    ;;
bench)
    # one call of the device tool runs at most 10 minutes: the paper sweep of 7 sizes in one
    # precision (Newton and chord) took about 4 minutes on an H100, the accurate preset about
    # 2.5 minutes per size at B = 65,536 (compile, an untimed and a timed period); bench rewrites
    # its table after every measurement, so a run stopped by `timeout` keeps what it measured
    timeout "${LIMIT:-540}" python3 -m studies bench --arch gpu \
        --batch-sizes "${SIZES:-256,1024,4096,8192,16384,32768,65536}" \
        --precisions "${PRECISIONS:-f64}" --presets "${PRESETS:-paper}" \
        --jacobians "${JACOBIANS:-newton,chord}" \
        ${DURATION:+--accurate-duration "$DURATION"} --scenarios "${SCENARIOS:-none}" \
        --scenario-batch 8192 --workers-list none \
        --no-cache-probe --no-plain-call --sensitivity-counts none --out "$work/bench" 2>&1 | tee "$work/bench.log"
    ;;
compare)
    sweep=(--arch gpu --batch-sizes "${SIZES:-8192,65536}" --precisions f64 --presets "${PRESETS:-paper}"
           --scenarios none --workers-list none --no-cache-probe --no-plain-call
           --sensitivity-counts none)
    timeout "${LIMIT:-120}" python3 -m studies bench "${sweep[@]}" \
        --out "$work/today" 2>&1 | tee "$work/today.log"
    (cd .base && PYTHONPATH=/tmp/site:$PWD timeout "${LIMIT:-120}" python3 -m studies bench \
        "${sweep[@]}" --out "$work/base" 2>&1 | tee "$work/base.log")
    ;;
ab)
    for round in $(seq "${ROUNDS:-2}"); do
        for build in after before; do
            tree=$PWD
            [ "$build" = before ] && tree=$PWD/.base
            (cd "$tree" && PYTHONPATH=/tmp/site:$tree timeout "${LIMIT:-70}" python3 -m studies \
                bench --arch gpu --batch-sizes "${SIZES:-65536}" --precisions f64 \
                --presets "${PRESETS:-paper}" --jacobians "${JACOBIANS:-newton}" --scenarios none \
                --workers-list none --no-cache-probe --no-plain-call --sensitivity-counts none \
                --repeats 2 --out "$work/r${round}_$build" 2>&1 | tee -a "$work/ab.log")
            for file in bench_gpu.csv bench_gpu.csv.json; do
                cp "$work/r${round}_$build/$file" "$OUT/r${round}_$build${file#bench_gpu}"
            done
        done
    done
    ;;
occupancy)
    ncu=$(command -v ncu || ls /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1)
    timeout "${LIMIT:-150}" "$ncu" --target-processes all --kernel-name regex:advance \
        --launch-count "${COUNT:-3}" --metrics launch__registers_per_thread,\
launch__occupancy_limit_registers,launch__block_size,launch__grid_size,\
sm__warps_active.avg.pct_of_peak_sustained_active,smsp__thread_inst_executed_per_inst_executed.ratio,\
gpu__time_duration.sum,l1tex__t_bytes_pipe_lsu_mem_local_op_ld.sum,dram__bytes.sum \
        python3 tools/gpu_kernels.py --batch "${BATCH:-8192}" 2>&1 | tee "$work/ncu.log"
    ;;
*)
    echo "unknown phase $phase"; exit 2 ;;
esac
status=$?
# ab's eight tables are all the files the device returns
[ "$phase" = ab ] && exit $status
tar -czf "$OUT/$phase${PRESETS:+_${PRESETS//,/_}}${PRECISIONS:+_${PRECISIONS//,/_}}.tar.gz" -C "$work" .
exit $status
