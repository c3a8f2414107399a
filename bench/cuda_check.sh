#!/usr/bin/env bash
# The renderer on a CUDA machine: its tests (CPU == CUDA included) and bench/render.py on the CPU and
# on the GPU of the same machine, so the ratio is measured in one run. Needs only numpy, torch and
# pytest (what a GPU image has); the rest of siteline (zarr, laspy, the catalog) is not
# imported. Usage: bash bench/cuda_check.sh [POINTS]
set -uo pipefail
points=${1:-12000000}
only_tests=${ONLY_TESTS:-0}
export PYTHONPATH=platform
py=${PYTHON:-python3}
nvidia-smi -L || true
$py -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available(), torch.cuda.get_device_name() if torch.cuda.is_available() else '')"
echo "== renderer on CUDA against the CPU (tests/render/test_cuda.py)"
$py -m pytest --noconftest -q -p no:cacheprovider -o addopts="-ra" tests/render/test_cuda.py tests/render/test_splats.py 2>&1 | tail -8
[ "$only_tests" = 1 ] && exit 0
echo "== bench/render.py --device cpu ($(nproc) cores)"
$py bench/render.py --device cpu --points "$points" --memory-points 0
echo "== bench/render.py --device cuda"
$py bench/render.py --device cuda --points "$points"
