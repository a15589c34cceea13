#!/bin/sh
# The comparison of docs/fidelity.md, end to end: exports the default graph's Lambertian variant
# (all glossiness 0) and its glossy-ball variant (ball glossiness 0.8) with today's renderer in
# four pipeline configurations, renders each scene once in Cycles, and prints the metrics.
#
#   tools/fidelity/before.sh [OUT] [SAMPLES]
#
# OUT defaults to target/fidelity, SAMPLES to 1024. Needs the werkstatt binary (WERKSTATT, default
# target/release/werkstatt, else target/debug/werkstatt) and a Python with bpy (BPY_PYTHON,
# default python3); without bpy the Cycles step is skipped and the committed renders under
# tests/data/fidelity/ are used instead.
set -eu
out=${1:-target/fidelity}
samples=${2:-1024}
py=${BPY_PYTHON:-python3}
ws=${WERKSTATT:-}
if [ -z "$ws" ]; then
    if [ -x target/release/werkstatt ]; then ws=target/release/werkstatt; else ws=target/debug/werkstatt; fi
fi
graph=graphs/still_life.ron
lambert="--set ball_material.glossiness=0 --set cloth.glossiness=0 --set floor_material.glossiness=0"
glossy="--set ball_material.glossiness=0.8 --set cloth.glossiness=0 --set floor_material.glossiness=0"

# name | cycles case | werkstatt flags
variants="
ibl_alone|lambert|$lambert --unlink light.shadows --set hybrid.local=false
ibl_atlas|lambert|$lambert --set hybrid.local=false
default|lambert|$lambert
tiles512|lambert|$lambert --set shadow_atlas.tile_size=512
glossy_ball|glossy|$glossy
"

mkdir -p "$out"
case "$out" in
/*) abs=$out ;;
*) abs=$(pwd)/$out ;;
esac
render_cycles() { # case flags
    dir="$out/cycles_$1"
    # shellcheck disable=SC2086
    "$ws" fidelity export "$graph" $2 --out "$dir" >/dev/null
    if "$py" -c 'import bpy' >/dev/null 2>&1; then
        "$py" tools/fidelity/cycles.py "$dir" --samples "$samples" >/dev/null 2>&1
        "$py" tools/fidelity/cycles.py "$dir" --samples "$samples" --direct-only --no-ids >/dev/null 2>&1
    else
        committed=tests/data/fidelity/default_lambert
        [ "$1" = glossy ] && committed=tests/data/fidelity/default_glossy_ball
        echo "no bpy in $py: using the committed Cycles render $committed/cycles.exr" >&2
        cp "$committed/cycles.exr" "$dir/cycles.exr"
    fi
}
render_cycles lambert "$lambert"
render_cycles glossy "$glossy"

echo "$variants" | while IFS='|' read -r name case flags; do
    [ -n "$name" ] || continue
    dir="$out/$name"
    # shellcheck disable=SC2086
    "$ws" fidelity export "$graph" $flags --out "$dir" >/dev/null
    echo "## $name ($flags)"
    "$ws" fidelity compare "$dir" --cycles "$abs/cycles_$case/cycles.exr"
    if [ -f "$out/cycles_$case/cycles_direct.exr" ]; then
        echo "against Cycles direct light only:"
        "$ws" fidelity compare "$dir" --cycles "$abs/cycles_$case/cycles_direct.exr" | head -1
    fi
    echo
done
