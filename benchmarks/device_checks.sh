#!/usr/bin/env bash
# The CUDA backend's checks on a machine with a CUDA GPU, in one go:
#
#   1. the [cuda] extra: numba-cuda as pyproject.toml asks for it, from wheels in .whl/ where the machine has no
#      package index (and the wheels the benchmark needs that the machine lacks: hj-reachability, shapely, pyproj,
#      msgspec);
#   2. the tests that hold the CUDA sets to the CPU's (tests/test_hji_cuda.py), on the GPU: no simulator;
#   3. benchmarks/hji.py --device cuda: ours against hj_reachability on the same GPU, the two-stage game at 45^4,
#      65^4 and 101^4, the kernels' compile, and the targets;
#   4. benchmarks/hji.py --threads: the CPU backend at 1, 2, 4, 8 and 16 threads on the machine's cores.
#
#   benchmarks/device_checks.sh [all|tests|bench|threads|quick]
#                                         (default all; quick: the tests, then bench --quick and threads --quick)
#
# Logs go to $OUT (the folder a lent machine sends back) or /tmp/bearcat-device-checks. The step that fails stops
# the script with its exit code. The wheels, fetched on a machine that reaches an index (Python 3.12, x86-64), into
# a folder .whl/ at the repository's root, which git ignores (echo /.whl/ >> .git/info/exclude):
#
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#       --platform manylinux_2_28_x86_64 --platform manylinux_2_24_x86_64 --platform manylinux_2_17_x86_64 \
#       --platform manylinux2014_x86_64 -d .whl numba-cuda==0.30.4 hj-reachability shapely pyproj msgspec
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
what=${1:-all}
out=${OUT:-/tmp/bearcat-device-checks}
mkdir -p "$out"
python=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
unset NUMBA_ENABLE_CUDASIM

if compgen -G ".whl/*.whl" >/dev/null; then
    "$python" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/bearcat-site \
        .whl/*.whl
    export PYTHONPATH=/tmp/bearcat-site
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"

echo "== the machine and the [cuda] extra" | tee "$out/setup.log"
{ command -v nvidia-smi >/dev/null && nvidia-smi -L; } 2>&1 | tee -a "$out/setup.log" || true
"$python" - <<'EOF' 2>&1 | tee -a "$out/setup.log"
import sys
import tomllib
from importlib import metadata

from packaging.requirements import Requirement

extra = tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["cuda"]
missing = []
for line in extra:
    requirement = Requirement(line)
    try:
        version = metadata.version(requirement.name)
    except metadata.PackageNotFoundError:
        version = None
    ok = version is not None and requirement.specifier.contains(version, prereleases=True)
    print(f"{line}: {version or 'not installed'}{'' if ok else ' - does not meet the [cuda] extra'}")
    missing += [] if ok else [line]
if missing:
    sys.exit(f"the [cuda] extra is not met ({', '.join(missing)}): carry its wheels in .whl/ (see this script's head)")

from bearcat.solvers.levelset.devices import choose_device
from bearcat.solvers.errors import InputError

try:
    print(f"python {sys.version.split()[0]}; device cuda: {choose_device('cuda')}")
except InputError as exc:
    sys.exit(f"no GPU to check on: {exc}")
EOF

if [ "$what" = all ] || [ "$what" = tests ] || [ "$what" = quick ]; then
    echo "== the CUDA sets against the CPU's, on the GPU"
    BEARCAT_CUDA_TESTS=hardware timeout 420 "$python" -m pytest -n 0 -q -p no:cacheprovider --durations=5 \
        tests/test_hji_cuda.py -k "cpu_sets or cpu_window or cpu_solve or cpu_game or narrow_band" 2>&1 \
        | tee "$out/tests.log"
fi
if [ "$what" = all ] || [ "$what" = bench ]; then
    echo "== benchmarks/hji.py --device cuda"
    timeout 540 "$python" benchmarks/hji.py --device cuda 2>&1 | tee "$out/benchmark.txt"
elif [ "$what" = quick ]; then
    echo "== benchmarks/hji.py --device cuda --quick"
    timeout 300 "$python" benchmarks/hji.py --device cuda --quick 2>&1 | tee "$out/benchmark.txt"
fi
if [ "$what" = all ] || [ "$what" = threads ]; then
    echo "== benchmarks/hji.py --threads"
    timeout 240 "$python" benchmarks/hji.py --threads 2>&1 | tee "$out/threads.txt"
elif [ "$what" = quick ]; then
    echo "== benchmarks/hji.py --threads --quick"
    timeout 120 "$python" benchmarks/hji.py --threads --quick 2>&1 | tee "$out/threads.txt"
fi
