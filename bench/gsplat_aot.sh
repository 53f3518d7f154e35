#!/usr/bin/env bash
# Build gsplat's CUDA extension ahead of time, here on the CPU, for the lent GPU (issue 23:
# "within 3x of gsplat"). PyPI ships gsplat only as a JIT wheel (sources compiled on first
# import), and the lent machine's image has no nvcc, so the extension is compiled here against
# the same torch build that machine runs (2.11.0+cu130, CPython 3.12) with NVIDIA's nvcc 13.0
# wheels, for sm_90 only (H100/H200), and carried as a tarball in .whl/.
#
# gsplat's own loader (gsplat/cuda/_backend.py) imports `gsplat.csrc` before it tries to JIT, so
# the compiled module is dropped in as gsplat/csrc.cpython-312-x86_64-linux-gnu.so. The flags
# follow what torch.utils.cpp_extension passes to nvcc and g++ (torch's own C++ ABI, the
# half-precision operator guards, relaxed constexpr) and gsplat's (-O3, --use_fast_math, its
# include dirs and glm). Nothing here imports torch: this CPU machine's torch is another build.
#
# Usage: bash bench/gsplat_aot.sh            (downloads with pip, ~650 MB, then compiles;
#        JOBS=2 nice; about 30-60 min on 2 cores)
# Output: .whl/gsplat-1.5.3-aot-sm90-cp312.tar.gz, unpacked by bench/device_run.sh into its
#         site dir when present.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
W=${GSPLAT_WORK:-/tmp/gsplat_aot}
JOBS=${JOBS:-2}
ARCH=${ARCH:-90}
PY312=${PY312:-python3.12}
PIP=${PIP:-"$ROOT/.venv/bin/pip"}
mkdir -p "$W/dl" "$W/obj"
cd "$W"

plat="--no-deps --only-binary=:all: --python-version 3.12 --implementation cp
  --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64
  --platform manylinux_2_12_x86_64 -d dl"
# shellcheck disable=SC2086
[ -n "$(ls dl/torch-2.11.0-* 2>/dev/null)" ] || "$PIP" download -q $plat torch==2.11.0
# shellcheck disable=SC2086
"$PIP" download -q $plat gsplat==1.5.3 nvidia-cuda-nvcc==13.0.88 nvidia-cuda-runtime==13.0.96 \
  nvidia-cuda-cccl==13.0.85 nvidia-cuda-crt==13.0.88 nvidia-nvvm==13.0.88

if [ ! -x tc/nvidia/cu13/bin/nvcc ]; then
  for w in dl/nvidia_*.whl; do unzip -q -o "$w" -d tc; done
fi
[ -d torchw/torch/include ] || unzip -q -o dl/torch-2.11.0-*.whl 'torch/include/*' 'torch/lib/*' \
  'torch/version.py' -d torchw
grep -q "2.11.0+cu130" torchw/torch/version.py || { echo "torch wheel is not 2.11.0+cu130" >&2; exit 1; }
[ -d src/gsplat ] || unzip -q -o dl/gsplat-1.5.3-py3-none-any.whl -d src

CU=$W/tc/nvidia/cu13
TI=$W/torchw/torch/include
G=$W/src/gsplat/cuda
PYI=$("$PY312" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
INC=(-I"$TI" -I"$TI/torch/csrc/api/include" -I"$CU/include" -isystem "$CU/include/cccl"
  -I"$PYI" -I"$G/include" -I"$G/csrc/third_party/glm")
DEFS=(-DTORCH_EXTENSION_NAME=csrc -DTORCH_API_INCLUDE_EXTENSION_H -D_GLIBCXX_USE_CXX11_ABI=1)
NVCC_FLAGS=(-O3 --use_fast_math -std=c++17 --expt-relaxed-constexpr -diag-suppress=20012
  -D__CUDA_NO_HALF_OPERATORS__ -D__CUDA_NO_HALF_CONVERSIONS__ -D__CUDA_NO_BFLOAT16_CONVERSIONS__
  -D__CUDA_NO_HALF2_OPERATORS__ -gencode="arch=compute_$ARCH,code=sm_$ARCH"
  --compiler-options=-fPIC -ccbin=g++)
CXX_FLAGS=(-O3 -std=c++17 -fPIC -Wno-attributes)
export PATH="$CU/bin:$PATH"

compile() {  # one source -> obj/<name>.o, skipped when up to date
  local s=$1 o
  o="$W/obj/$(basename "$s").o"
  [ "$o" -nt "$s" ] && return 0
  local t0=$SECONDS
  case "$s" in
    *.cu) nice -n 19 nvcc "${NVCC_FLAGS[@]}" "${DEFS[@]}" "${INC[@]}" -c "$s" -o "$o.tmp" ;;
    *) nice -n 19 g++ "${CXX_FLAGS[@]}" "${DEFS[@]}" "${INC[@]}" -c "$s" -o "$o.tmp" ;;
  esac
  mv "$o.tmp" "$o"
  echo "compiled $(basename "$s") in $((SECONDS - t0)) s"
}
t_start=$SECONDS
srcs=("$G"/csrc/*.cu "$G"/csrc/*.cpp "$G/ext.cpp")
for s in "${srcs[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do sleep 1; done
  compile "$s" &
done
wait
n_obj=$(ls obj/*.o | wc -l)
[ "$n_obj" -eq "${#srcs[@]}" ] || { echo "only $n_obj of ${#srcs[@]} objects built" >&2; exit 1; }

so=src/gsplat/csrc.cpython-312-x86_64-linux-gnu.so
g++ -shared -o "$so" obj/*.o -L"$W/torchw/torch/lib" -lc10 -ltorch -ltorch_cpu -ltorch_python \
  -lc10_cuda -ltorch_cuda -L"$CU/lib" -l:libcudart.so.13
echo "built $so ($(du -h "$so" | cut -f1)) in $((SECONDS - t_start)) s with $JOBS jobs"
# every symbol the module needs must be defined by torch 2.11, cudart 13 or the C/C++ runtimes
# (nothing here can load it: that needs the GPU machine's CUDA libraries)
nm -D --undefined-only "$so" | awk '{print $2}' | sed 's/@.*//' | sort -u > undef.txt
for l in torchw/torch/lib/*.so* "$CU/lib/libcudart.so.13" /usr/lib/x86_64-linux-gnu/libstdc++.so.6 \
  /lib/x86_64-linux-gnu/libc.so.6 /lib/x86_64-linux-gnu/libm.so.6 /lib/x86_64-linux-gnu/libgcc_s.so.1 \
  "$("$PY312" -c "import sys; print(sys.executable)")" \
  "$("$PY312" -c "import sysconfig as s; print(s.get_config_var('LIBDIR'))")"/libpython3.12.so*; do
  nm -D --defined-only "$l" 2>/dev/null | awk '{print $3}' | sed 's/@.*//'
done | sort -u > def.txt
missing=$(comm -23 undef.txt def.txt | grep -v -E '^(_ITM_|__gmon_start__|__tls_get_addr)' || true)
[ -z "$missing" ] || { echo "unresolved symbols:" >&2; echo "$missing" | head >&2; exit 1; }
echo "all $(wc -l < undef.txt) undefined symbols resolve against torch 2.11.0+cu130 and cudart 13"

mkdir -p "$ROOT/.whl"
tar -C src -czf "$ROOT/.whl/gsplat-1.5.3-aot-sm${ARCH}-cp312.tar.gz" \
  --exclude='gsplat/cuda/csrc/*' gsplat
ls -la "$ROOT/.whl/gsplat-1.5.3-aot-sm${ARCH}-cp312.tar.gz"
