#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_bad_inputs.sh PREP WORKDIR
# Bad surfaces and volumes as other tools (or accidents) make them, each through `aneuprep surface` /
# `aneuprep segment`: exactly one error line naming the file and what was expected, exit code 2 (the input
# is at fault), no raw exception text (std::bad_alloc, basic_string, filesystem error), and nothing left
# under the output's final name. The inputs are generated here (awk: ASCII STL of a tube; perl: a float MHA).
set -u
prep=$1 w=$2/bad_inputs
rm -rf "$w" && mkdir -p "$w"
fails=0

# ASCII STL of an open tube along z (radius R, length L, N around, M along), optionally scaled, with a face
# left out (hole), a NaN vertex, or a second tube crossing the first.
tube() {  # tube FILE SCALE HOLE NAN CROSS
  awk -v s="$2" -v hole="$3" -v nan="$4" -v cross="$5" 'BEGIN {
    R = 2; L = 20; N = 24; M = 20; pi = atan2(0, -1)
    print "solid tube"
    ntubes = cross ? 2 : 1
    for (t = 0; t < ntubes; t++)
      for (j = 0; j < M; j++)
        for (i = 0; i < N; i++) {
          if (hole && t == 0 && j == M / 2 && i == 3) continue
          for (q = 0; q < 2; q++) {
            if (q == 0) { a = i; b = i + 1; c = i + 1; ja = j; jb = j; jc = j + 1 }
            else        { a = i; b = i + 1; c = i;     ja = j; jb = j + 1; jc = j + 1 }
            print "facet normal 0 0 0"; print " outer loop"
            split(a " " b " " c, I, " "); split(ja " " jb " " jc, J, " ")
            for (k = 1; k <= 3; k++) {
              th = 2 * pi * I[k] / N; z = L * J[k] / M - L / 2
              x = R * cos(th); y = R * sin(th)
              if (t == 1) { tmp = z; z = x; x = tmp; y = y + 0.37 }  # the second tube runs along x through the first
              xs = x * s; ys = y * s; zs = z * s
              if (nan && t == 0 && j == 5 && i == 5 && k == 1) xs = "nan"
              print "  vertex " xs " " ys " " zs
            }
            print " endloop"; print "endfacet"
          }
        }
    print "endsolid tube"
  }' > "$1"
}

check() {  # check NAME WANT_CODE REGEX OUTPUT -- command...
  local name=$1 want=$2 regex=$3 out=$4
  shift 5
  local err
  err=$("$@" 2>&1 >/dev/null)
  local got=$?
  local lines
  lines=$(printf '%s\n' "$err" | grep -c 'error:')
  local bad=""
  [ "$got" = "$want" ] || bad="$bad exit $got (expected $want);"
  printf '%s\n' "$err" | grep -Eq -- "$regex" || bad="$bad message does not match /$regex/;"
  [ "$lines" = 1 ] || bad="$bad $lines error lines (expected 1);"
  if printf '%s\n' "$err" | grep -Eq 'bad_alloc|basic_string|filesystem error|std::'; then bad="$bad raw exception text;"; fi
  [ -e "$out" ] && bad="$bad $out exists;"
  if [ -n "$bad" ]; then
    echo "FAIL $name:$bad"; printf '%s\n' "$err" | tail -5; fails=$((fails + 1))
  else
    echo "ok   $name: $(printf '%s\n' "$err" | grep 'error:' | cut -c1-160)"
  fi
}

tube "$w/metres.stl" 0.001 0 0 0
tube "$w/holed.stl" 1 1 0 0
tube "$w/nan.stl" 1 0 1 0
tube "$w/overlap.stl" 1 0 0 1
tube "$w/good.stl" 1 0 0 0
# Near-degenerate: every vertex squeezed into a plane (a tube flattened to 1e-9 mm).
awk '/vertex/ { $3 = $3 * 1e-9 } { print }' "$w/good.stl" > "$w/flat.stl"

check metre_scale 2 "metres\\.stl: the surface spans 0\\.0[0-9]+ mm.*--input-scale 1000" "$w/o1.h5" -- "$prep" surface "$w/metres.stl" -o "$w/o1.h5"
check hole_in_side 2 "holed\\.stl: the boundary loop at .*hole in the side" "$w/o2.h5" -- "$prep" surface "$w/holed.stl" -o "$w/o2.h5"
check nan_vertex 2 "nan\\.stl: vertex [0-9]+ has a NaN or infinite coordinate" "$w/o3.h5" -- "$prep" surface "$w/nan.stl" -o "$w/o3.h5"
check overlapping_tubes 2 "overlap\\.stl: .*(intersects itself|manifold)" "$w/o4.h5" -- "$prep" surface "$w/overlap.stl" -o "$w/o4.h5"
check near_degenerate 2 "flat\\.stl: " "$w/o5.h5" -- "$prep" surface "$w/flat.stl" -o "$w/o5.h5"
check absurd_edge 2 "--edge-mm = 1e-05 mm would make about [0-9e+.]+ triangles .*expected an edge of at least" "$w/o6.h5" -- "$prep" surface "$w/good.stl" -o "$w/o6.h5" --edge-mm 0.00001
check negative_edge 2 "--edge-mm must be > 0" "$w/o7.h5" -- "$prep" surface "$w/good.stl" -o "$w/o7.h5" --edge-mm -1

# A CT volume with a NaN voxel (MetaImage, float, 8x8x8).
perl -e 'print "ObjectType = Image\nNDims = 3\nDimSize = 8 8 8\nElementSpacing = 0.5 0.5 0.5\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n";
         for $i (0..511) { print pack("f<", $i == 77 ? 9**9**9 / 9**9**9 : ($i % 8 > 3 ? 400.0 : 40.0)); }' > "$w/nan.mha"
check nan_voxel 2 "nan\\.mha: 1 voxel\\(s\\) are NaN or infinite, the first at index \\(5, 1, 1\\)" "$w/o8.h5" -- "$prep" segment "$w/nan.mha" -o "$w/o8.h5"

echo "$fails failure(s)"
[ "$fails" = 0 ]
