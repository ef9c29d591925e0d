# SPDX-License-Identifier: MIT
# Sourced by the pipe benchmarks: after the mesh (timed from t0), solve with simpleFoam, post-process the wall shear
# stress and cell centres, and compare with Hagen–Poiseuille (poiseuille_check.py). Arguments: the check's labels.
solve_and_check() {
    checkMesh > log.checkMesh 2>&1 || true
    local t1 t2
    t1=$(date +%s.%N)
    simpleFoam > log.simpleFoam 2>&1
    t2=$(date +%s.%N)
    simpleFoam -postProcess -latestTime -func wallShearStress > log.wss 2>&1
    postProcess -latestTime -func writeCellCentres > log.centres 2>&1
    python3 "$here/bench/flow/poiseuille_check.py" "$case" "$R" "$L" "$U" "$NU" "$(python3 -c "print($t1-$t0)")" "$(python3 -c "print($t2-$t1)")" "$@"
}
