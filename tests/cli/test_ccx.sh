#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# usage: test_ccx.sh PREP WORKDIR
# The exported Abaqus/CalculiX model runs in ccx and its displacements under a pressure on the inner wall match
# `aneuprep solve` to 1e-5 relative (largest difference over all nodes and axes / largest |u|), for 4-node and
# 10-node tetrahedra and two materials (a tube with a sac: artery and aneurysm regions, E 1 and 3 MPa).
set -u
prep=$1 w=$2
fail() { echo "FAIL: $*"; exit 1; }
command -v ccx >/dev/null || fail "ccx not found (Debian package calculix-ccx; scripts/install_deps.sh installs it)"
rm -rf "$w"; mkdir -p "$w"; cd "$w" || exit 1
"$prep" tubewall -o wall.h5 --n-theta 16 --n-z 12 --sac-radius-mm 1.6 --neck-radius-mm 1.0 --edge-mm 0.45 -q || fail "tubewall"
"$prep" tetmesh wall.h5 -o vol.h5 -q || fail "tetmesh"
for order in 1 2; do
  "$prep" assemble vol.h5 -o fem$order.h5 --element-order $order --E-aneurysm-mpa 3 --nu-aneurysm 0.4 -q || fail "assemble $order"
  "$prep" solve fem$order.h5 -o u$order.csv --pressure-mpa 0.016 -q || fail "solve $order"
  "$prep" export fem$order.h5 --format inp --pressure-mpa 0.016 -o model$order.inp -q || fail "export $order"
  grep -q "TYPE=C3D$([ $order = 1 ] && echo 4 || echo 10), ELSET=E_aneurysm" model$order.inp || fail "no aneurysm element set of order $order"
  ccx -i model$order >ccx$order.log 2>&1 || { tail -20 ccx$order.log; fail "ccx failed on model$order.inp"; }
  grep -q ERROR ccx$order.log && { grep -A3 ERROR ccx$order.log | head; fail "ccx reported an error"; }
  # ccx prints "node ux uy uz" after the "displacements" line; ours: node(0-based),x,y,z,ux,uy,uz.
  awk -v order=$order '
    FNR == NR { if (FNR > 1) { split($0, a, ","); n = a[1] + 1; u[n, 1] = a[5]; u[n, 2] = a[6]; u[n, 3] = a[7]; nn++
                  m = sqrt(a[5]^2 + a[6]^2 + a[7]^2); if (m > umax) umax = m } next }
    /displacements/ { on = 1; next }
    on && NF == 4 { seen++; for (k = 1; k <= 3; ++k) { d = $(k + 1) - u[$1, k]; if (d < 0) d = -d; if (d > dmax) dmax = d } }
    END { if (seen != nn || nn == 0) { printf "order %d: ccx printed %d nodes, aneuprep %d\n", order, seen, nn; exit 1 }
          rel = dmax / umax; printf "order %d: %d nodes, largest |u| %.6g mm, largest difference %.3g mm, relative %.3g\n", order, nn, umax, dmax, rel
          exit !(rel <= 1e-5 && umax > 0) }' u$order.csv model$order.dat || fail "ccx and aneuprep differ (order $order)"
done
echo OK
