#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Makefile.cases on a Slurm cluster: one job per case and stage, chained per case (--dependency=afterok on the
# previous stage's job), the cases side by side. Each job runs `make -f Makefile.cases STAGE_OUTPUT`, so a job
# whose output is already up to date costs a provenance check, and a failed stage stops only its case's chain.
# A case whose [flow] names a session's series (`series = ".../SCENE_series.h5"`) gets a session job between its
# case bundle and its flow: --scene CASE=SCENE.json submits `aneusim run SCENE --deterministic` (the scene must
# write that series); without it the case is refused (exit 2) before anything is submitted.
#
# usage: bash scripts/slurm_cases.sh [--scene CASE=SCENE.json]... [--dry-run] [-- SBATCH_OPTION...]
#   e.g. bash scripts/slurm_cases.sh -- --partition=short --cpus-per-task=2 --mem=8G
# env: PREP (build/tools/aneuprep), SIM (build/tools/aneusim), CASES_DIR (configs/cases), OUT (out/cases),
#      SBATCH (sbatch). --dry-run prints the sbatch commands instead of submitting them.
set -euo pipefail
cd "$(dirname "$0")/.."
PREP=${PREP:-build/tools/aneuprep}
SIM=${SIM:-build/tools/aneusim}
CASES_DIR=${CASES_DIR:-configs/cases}
OUT=${OUT:-out/cases}
SBATCH=${SBATCH:-sbatch}
declare -A SCENE=()
extra=()
dry=0
while [ $# -gt 0 ]; do
  case "$1" in
    --scene) [ $# -ge 2 ] && [[ "$2" == *=* ]] || { echo "slurm_cases.sh: --scene expects CASE=SCENE.json" >&2; exit 2; }
             SCENE[${2%%=*}]=${2#*=}; shift 2 ;;
    --dry-run) dry=1; shift ;;
    --) shift; extra=("$@"); break ;;
    *) echo "slurm_cases.sh: unknown argument '$1' (expected --scene CASE=SCENE.json, --dry-run, -- SBATCH_OPTION...)" >&2; exit 2 ;;
  esac
done
shopt -s nullglob
configs=("$CASES_DIR"/*.toml)
[ ${#configs[@]} -gt 0 ] || { echo "slurm_cases.sh: no case configs in $CASES_DIR" >&2; exit 2; }
# Plan every case first (its rules, in stage order), so a refused case submits nothing.
declare -A PLAN=()
for cfg in "${configs[@]}"; do
  id=$(basename "$cfg" .toml)
  mkdir -p "$OUT/$id"
  "$PREP" run "$cfg" --out-dir "$OUT/$id" --make-rules "$OUT/$id/rules.mk" --quiet
  # "stage TARGET" per stage rule, "series TARGET" for a session's series, in the rules' order.
  PLAN[$id]=$(awk '/^[^\t#][^:]*:/ { t = substr($0, 1, index($0, ":") - 1); next_is = 1; next }
                   next_is && /--stage / { match($0, /--stage [a-z]+/); print substr($0, RSTART + 8, RLENGTH - 8), t }
                   next_is && /run the scene first/ { print "series", t }
                   { next_is = 0 }' "$OUT/$id/rules.mk")
  if grep -q '^series ' <<< "${PLAN[$id]}" && [ -z "${SCENE[$id]:-}" ]; then
    echo "slurm_cases.sh: case $id: its [flow] follows a session ($(awk '$1 == "series" { print $2 }' <<< "${PLAN[$id]}")): give --scene $id=SCENE.json" >&2
    exit 2
  fi
done
submit() {  # name dependency command -> prints the job id
  local args=(--parsable --job-name "$1")
  [ -n "$2" ] && args+=(--dependency "afterok:$2")
  args+=("${extra[@]}" --wrap "$3")
  if [ $dry = 1 ]; then echo "$SBATCH ${args[*]}" >&2; echo "dry$RANDOM"; else "$SBATCH" "${args[@]}"; fi
}
for cfg in "${configs[@]}"; do
  id=$(basename "$cfg" .toml)
  prev=""
  n=0
  while read -r stage target; do
    [ -n "$stage" ] || continue
    if [ "$stage" = series ]; then
      job=$(submit "aneu-$id-session" "$prev" "$SIM run ${SCENE[$id]} --deterministic")
    else
      job=$(submit "aneu-$id-$stage" "$prev" "make -f Makefile.cases PREP=$PREP CASES_DIR=$CASES_DIR OUT=$OUT $target")
    fi
    job=${job%%;*}  # --parsable: "id" or "id;cluster"
    prev=$job
    n=$((n + 1))
  done <<< "${PLAN[$id]}"
  echo "case $id: $n jobs, the last $prev"
done
