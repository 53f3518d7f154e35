#!/usr/bin/env bash
# Stage 2 of bench/device_run.sh (issue 23): the training loop's CUDA sync test, then
# bench/reconstruct.py --device cuda against the same job on the machine's CPU cores, in one run.
# The figures go to OUT/reconstruct.json (one JSON line). Usage: bash bench/device_reconstruct.sh OUT
# ITER (default 3000) steps on the GPU; the CPU follows the same schedule for CPU_ITER (default
# 600) steps on THREADS (default 16) torch threads; SAME_STEPS=1 trains the CPU to ITER too;
# PROJ (default, fused or torch) picks the triton backend's projection, BIN (default, triton or
# torch) its tile binning, FIN (default, triton or torch) its output finish.
set -u
OUT=${1:?usage: bash bench/device_reconstruct.sh OUT}
ITER=${ITER:-3000}
CPU_ITER=${CPU_ITER:-600}
THREADS=${THREADS:-16}
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=$THREADS
mkdir -p "$OUT"
timeout 90 python3 -m pytest -q -p no:cacheprovider tests/reconstruct/test_train_sync.py 2>&1 \
  | tail -40 | tee "$OUT/reconstruct_tests.log"
same=()
[[ ${SAME_STEPS:-0} == 1 ]] && same=(--same-steps)
python3 bench/reconstruct.py --device cuda --skip-tsdf --iterations "$ITER" \
  --cpu-baseline-iterations "$CPU_ITER" "${same[@]}" --threads "$THREADS" \
  --triton-projection "${PROJ:-default}" --triton-binning "${BIN:-default}" \
  --fused-finish "${FIN:-default}" \
  --json "$OUT/reconstruct.json" 2>&1 | grep -v "^\s*$"
