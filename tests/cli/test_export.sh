#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_export.sh PREP WORKDIR
# Every export format from the stage file that holds its data, checked by content: counts in the VTK XML
# headers, the binary STL's size (84 + 50 bytes per face, only the faces of the label asked for), the NRRD
# header's physical frame, the XDMF's references into the stage file; and the errors for missing data.
set -u
prep=$1 w=$2
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$w"; mkdir -p "$w"; cd "$w" || exit 1
"$prep" phantom -o ph --formats nrrd --fov-mm 16,14,12 -q || fail phantom
"$prep" segment ph/ct.nrrd -o seg.h5 -q || fail segment
"$prep" tubewall -o wall.h5 --n-theta 16 --n-z 12 -q || fail tubewall
"$prep" tetmesh wall.h5 -o vol.h5 -q || fail tetmesh
info=$("$prep" inspect vol.h5)
nodes=$(echo "$info" | sed -n 's|^  /volume *\([0-9]*\) nodes, \([0-9]*\) tets.*|\1|p')
tets=$(echo "$info" | sed -n 's|^  /volume *\([0-9]*\) nodes, \([0-9]*\) tets.*|\2|p')
[ -n "$nodes" ] && [ -n "$tets" ] || fail "cannot read the mesh size from inspect"

"$prep" export vol.h5 --format vtu -o mesh.vtu -q || fail "vtu"
grep -q "<Piece NumberOfPoints=\"$nodes\" *NumberOfCells=\"$tets\"" mesh.vtu || fail "vtu: not $nodes points and $tets cells"
for a in region set_outer set_inner set_fixed; do grep -q "Name=\"$a\"" mesh.vtu || fail "vtu: no array $a"; done

"$prep" export vol.h5 --format xdmf -o mesh.xdmf -q || fail "xdmf"
grep -q "NumberOfElements=\"$tets\"" mesh.xdmf || fail "xdmf: element count"
grep -q ">vol.h5:/volume/nodes<" mesh.xdmf || fail "xdmf: nodes not read from vol.h5"

"$prep" export wall.h5 --format vtp -o wall.vtp -q || fail "vtp"
grep -q 'Name="label"' wall.vtp || fail "vtp: no label array"
faces_all=$(grep -o 'NumberOfPolys="[0-9]*"' wall.vtp | grep -o '[0-9]*')
"$prep" export wall.h5 --format stl -o wall.stl -q || fail "stl"
[ "$(stat -c %s wall.stl)" = $((84 + 50 * faces_all)) ] || fail "stl: size is not that of $faces_all faces"
"$prep" export wall.h5 --format stl --label outer -o outer.stl -q || fail "stl outer"
n_outer=$(( ($(stat -c %s outer.stl) - 84) / 50 ))
[ "$n_outer" -gt 0 ] && [ "$n_outer" -lt "$faces_all" ] || fail "stl --label outer: $n_outer of $faces_all faces"

"$prep" export seg.h5 --format nrrd -o mask.nrrd -q || fail "nrrd"
head -c 2000 mask.nrrd | grep -aq "space: left-posterior-superior" || fail "nrrd: no LPS space"
head -c 2000 mask.nrrd | grep -aq "type: unsigned char" || fail "nrrd: not a uint8 label map"

# errors: exit code 2, one line naming the file and what is missing; nothing left behind
"$prep" export seg.h5 --format inp -o x.inp 2>err.txt; rc=$?
[ $rc = 2 ] && grep -q "seg.h5: no /volume" err.txt || { cat err.txt; fail "inp from a segmentation: exit $rc"; }
"$prep" export vol.h5 --format inp -o x.inp 2>err.txt; rc=$?
[ $rc = 2 ] && grep -q "vol.h5: no /fem" err.txt || { cat err.txt; fail "inp without /fem: exit $rc"; }
"$prep" export vol.h5 --format obj -o x.obj 2>err.txt; rc=$?
[ $rc = 2 ] && grep -q "expected vtu, vtp, stl, nrrd, xdmf or inp" err.txt || { cat err.txt; fail "unknown format: exit $rc"; }
"$prep" export wall.h5 --format stl --label nope -o x.stl 2>err.txt; rc=$?
[ $rc = 2 ] && grep -q "label 'nope': not a label" err.txt || { cat err.txt; fail "unknown label: exit $rc"; }
ls | grep -q 'part-\|^x\.' && fail "an export that failed left a file: $(ls)"
echo OK
