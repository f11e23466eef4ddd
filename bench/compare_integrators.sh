#!/usr/bin/env bash
# Regenerates docs/integrators.md's comparison tables: for each scene, every integrator renders
# for the same wall-clock time, and its RMSE against a long reference render is measured.
#
#   bench/compare_integrators.sh [SECONDS_PER_RENDER] [REFERENCE_SECONDS] [SCENE...]
#
# Defaults: 20 s per integrator, 600 s per reference (the reference integrator is named per
# scene below: one that converges well there; its seed differs from the compared renders', so
# their errors are independent). RMSE and relMSE (pbrt-v4's, the render's noise figure) over
# pixels and RGB; RMSE is dominated by the pixels that see the lights.
# Writes docs/img/compare/<scene>-<integrator>.png and prints the markdown tables on stdout.
set -euo pipefail
cd "$(dirname "$0")/.."
T=${1:-20}
REF_T=${2:-600}
OUT=${RAYFARM_COMPARE_DIR:-build/compare}
IMG=docs/img/compare
mkdir -p "$OUT" "$IMG"
./rayfarm --help >/dev/null  # build first

# scene, resolution, reference integrator, integrators to compare
SCENES=(
  "veach-mis 320x180 bdpt whitted direct path light ir bdpt ppm"
  "caustic 160x120 bdpt path light ir bdpt ppm"
  "hidden-light 160x120 bdpt path light ir bdpt ppm"
)
# a region where the methods differ most, reported beside the whole image (x0,y0,x1,y1 pixels)
declare -A REGION=(
  [caustic]="40,76,150,120"        # the floor in front of the ball: caustic and shadow, no glass
)
known=$( (build/bin/rayfarm render scenes/cornell-box/scene.json --integrator nosuch -o /dev/null 2>&1 || true) | sed -n 's/.*known: \(.*\))/\1/p' | tr -d ',')

errors() {  # "RMSE | relMSE" of a against b, over RGB (optionally in a window)
  build/bin/rayfarm compare "$@" | awk '{printf "%.4g | %.4g", $2, $4}'
}

ONLY=" ${*:3} "
for entry in "${SCENES[@]}"; do
  read -r scene res ref integrators <<<"$entry"
  [ "$ONLY" = "  " ] || case "$ONLY" in *" $scene "*) ;; *) continue ;; esac
  case " $known " in *" $ref "*) ;; *) ref=path ;; esac
  refexr="$OUT/$scene-reference-$ref.exr"
  if [ ! -f "$refexr" ]; then
    ./rayfarm render "scenes/$scene/scene.json" -o "$refexr" --integrator "$ref" --res "$res" \
      --spp 1048576 --passes 65536 --time-budget "$REF_T" --seed 7919 -q >&2
  fi
  echo
  echo "### $scene ($res, ${T} s per render, reference: $ref for ${REF_T} s)"
  echo
  region=${REGION[$scene]:-}
  if [ -n "$region" ]; then
    echo "| integrator | passes in ${T} s | RMSE | relMSE | RMSE in $region | relMSE in $region | image |"
    echo "|---|---:|---:|---:|---:|---:|---|"
  else
    echo "| integrator | passes in ${T} s | RMSE | relMSE | image |"
    echo "|---|---:|---:|---:|---|"
  fi
  for integrator in $integrators; do
    case " $known " in *" $integrator "*) ;; *) continue ;; esac
    exr="$OUT/$scene-$integrator.exr"
    log=$(./rayfarm render "scenes/$scene/scene.json" -o "$exr" --integrator "$integrator" \
      --res "$res" --spp 1048576 --passes 65536 --time-budget "$T" -q 2>&1 || true)
    if [ ! -f "$exr" ]; then
      echo "| $integrator | — | cannot render: $(tail -1 <<<"$log" | sed 's/|/\\|/g') | | |"
      continue
    fi
    passes=$(sed -n 's/.*(\([0-9]*\) passes).*/\1/p' <<<"$log" | tail -1)
    cp "${exr%.exr}.png" "$IMG/$scene-$integrator.png"
    row="$(errors "$exr" "$refexr")"
    [ -n "$region" ] && row="$row | $(errors "$exr" "$refexr" --window "$region")"
    echo "| $integrator | $passes | $row | ![](img/compare/$scene-$integrator.png) |"
  done
done
