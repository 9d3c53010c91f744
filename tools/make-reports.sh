#!/usr/bin/env bash
# Regenerates the reports checked in under docs/: the example report on the
# quarter-scale city, the memory-budget report on the full city, one report
# per third-party scene in ../shared/scenes/ and one per generated stress
# scene. Each is checked in headless Chromium (tools/check-report.sh) and
# screenshotted (the first charts, the walkthrough, the estimate against
# truth); only report.html and the screenshots are kept.
#
#   tools/make-reports.sh            # every report (about 20 minutes on 2 cores)
#   tools/make-reports.sh NAME...    # some of them, by name:
#     city-quarter city-budget DenHaag_01 lyon1_buildings forza
#     azure_coast_2p Ifc2x3_Duplex_Architecture track hilly-flyover
#
# The third-party scenes are read from ../shared/scenes/ (beside this
# repository); a name whose scene is missing is an error.
set -euo pipefail

cd "$(dirname "$0")/.."
die() { echo "make-reports: $*" >&2; exit 2; }

cargo build --release --quiet
B=target/release/impostor
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
scenes=../shared/scenes
all=(city-quarter city-budget DenHaag_01 lyon1_buildings forza azure_coast_2p
    Ifc2x3_Duplex_Architecture track hilly-flyover)
names=("$@")
[ ${#names[@]} -gt 0 ] || names=("${all[@]}")

# report NAME SCENE JOB [impostor report options...]: writes
# docs/report-NAME/ (report.html and screenshots) and checks it.
report() {
    local name=$1 scene=$2 job=$3
    shift 3
    local out="$work/$name" dir="docs/report-$name"
    echo "make-reports: $name" >&2
    local start=$SECONDS
    "$B" report "$scene" --job "$job" "$@" -o "$out"
    echo "make-reports: $name took $((SECONDS - start)) s" >&2
    rm -rf "$dir"
    mkdir -p "$dir"
    cp "$out/report.html" "$dir/"
    tools/check-report.sh "$dir/report.html" "$dir/first-charts.png"
    tools/check-report.sh "$dir/report.html" "$dir/walkthrough.png" '#walkthrough figure'
    tools/check-report.sh "$dir/report.html" "$dir/estimates.png" '#estimates figure'
}

# A job file derived from JOB with some fields replaced (a JSON object
# merged at the top level, one level deep).
derive() {
    python3 - "$1" "$2" "$3" <<'EOF'
import json, sys
job = json.load(open(sys.argv[1]))
for k, v in json.loads(sys.argv[2]).items():
    if isinstance(v, dict) and isinstance(job.get(k), dict):
        job[k].update(v)
    else:
        job[k] = v
json.dump(job, open(sys.argv[3], "w"), indent=2)
EOF
}

for name in "${names[@]}"; do
    case $name in
    city-quarter)
        "$B" gen-city --scale 0.25 --seed 5 -o "$work/q.glb"
        report city-quarter "$work/q.glb" fixtures/jobs/city-report.json \
            --sweep target_frame_time_ms=11,12,13,14 \
            --sweep problem_views.cell_size=46,23,11.5 \
            --sweep env_map.far_m=150,300 --stability --views 4000
        # The README shows the 13 ms panels.
        d=docs/report-city-quarter
        tools/check-report.sh $d/report.html $d/walkthrough.png '#chart-walk-2'
        for m in memory time; do
            tools/check-report.sh $d/report.html $d/methods-$m.png "#chart-methods-$m-2"
        done
        ;;
    city-budget)
        [ -f "$work/city.glb" ] || "$B" gen-city -o "$work/city.glb"
        derive fixtures/jobs/vienna-reference.json \
            '{"target_frame_time_ms": 4, "visibility": "conservative"}' "$work/4ms.json"
        report city-budget "$work/city.glb" "$work/4ms.json" \
            --methods shafts --budgets 0.5,0.25,0.1 --views 20000
        ;;
    DenHaag_01 | lyon1_buildings | forza | azure_coast_2p | Ifc2x3_Duplex_Architecture)
        [ -f "$scenes/$name.glb" ] || die "$scenes/$name.glb is missing"
        report "$name" "$scenes/$name.glb" "fixtures/jobs/$name.json" \
            --methods shafts,boxes --views 4000
        ;;
    track)
        "$B" gen-city --track -o "$work/track.glb"
        report track "$work/track.glb" fixtures/jobs/track.json --methods shafts --views 4000
        ;;
    hilly-flyover)
        "$B" gen-city --hills 40 -o "$work/hilly.glb"
        report hilly-flyover "$work/hilly.glb" fixtures/jobs/hilly-flyover.json \
            --methods shafts --views 4000
        ;;
    *) die "unknown report '$name' (known: ${all[*]})" ;;
    esac
done
