#!/usr/bin/env bash
# The GPU check of the cuda backend and solver.device = "cuda", on a machine with an NVIDIA GPU and
# CuPy, NVRTC (pip install '.[cuda]'): the device tests, then `tensormass bench gpu`, whose lines are
# the numbers docs/guide/gpu.md reports. About 3 minutes on an H100 (the organ mesh: made with gmsh,
# or given as ORGAN_MESH=FILE). Writes $OUT/bench_gpu.json and its scaling plot when OUT is set.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-.}"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
python -c "import cupy; print('CuPy', cupy.__version__, 'CUDA runtime', cupy.cuda.runtime.runtimeGetVersion())"
python -m pytest -q -p no:cacheprovider -m "heavy or not heavy" tests/backends/test_cuda_backend.py \
    tests/runtime/solve/test_device_step.py tests/runtime/physics/test_device_euler.py
tensormass bench gpu --json "$out/bench_gpu.json" ${ORGAN_MESH:+--organ-mesh "$ORGAN_MESH"}
