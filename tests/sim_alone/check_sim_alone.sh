#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Proves that the simulator half (aneu_core + aneu_sim + aneusim) configures and builds with the offline
# stack unavailable to CMake, and that neither that aneusim nor the main build's links ITK, VTK, CGAL,
# Netgen, TetGen or GDCM.   usage: check_sim_alone.sh SOURCE_DIR BUILD_DIR MAIN_BUILD_ANEUSIM
set -euo pipefail
src=$1 build=$2 main_sim=$3
rm -rf "$build"
args=(-DANEU_BUILD_PIPELINE=OFF -DANEU_BUILD_TESTS=OFF -DANEU_BUILD_BENCH=OFF -DCMAKE_BUILD_TYPE=Release)
for pkg in ITK VTK CGAL TetGen Nglib GDCM; do args+=(-DCMAKE_DISABLE_FIND_PACKAGE_${pkg}=ON); done
if command -v ccache >/dev/null; then
  args+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
if command -v ninja >/dev/null; then args+=(-G Ninja); fi
cmake -S "$src" -B "$build" "${args[@]}" >"$build.configure.log" 2>&1 || { cat "$build.configure.log"; exit 1; }
cmake --build "$build" --target aneusim -j2 >"$build.build.log" 2>&1 || { tail -50 "$build.build.log"; exit 1; }
if grep -E '^(ITK_DIR|VTK_DIR|CGAL_DIR):PATH=/' "$build/CMakeCache.txt"; then
  echo "FAIL: the sim-only configure located part of the offline stack"; exit 1
fi
# Transitively (ldd) no ITK, VTK, Netgen, TetGen or GDCM; directly (NEEDED) not CGAL's GMP/MPFR either
# (libgmp also arrives through HDF5 -> curl -> gnutls, which is not the offline stack).
forbidden='libITK|libitk|libvtk|nglib|netgen|libtet\.|gdcm'
status=0
for exe in "$build/tools/aneusim" "$main_sim"; do
  [ -x "$exe" ] || { echo "FAIL: $exe was not built"; exit 1; }
  if ldd "$exe" | grep -E "$forbidden"; then
    echo "FAIL: $exe links part of the offline stack (above)"; status=1
  fi
  if readelf -d "$exe" | grep NEEDED | grep -E "$forbidden|libgmp|libmpfr|CGAL"; then
    echo "FAIL: $exe links part of the offline stack directly (above)"; status=1
  fi
done
[ $status -eq 0 ] && echo "sim half: configured and built without ITK/VTK/CGAL/Netgen/TetGen; aneusim links none of them"
rm -rf "$build" "$build.configure.log" "$build.build.log"
exit $status
