#!/usr/bin/env bash
# One lent-GPU session for issue 23, prepared and tried on the CPU first (see bench/RESULTS.md).
# Carry .whl (the project's missing dependencies and a robogs wheel for its metadata, filled by
# bench/device_wheels.sh here); the working tree comes first
# on PYTHONPATH. Stages, run in this order: 1 = CUDA render and training-step tests; 2 = the reconstruct
# bench (bench/device_reconstruct.sh; PROJ=fused|torch picks the triton projection); r = the render
# bench against the CPU; s = sweep of
# the Triton kernels (and the other projection than the default) and a profile; g = gsplat side by
# side (bench/gsplat_side.py), with gsplat unpacked from the tarball bench/gsplat_aot.sh leaves in
# .whl (the image has no nvcc to JIT it).
# Usage there: bash bench/device_run.sh [12rsg]
set -u
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=16
OUT=${OUT:-/tmp/robogs-device-out}
mkdir -p "$OUT"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
  --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=$PWD:/tmp/site
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv; nproc;
  python3 -c "import torch, triton; print(torch.__version__, triton.__version__, torch.cuda.get_device_name())"
  python3 -c "from robogs.format.render.backends import backend_entries as b; [print(e.name, e.status, e.reason) for e in b()]"
} 2>&1 | tee "$OUT/env.txt"
stage=${1:-12rs}
if [[ $stage == *1* ]]; then
  timeout 150 python3 -m pytest -q -p no:cacheprovider -n 8 tests/render/test_triton_backend.py \
    tests/render/test_triton_project.py tests/render/test_triton_binning.py \
    tests/render/test_triton_finish.py tests/render/test_oracle.py \
    tests/render/test_means2d_grad.py \
    tests/reconstruct/test_step_loss.py tests/reconstruct/test_model_adam.py \
    tests/reconstruct/test_train_sync.py 2>&1 | tail -25 \
    | tee "$OUT/tests.log"
fi
if [[ $stage == *2* ]] && [[ -f bench/device_reconstruct.sh ]]; then
  timeout 220 bash bench/device_reconstruct.sh "$OUT" 2>&1 | tail -40 | tee "$OUT/reconstruct.log"
fi
if [[ $stage == *r* ]]; then
  timeout 120 python3 bench/render.py --only gpu --device cuda --threads 16 --repeats 5 --no-append \
    --json "$OUT/render.json" 2>&1 | tee "$OUT/render.log"
fi
if [[ $stage == *s* ]]; then
  timeout 150 python3 bench/triton_sweep.py --repeats 20 --triton-binning --fused-finish \
    --defaults-only --profile \
    --json "$OUT/sweep.json" 2>&1 \
    | tee "$OUT/sweep.log"
fi
if [[ $stage == *g* ]]; then
  for tgz in .whl/gsplat-*-aot-*.tar.gz; do [[ -f $tgz ]] && tar -xzf "$tgz" -C /tmp/site; done
  timeout 150 python3 bench/gsplat_side.py --repeats 20 --json "$OUT/gsplat.json" 2>&1 \
    | tee "$OUT/gsplat.log"
fi
