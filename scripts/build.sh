#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Configures and builds aneuclip in ./build: RelWithDebInfo, Ninja, ccache, warnings as errors, tests and
# benchmarks configured. One configuration for everything (the demo, the tests, the benchmarks), so that the
# demo's build is reused by the test command instead of being rebuilt with other flags.
# Usage: bash scripts/build.sh [TARGET ...]   (no target: build everything)
set -euo pipefail
cd "$(dirname "$0")/.."
export CCACHE_DIR="${CCACHE_DIR:-$HOME/.cache/ccache}"
ccache --max-size=5G >/dev/null 2>&1 || true
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DANEU_WERROR=ON -DANEU_BUILD_TESTS=ON \
      -DANEU_BUILD_BENCH=ON -DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache
if [ "$#" -gt 0 ]; then
  cmake --build build -j"$(nproc)" --target "$@"
else
  cmake --build build -j"$(nproc)"
fi
