#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Issue #17, feasibility of the solver half: Debian's OpenFOAM (package `openfoam`, v1912) solves steady laminar
# flow in a straight pipe (the Hagen–Poiseuille check of the issue's acceptance) on this machine. A structured O-grid
# pipe from blockMesh (not yet the product's own lumen mesh), blood (ρ 1,060 kg/m³, μ 3.5 mPa·s), a plug inflow,
# zero pressure at the outlet; simpleFoam to convergence; then the developed pressure gradient and the wall shear
# stress against Hagen–Poiseuille, and the mass balance.
# Usage: bash bench/flow/poiseuille_openfoam.sh [N_AROUND_QUARTER=10] [N_RADIAL=8] [N_AXIAL=80]
# Output: bench/results/flow/poiseuille.md (and the case under build/flow/poiseuille).
set -euo pipefail
# Debian's OpenFOAM finds its etc/ (controlDict, cellModels) through WM_PROJECT_DIR.
export WM_PROJECT_DIR=${WM_PROJECT_DIR:-/usr/share/openfoam}
here=$(cd "$(dirname "$0")/../.." && pwd)
N=${1:-10} M=${2:-8} NX=${3:-80}
R=2 L=40 U=0.05 NU=3.30189e-06   # mm, mm, m/s, m²/s (3.5e-3 / 1060)
case=$here/build/flow/poiseuille
rm -rf "$case"; mkdir -p "$case"/{system,constant,0}
cd "$case"
A=0.7 C=$(python3 -c "print($R/2**0.5)")
cat > system/blockMeshDict <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object blockMeshDict; }
convertToMeters 0.001;
vertices (
  (0 -$A -$A) (0 $A -$A) (0 $A $A) (0 -$A $A)
  (0 -$C -$C) (0 $C -$C) (0 $C $C) (0 -$C $C)
  ($L -$A -$A) ($L $A -$A) ($L $A $A) ($L -$A $A)
  ($L -$C -$C) ($L $C -$C) ($L $C $C) ($L -$C $C)
);
blocks (
  hex (0 1 2 3 8 9 10 11) ($N $N $NX) simpleGrading (1 1 1)
  hex (4 5 1 0 12 13 9 8) ($N $M $NX) simpleGrading (1 3 1)
  hex (5 6 2 1 13 14 10 9) ($N $M $NX) simpleGrading (1 3 1)
  hex (6 7 3 2 14 15 11 10) ($N $M $NX) simpleGrading (1 3 1)
  hex (7 4 0 3 15 12 8 11) ($N $M $NX) simpleGrading (1 3 1)
);
edges (
  arc 4 5 (0 0 -$R) arc 5 6 (0 $R 0) arc 6 7 (0 0 $R) arc 7 4 (0 -$R 0)
  arc 12 13 ($L 0 -$R) arc 13 14 ($L $R 0) arc 14 15 ($L 0 $R) arc 15 12 ($L -$R 0)
);
boundary (
  inlet { type patch; faces ((0 3 2 1) (4 0 1 5) (5 1 2 6) (6 2 3 7) (7 3 0 4)); }
  outlet { type patch; faces ((8 9 10 11) (12 13 9 8) (13 14 10 9) (14 15 11 10) (15 12 8 11)); }
  wall { type wall; faces ((4 5 13 12) (5 6 14 13) (6 7 15 14) (7 4 12 15)); }
);
EOD
cat > system/controlDict <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object controlDict; }
application simpleFoam; startFrom startTime; startTime 0; stopAt endTime; endTime 3000; deltaT 1;
writeControl timeStep; writeInterval 3000; purgeWrite 0; writeFormat ascii; writePrecision 10; runTimeModifiable false;
EOD
cat > system/fvSchemes <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object fvSchemes; }
ddtSchemes { default steadyState; }
gradSchemes { default Gauss linear; }
divSchemes { default none; div(phi,U) bounded Gauss linearUpwind grad(U); div((nuEff*dev2(T(grad(U))))) Gauss linear; }
laplacianSchemes { default Gauss linear corrected; }
interpolationSchemes { default linear; }
snGradSchemes { default corrected; }
wallDist { method meshWave; }
EOD
cat > system/fvSolution <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object fvSolution; }
solvers {
  p { solver GAMG; smoother GaussSeidel; tolerance 1e-9; relTol 0.05; }
  U { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-10; relTol 0.1; }
}
SIMPLE { nNonOrthogonalCorrectors 0; consistent yes; residualControl { p 1e-7; U 1e-8; } }
relaxationFactors { equations { U 0.9; } }
EOD
cat > constant/transportProperties <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object transportProperties; }
transportModel Newtonian; nu $NU;
EOD
cat > constant/turbulenceProperties <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object turbulenceProperties; }
simulationType laminar;
EOD
cat > 0/U <<EOD
FoamFile { version 2.0; format ascii; class volVectorField; object U; }
dimensions [0 1 -1 0 0 0 0]; internalField uniform (0 0 0);
boundaryField { inlet { type fixedValue; value uniform ($U 0 0); } outlet { type zeroGradient; } wall { type noSlip; } }
EOD
cat > 0/p <<EOD
FoamFile { version 2.0; format ascii; class volScalarField; object p; }
dimensions [0 2 -2 0 0 0 0]; internalField uniform 0;
boundaryField { inlet { type zeroGradient; } outlet { type fixedValue; value uniform 0; } wall { type zeroGradient; } }
EOD
t0=$(date +%s.%N)
blockMesh > log.blockMesh 2>&1
source "$here/bench/flow/solve_and_check.sh"
solve_and_check "$N" "$M" "$NX"
