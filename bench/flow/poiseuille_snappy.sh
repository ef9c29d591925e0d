#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Issue #17, the fluid-mesh question: a lumen given as a closed surface (a straight pipe's STL with inlet, outlet and
# wall regions, as `aneuprep flow` would write it from a lumen) meshed by OpenFOAM's snappyHexMesh (castellated hex
# mesh snapped to the surface, boundary layers at the wall) and solved by simpleFoam; the same Hagen–Poiseuille
# comparison as poiseuille_openfoam.sh (blood, plug inflow, outlet p = 0).
# Usage: bash bench/flow/poiseuille_snappy.sh [CELL_MM=0.25] [LAYERS=3]
# Output: appends to bench/results/flow/poiseuille.md; the case under build/flow/snappy.
set -euo pipefail
export WM_PROJECT_DIR=${WM_PROJECT_DIR:-/usr/share/openfoam}
here=$(cd "$(dirname "$0")/../.." && pwd)
H=${1:-0.25} LAYERS=${2:-3}
R=2 L=40 U=0.05 NU=3.30189e-06
case=$here/build/flow/snappy
rm -rf "$case"; mkdir -p "$case"/{system,constant/triSurface,0}
cd "$case"
# The pipe's surface in mm: 96 segments around, 160 along; flat end caps as separate regions.
python3 - "$R" "$L" > constant/triSurface/lumen.stl <<'PY'
import math, sys
R, L = float(sys.argv[1]), float(sys.argv[2])
n, m = 96, 160
def tri(f, a, b, c):
    u = [b[i] - a[i] for i in range(3)]; v = [c[i] - a[i] for i in range(3)]
    nn = [u[1]*v[2]-u[2]*v[1], u[2]*v[0]-u[0]*v[2], u[0]*v[1]-u[1]*v[0]]
    l = math.sqrt(sum(x*x for x in nn)) or 1
    f.append("facet normal %g %g %g\n outer loop\n" % tuple(x/l for x in nn) + "".join("  vertex %.9g %.9g %.9g\n" % tuple(p) for p in (a, b, c)) + " endloop\nendfacet\n")
ring = lambda x: [(x, R*math.cos(2*math.pi*k/n), R*math.sin(2*math.pi*k/n)) for k in range(n)]
out = []
w = []
for j in range(m):
    a, b = ring(L*j/m), ring(L*(j+1)/m)
    for k in range(n):
        k1 = (k + 1) % n
        tri(w, a[k], b[k], b[k1]); tri(w, a[k], b[k1], a[k1])
out.append("solid wall\n" + "".join(w) + "endsolid wall\n")
for name, x, flip in (("inlet", 0.0, True), ("outlet", L, False)):
    c = []
    r = ring(x)
    for k in range(n):
        k1 = (k + 1) % n
        if flip: tri(c, (x, 0, 0), r[k1], r[k])
        else: tri(c, (x, 0, 0), r[k], r[k1])
    out.append("solid %s\n%sendsolid %s\n" % (name, "".join(c), name))
sys.stdout.write("".join(out))
PY
NB=$(python3 -c "import math; print(math.ceil(($R*2+1)/$H))") NL=$(python3 -c "import math; print(math.ceil(($L+2)/$H))")
cat > system/blockMeshDict <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object blockMeshDict; }
convertToMeters 0.001;
vertices ((-1 -2.5 -2.5) ($((L+1)) -2.5 -2.5) ($((L+1)) 2.5 -2.5) (-1 2.5 -2.5) (-1 -2.5 2.5) ($((L+1)) -2.5 2.5) ($((L+1)) 2.5 2.5) (-1 2.5 2.5));
blocks (hex (0 1 2 3 4 5 6 7) ($NL $NB $NB) simpleGrading (1 1 1));
edges (); boundary (); 
EOD
cat > system/snappyHexMeshDict <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object snappyHexMeshDict; }
castellatedMesh true; snap true; addLayers true;
geometry { lumen.stl { type triSurfaceMesh; scale 0.001; name lumen;
  regions { wall { name wall; } inlet { name inlet; } outlet { name outlet; } } } }
castellatedMeshControls { maxLocalCells 2000000; maxGlobalCells 4000000; minRefinementCells 0; nCellsBetweenLevels 2;
  resolveFeatureAngle 30; features ();
  refinementSurfaces { lumen { level (0 0); patchInfo { type wall; }
    regions { inlet { level (0 0); patchInfo { type patch; } } outlet { level (0 0); patchInfo { type patch; } } } } }
  refinementRegions { } locationInMesh (0.020 0.0003 0.0002); allowFreeStandingZoneFaces false; }
snapControls { nSmoothPatch 3; tolerance 2.0; nSolveIter 100; nRelaxIter 5; nFeatureSnapIter 10; implicitFeatureSnap true; explicitFeatureSnap false; }
addLayersControls { relativeSizes true; layers { wall { nSurfaceLayers $LAYERS; } } expansionRatio 1.2; finalLayerThickness 0.4;
  minThickness 0.05; nGrow 0; featureAngle 130; slipFeatureAngle 30; nRelaxIter 3; nSmoothSurfaceNormals 1; nSmoothNormals 3;
  nSmoothThickness 10; maxFaceThicknessRatio 0.5; maxThicknessToMedialRatio 0.3; minMedialAxisAngle 90; nBufferCellsNoExtrude 0;
  nLayerIter 50; }
meshQualityControls { maxNonOrtho 65; maxBoundarySkewness 20; maxInternalSkewness 4; maxConcave 80; minVol 1e-20; minTetQuality 1e-15;
  minArea -1; minTwist 0.02; minDeterminant 0.001; minFaceWeight 0.05; minVolRatio 0.01; minTriangleTwist -1; nSmoothScale 4;
  errorReduction 0.75; relaxed { maxNonOrtho 75; } }
mergeTolerance 1e-6;
EOD
cp "$here/build/flow/poiseuille/system/"{controlDict,fvSchemes,fvSolution} system/ 2>/dev/null || { echo "run poiseuille_openfoam.sh first (its dictionaries are reused)"; exit 2; }
sed -i 's/nNonOrthogonalCorrectors 0/nNonOrthogonalCorrectors 2/' system/fvSolution
cat > system/meshQualityDict <<EOD
FoamFile { version 2.0; format ascii; class dictionary; object meshQualityDict; }
#includeEtc "caseDicts/mesh/generation/meshQualityDict"
EOD
cp "$here/build/flow/poiseuille/constant/"{transportProperties,turbulenceProperties} constant/
cp "$here/build/flow/poiseuille/0/"{U,p} 0/
t0=$(date +%s.%N)
blockMesh > log.blockMesh 2>&1
snappyHexMesh -overwrite > log.snappy 2>&1
source "$here/bench/flow/solve_and_check.sh"
solve_and_check snappy "$H" "$LAYERS"
