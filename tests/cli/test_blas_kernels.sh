#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_blas_kernels.sh ANEUPREP ANEUSIM
# Debian 12's OpenBLAS 0.3.21 falls back to its SSE3 "Prescott" kernels on CPUs it does not know (OpenBLAS issue
# #4267; this project's Xeon: dgemm 13 instead of 65 GFLOP/s). The tools set OPENBLAS_CORETYPE for the CPU and
# start again (aneu::set_blas_kernels_env): on a CPU with AVX2 and FMA they never run on Prescott's; a kernel set the
# user asks for is kept. (Which set a known CPU gets is OpenBLAS's choice: an AMD Zen 4 with AVX-512 is "Zen".)
set -u
prep=$1 sim=$2
fail=0
flags=$(grep -m1 '^flags' /proc/cpuinfo)
has() { [[ " $flags " == *" $1 "* ]]; }
for tool in "$prep version" "$sim --version"; do
  got=$(env -u OPENBLAS_CORETYPE $tool | sed -n 's/.*OpenBLAS kernels *//p' | head -1)
  [ -n "$got" ] || { echo "$tool: prints no 'OpenBLAS kernels'"; fail=1; continue; }
  if has avx2 && has fma && [ "$got" = Prescott ]; then
    echo "$tool: OpenBLAS kernels $got on a CPU with AVX2 and FMA"; fail=1
  fi
  kept=$(OPENBLAS_CORETYPE=Prescott $tool | sed -n 's/.*OpenBLAS kernels *//p' | head -1)
  [ "$kept" = Prescott ] || { echo "$tool: OPENBLAS_CORETYPE=Prescott not kept (got '$kept')"; fail=1; }
  echo "$tool: OpenBLAS kernels $got (asked for Prescott: $kept)"
done
exit $fail
